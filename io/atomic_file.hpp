// Outputs are written under a temporary name beside the target and renamed when complete, so
// a failure or a kill never leaves a half-written file under the real name. A program that calls
// remove_temporaries_on_interrupt() (the touchstone command does) also removes the temporary
// files in progress on Ctrl-C (SIGINT) or SIGTERM.
#pragma once

#include <filesystem>
#include <string>

namespace ts::io {

/// Handle SIGINT and SIGTERM: unlink every AtomicOutput's temporary file in progress, then die
/// of the signal as if unhandled. Async-signal-safe (fixed slots, unlink only).
void remove_temporaries_on_interrupt();

class AtomicOutput {
 public:
  /// Reserve `target`; temp_path() is "<target>.tmp-<pid>-<serial>" in the same directory
  /// (unique within the process too).
  explicit AtomicOutput(std::filesystem::path target);
  ~AtomicOutput();  ///< removes the temporary file unless commit() succeeded
  AtomicOutput(const AtomicOutput&) = delete;
  AtomicOutput& operator=(const AtomicOutput&) = delete;

  const std::filesystem::path& temp_path() const { return temp_; }
  const std::filesystem::path& target() const { return target_; }
  /// Flush the temporary file to the disk (fsync), rename it onto the target (atomic on one
  /// file system), then flush the folder, so that the rename survives a power cut.
  void commit();

 private:
  std::filesystem::path target_, temp_;
  bool committed_ = false;
  int slot_ = -1;   ///< registration for the signal handler
};

}  // namespace ts::io
