// Stiff and extreme cases as a study (`touchstone stress`, docs/testing.md "study 10"): objects from 1 cm
// to 2 m, dives up to 1 000 km from the world origin, arm noise up to 20 mm, 3 to 5 000 contacts,
// duplicated and near-collinear contacts, a single flat patch, a 2 m x 1 cm rod. Each case runs
// the recognizer (the improved or the paper preset) over synthetic tactile patches of known
// objects at known poses, and reports the errors, how often the answer is flagged ambiguous
// (StepResult::pose_ambiguous), the condition of the ICP normal equations at the answer
// (engine/recognition/icp.hpp icp_system) and whether any output (JSON, result stores) held a NaN or an
// infinity.
//
// The objects: five asymmetric prisms (irregular polygon sections, slanted tops) whose largest
// bounding-box side is `size_m`; a case with a rod explores a rod of rod_length_m x rod_section_m
// added to a database of the five at 15 cm. Contacts: per grasp one tactile patch (radius 12 mm,
// `contacts` taxels at random spots of the disc projected onto the surface), moved by the arm's
// error (a rotation about the patch centre and a translation, per grasp), each contact by the
// contact noise; free space: points off the surface along the patch normal.
//
// Scaling (size_m / 0.15 = f): every length of the database (scanner spacing, voxels, coverage
// radius, FPFH radii, distance field voxels and margin) and of the recognizer
// (RecognizerSettings::scaled), the patch radius, the free-space offsets, the placement box and,
// unless scale_noise = false, the arm's position error and the contact noise. Angles are not
// scaled. A rod case uses f = 1 (its section would fall below the scaled scanner spacing).
//
// Determinism: everything derives from (seed, run, grasp), not from the case: run r of every
// case explores the same object at the same pose (rotation; position scaled, plus the dive
// distance) with the same draws for its patches and noise, so cases compare pair by pair.
// Results do not depend on the thread count. Runs of one case differ in pose (and object) but
// share five shapes: they are not independent samples of a population of objects.
#pragma once

#include "engine/core.hpp"

#include <nlohmann/json.hpp>

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace ts::experiments {

struct StressCase {
  std::string name = "baseline";
  double size_m = 0.15;            ///< largest bounding-box side of every object
  double distance_m = 0.0;         ///< distance of the dive (the object) from the world origin
  double arm_noise_m = 0.003;      ///< arm position error per axis per grasp (at 15 cm)
  double arm_rotation_deg = 1.0;   ///< arm rotation error per axis per grasp
  double contact_noise_m = 0.0003; ///< per contact per axis (at 15 cm)
  bool scale_noise = true;         ///< arm position error and contact noise scaled with size
  int grasps = 10;                 ///< steps; one patch each
  int contacts = 30;               ///< taxels per patch
  int duplicates = 1;              ///< every contact recorded this many times
  double collinear_m = 0.0;        ///< > 0: each patch is a line, its contacts within this of
                                   ///< it (at 15 cm; scaled)
  bool flat = false;               ///< every patch on the object's largest flat face, contacts
                                   ///< on that face only
  double rod_length_m = 0.0;       ///< > 0: explore a rod of this length ...
  double rod_section_m = 0.01;     ///< ... and section
};

struct StressStudy {
  std::string name = "stress";
  std::string description;
  std::string preset = "improved"; ///< improved | paper
  int runs = 5;                    ///< runs per case (object r mod 5, a pose per run)
  std::uint64_t seed = 1;
  std::vector<StressCase> cases;   ///< in file order
};

/// Read a study (TOML, CLI11's parser):
///   name, description, preset, runs, seed
///   [baseline] every StressCase key (the defaults above otherwise)
///   [cases] NAME = "key=value, key=value": a case is the baseline with these keys changed
/// Unknown keys, impossible values (negative noise, 0 contacts, sizes out of 1 mm..10 m,
/// distances beyond 1e7 m) throw ts::Error naming the file and the key.
StressStudy load_stress_study(const std::filesystem::path& file);

/// Set one case key from text; throws ts::Error naming `file` and `key`.
void set_stress_key(StressCase& c, const std::string& key, const std::string& value,
                    const std::string& file);

/// One run's outcome at its last step.
struct StressRun {
  std::string object;              ///< explored object
  bool correct = false;            ///< the answer's object is the explored one
  bool valid = false;              ///< there was an answer
  double position_error_m = 0.0;
  double orientation_error_deg = 0.0;
  double symmetric_position_error_m = 0.0;     ///< under the object's symmetries (a right answer)
  double symmetric_orientation_error_deg = 0.0;
  bool ambiguous = true;           ///< StepResult::pose_ambiguous
  int unobservable_dof = 6;
  double condition = 0.0;          ///< icp_system at the answer: unitless condition
  double condition_raw = 0.0;      ///< ... as solved (m, rad)
  std::size_t contacts = 0;        ///< contacts given at the last step
  bool finite = true;              ///< every step's poses, weights and posteriors finite
  std::string non_finite;          ///< the first non-finite value found (empty: none)
};

struct StressCaseResult {
  StressCase config;
  std::vector<StressRun> runs;
  double time_s = 0.0;             ///< wall time of the case (database build included)
};

/// Run case `index` of the study. With `out_dir` non-empty,
/// each run's result store is written there (<case>-<run>.h5), read back and checked for
/// non-finite values. Runs in the caller's task arena.
StressCaseResult run_stress_case(const StressStudy& study, std::size_t index,
                                 const std::filesystem::path& out_dir);

/// The study's JSON (config, per case the summary and the runs).
nlohmann::ordered_json stress_json(const StressStudy& study, const std::vector<StressCaseResult>& results);

/// The table the study prints: one row per case.
std::string stress_table(const std::vector<StressCaseResult>& results);

/// The path of the first number in `j` that is NaN or infinite ("" when none).
std::string first_non_finite(const nlohmann::ordered_json& j, const std::string& path = "");

}  // namespace ts::experiments
