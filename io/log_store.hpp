// Tactile logs in HDF5: the layout of io/FORMAT_LOG.md. A log holds what a robot records per
// grasp (arm pose, finger joint angles, tactile images, timestamps), the gripper description,
// the sensor calibration and, for simulated logs, an evaluation-only ground-truth group.
//
// Grasps are appended to chunked, extendible datasets, so a log can grow during a dive without
// rewriting what is already there (LogWriter::append_to). Whole-log writes (write_log, the
// simulator) go through io::AtomicOutput: the file appears complete or not at all.
//
// Reading validates everything (ts::validate(TactileLog) plus the file's structure): a missing
// group or dataset, mismatched image sizes, NaN in poses or images, negative or over-range
// signals, a bad gripper description each throw one ts::Error naming the file and the field.
//
// All functions take the HDF5 wrapper's global mutex; call them from any thread.
#pragma once

#include "engine/touch/fusion.hpp"

#include <filesystem>
#include <memory>
#include <optional>
#include <string>

namespace ts::io {

constexpr const char* kLogFormat = "touchstone-tactile-log";
constexpr int kLogFormatVersion = 5;   ///< read: 1 to 5; written: 1 (pads), 2 (probe), 3 (fingertips),
                                       ///< 4 (a simulated scene's support in the ground truth), 5 (and
                                       ///< a cluttered scene's neighbours)

/// Everything of a log except its grasps (what a writer needs before the first grasp).
struct LogHeader {
  std::string object;
  std::string noise = "real";
  std::uint64_t seed = 0;
  Gripper gripper;
  std::vector<int> pads;
  std::vector<float> gains;
  std::optional<Pose> true_object_pose;  ///< set: the log carries a /ground_truth group
  std::string source;                    ///< free text: who wrote it ("touchstone simulate ...")
  Sensing sensing = Sensing::pads;       ///< probe: no /sensors, no joints or images;
                                         ///< fingertips: no /sensors or images, fingertip points
  ProbeSpec probe;
  bool fingertip_normals = false;        ///< fingertips: the grasps carry normals
  std::string true_scene = "none";       ///< ground truth: the simulated scene (with true_object_pose)
  Mesh true_support;                     ///< ground truth: its support, world frame (empty: none)
  std::vector<LogGroundTruth::Neighbour> true_neighbours;   ///< ground truth: a cluttered scene's
                                                            ///< other objects (with a support)
};

LogHeader header_of(const TactileLog& log);
/// A log of that header: its object, noise, seed, gripper, pads, gains and sensing, without
/// grasps or ground truth.
TactileLog log_of(const LogHeader& header);

/// Appends grasps to a log file. Not copyable; closes on destruction (errors then are lost:
/// call close() to see them).
class LogWriter {
 public:
  /// Create a new log at `path` (truncating it). With `atomic`, the file is written under a
  /// temporary name and only appears at `path` on close().
  static LogWriter create(const std::filesystem::path& path, const LogHeader& header, bool atomic = true);
  /// Open an existing log to append grasps (validates its header; grasps are not rewritten).
  static LogWriter append_to(const std::filesystem::path& path);

  LogWriter(LogWriter&&) noexcept;
  LogWriter& operator=(LogWriter&&) noexcept;
  ~LogWriter();

  const LogHeader& header() const;
  std::size_t grasps() const;
  /// Append one grasp. `truth_arm_pose` / `truth_joints` are required when the log has a
  /// ground-truth group and refused otherwise. The record is validated first (nothing is
  /// written when it is bad).
  void append(const GraspRecord& grasp, const Pose* truth_arm_pose = nullptr,
              const std::vector<double>* truth_joints = nullptr);
  void close();

 private:
  LogWriter();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Write a whole log (atomically).
void write_log(const std::filesystem::path& path, const TactileLog& log);
/// Read and validate a whole log.
TactileLog read_log(const std::filesystem::path& path);

}  // namespace ts::io
