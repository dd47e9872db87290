// Run the built `touchstone` program as a user does (CLI tests).
#pragma once

#include "temp_dir.hpp"

#include <cstdlib>
#include <filesystem>
#include <string>
#include <sys/wait.h>

namespace ts::test {

struct CliRun {
  int code = -1;         ///< exit code (-1: killed by a signal)
  std::string out, err;  ///< stdout, stderr
};

/// `touchstone <args>` with `dir` as the working directory; stdout, stderr and the exit code.
/// The capture files are removed again, so `dir` holds only what the command wrote. `launcher`
/// goes before the program (e.g. "mpirun -n 2").
inline CliRun touchstone(const TempDir& dir, const std::string& args, const std::string& launcher = "") {
  const auto out = dir / ".stdout.txt", err = dir / ".stderr.txt";
  const std::string cmd = "cd '" + dir.path().string() + "' && " + launcher + " '" TS_BINARY_DIR "/touchstone' " + args +
                          " >'" + out.string() + "' 2>'" + err.string() + "'";
  const int status = std::system(cmd.c_str());
  CliRun r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.out = read_bytes(out);
  r.err = read_bytes(err);
  std::filesystem::remove(out);
  std::filesystem::remove(err);
  return r;
}

}  // namespace ts::test
