// Progress of long commands where the user is: a line rewritten in place on a terminal; plain
// lines a log file keeps when stderr is not a terminal (Slurm, nohup, CI): one every 30 s and
// every 5 % done; JSON lines for workflow tools; nothing with --quiet. Everything goes to stderr.
#pragma once

#include <CLI/CLI.hpp>

#include <chrono>
#include <cstddef>
#include <optional>
#include <ostream>
#include <string>

namespace ts::cli {

struct ProgressOptions {
  std::string mode = "auto";   ///< auto | bar | lines | json | none
  bool quiet = false;          ///< --quiet: as none
};

/// Add --progress and --quiet to a subcommand.
void add_progress(CLI::App* sub, ProgressOptions& options);

/// "12 s", "3 min 4 s", "2 h 5 min".
std::string eta_text(double seconds);

class ProgressReport {
 public:
  /// `command` names the work in lines and JSON ("experiment"); `unit` what is counted ("runs").
  /// auto: bar on a terminal, else lines; none under --json (`json_output`: a program reads the
  /// output; it asks for --progress lines or json when it wants them). `out` is stderr unless a
  /// test gives another stream.
  ProgressReport(const ProgressOptions& options, std::string command, std::string unit, bool terminal,
                 bool json_output, std::ostream& out, double line_interval_s = 30.0);
  bool active() const { return mode_ != Mode::none; }
  /// `done` of `total` (done includes earlier sessions); `rate_per_min` and `left_s` from this
  /// session (left_s: nullopt before anything was done).
  void update(std::size_t done, std::size_t total, double rate_per_min, std::optional<double> left_s);
  /// The same with the rate and the time left measured from this report's construction (all of
  /// `done` counted as this session's work).
  void update(std::size_t done, std::size_t total);
  /// Ends a bar's line (no-op otherwise).
  void finish();
  /// A line for a person (bar and lines; not json or none).
  void note(const std::string& text);

 private:
  enum class Mode { bar, lines, json, none };
  Mode mode_;
  std::string command_, unit_;
  std::ostream& out_;
  double interval_s_;
  bool printed_ = false, bar_open_ = false;
  int last_twentieth_ = -1;
  std::chrono::steady_clock::time_point last_line_;
  std::chrono::steady_clock::time_point started_ = std::chrono::steady_clock::now();
};

}  // namespace ts::cli
