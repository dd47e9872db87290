// Recognition results in HDF5 (`recognize --out RESULT.h5`), layout in io/FORMAT_RESULT.md:
// per step the best hypothesis, the posterior per object and the errors against the ground
// truth, and every hypothesis of the state S_t. Written atomically (io::AtomicOutput); the bytes
// depend only on the inputs, settings and seed (no timings, no thread count, no timestamps).
#pragma once

#include "engine/geometry/pose_error.hpp"
#include "engine/recognition/recognizer.hpp"

#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace ts::io {

constexpr const char* kResultFormat = "touchstone-recognition-result";
constexpr std::int64_t kResultSchemaVersion = 1;

struct ResultHeader {
  std::string method;                     ///< "bricpsf", "batch-ransac", ...
  std::uint64_t seed = 1;
  std::string database;                   ///< path of the database as given
  std::string input;                      ///< path of the log or cloud as given
  std::string input_kind = "log";         ///< "log" or "cloud"
  std::vector<std::string> objects;       ///< database object names (index = object id)
  std::string truth_object;               ///< "" when unknown
  std::optional<Pose> truth_pose;         ///< T_world_object, when known
  std::vector<std::pair<std::string, double>> params;  ///< method parameters (name, value)
  /// Set answers (`recognize --calibration` with answer sets): their level; then every step
  /// carries its `answer_set`, else none does.
  std::optional<double> answer_set_alpha;
  std::string calibration;                ///< the calibration file as given ("" : none)
};

/// A step's set answer (engine/recognition/answer_set.hpp), per database object: its class of
/// congruent objects' conformal p-value and log-weight gap, and whether that class is in the set.
struct ResultAnswerSet {
  bool informative = true;                ///< false: no class could be excluded (every object is in)
  std::size_t size = 0;                   ///< classes in the set (all of them when not informative)
  int calibrated_step = 0;                ///< the calibration step whose scores were used
  std::vector<double> p_value;            ///< per object, in (0, 1]
  std::vector<double> log_weight_gap;     ///< per object, >= 0 (>= 1e6: its class has no hypothesis,
                                          ///< 1e6 + its shape-prior gap; +inf: the prior could not score it)
  std::vector<std::uint8_t> in_set;       ///< per object, 1 when its class is in the set
};

/// One step as stored.
struct ResultStep {
  int step = 0;
  bool valid = false;
  std::size_t contacts = 0, free_points = 0, candidates = 0;
  int unobservable_dof = 6;
  int best_object = -1;                   ///< -1 when !valid
  double best_weight = 0.0, best_log_weight = 0.0, best_posterior = 0.0;
  Pose best_pose = Pose::Identity();
  std::vector<double> posterior;          ///< per object
  std::optional<PoseError> error;         ///< when the truth pose is known (also for a wrong object)
  std::optional<bool> correct;            ///< best_object is the truth object (when known)
  std::vector<Hypothesis> hypotheses;     ///< the state S_t, best first
  std::optional<ResultAnswerSet> answer_set;  ///< with a calibration's answer sets (ResultHeader)
};

/// Convert an engine step; with `truth_object` (a database index) and `truth_pose` known, the
/// errors are filled in (symmetric ones from `symmetries`, which may be null).
ResultStep to_result_step(const StepResult& r, std::optional<std::size_t> truth_object,
                          const std::optional<Pose>& truth_pose, const SymmetryGroup* symmetries);

/// Write (atomically). Throws ts::Error naming the file.
void write_result(const std::filesystem::path& path, const ResultHeader& header,
                  const std::vector<ResultStep>& steps);

struct ResultData {
  ResultHeader header;
  std::vector<ResultStep> steps;
};

/// Read back (checks format, schema version and shapes).
ResultData read_result(const std::filesystem::path& path);

}  // namespace ts::io
