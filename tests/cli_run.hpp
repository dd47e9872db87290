// Run the `touchstone` command as a user does (CLI tests): in this process where a test checks the
// command's logic, as the built program where only a process shows what is checked.
#pragma once

#include "experiments/cli/cli_common.hpp"
#include "temp_dir.hpp"

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fcntl.h>
#include <iostream>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

namespace ts::test {

struct CliRun {
  int code = -1;         ///< exit code (-1: killed by a signal)
  std::string out, err;  ///< stdout, stderr
};

/// `touchstone <args>` as a process: the built program, started by the shell with `dir` as the
/// working directory; stdout, stderr and the exit code. The capture files are removed again, so
/// `dir` holds only what the command wrote. `launcher` goes before the program (e.g.
/// "mpirun -n 2"). For what only a process shows: the allocator it runs on, signals, MPI, shell
/// redirections, files left behind by a process that ends.
inline CliRun touchstone_process(const TempDir& dir, const std::string& args, const std::string& launcher = "") {
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

namespace detail {

/// `args` split into words as the shell splits them ('...' and "..." quote, \ escapes), or
/// nothing when they hold what only a shell does (redirections, pipes, variables, globs, ...).
inline std::optional<std::vector<std::string>> shell_words(const std::string& args) {
  std::vector<std::string> words;
  std::string word;
  bool in_word = false;
  for (std::size_t i = 0; i < args.size(); ++i) {
    const char c = args[i];
    if (c == ' ' || c == '\t' || c == '\n') {
      if (in_word) words.push_back(word);
      word.clear();
      in_word = false;
    } else if (c == '\'') {
      const auto end = args.find('\'', i + 1);
      if (end == std::string::npos) return std::nullopt;
      word += args.substr(i + 1, end - i - 1);
      i = end;
      in_word = true;
    } else if (c == '"') {
      std::size_t j = i + 1;
      for (; j < args.size() && args[j] != '"'; ++j) {
        if (args[j] == '$' || args[j] == '`') return std::nullopt;
        if (args[j] == '\\' && j + 1 < args.size()) ++j;
        word += args[j];
      }
      if (j >= args.size()) return std::nullopt;
      i = j;
      in_word = true;
    } else if (c == '\\' && i + 1 < args.size()) {
      word += args[++i];
      in_word = true;
    } else if (std::string_view("<>|&;$`*?[]{}()~#").find(c) != std::string_view::npos) {
      return std::nullopt;  // a shell's business: run the program
    } else {
      word += c;
      in_word = true;
    }
  }
  if (in_word) words.push_back(word);
  return words;
}

/// Points file descriptor `fd` at `path` until destroyed (the process's stdout or stderr).
class FdRedirect {
 public:
  FdRedirect(int fd, const std::filesystem::path& path) : fd_(fd), saved_(::dup(fd)) {
    const int file = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (saved_ < 0 || file < 0 || ::dup2(file, fd) < 0) throw std::runtime_error("cannot redirect to " + path.string());
    ::close(file);
  }
  ~FdRedirect() {
    ::dup2(saved_, fd_);
    ::close(saved_);
  }
  FdRedirect(const FdRedirect&) = delete;
  FdRedirect& operator=(const FdRedirect&) = delete;

 private:
  int fd_, saved_;
};

/// Keeps a stream's formatting (a command may set precision or fixed) from one command to the next.
class StreamState {
 public:
  explicit StreamState(std::ostream& s) : s_(s), flags_(s.flags()), precision_(s.precision()), fill_(s.fill()) {}
  ~StreamState() {
    s_.flags(flags_);
    s_.precision(precision_);
    s_.fill(fill_);
    s_.clear();
  }
  StreamState(const StreamState&) = delete;
  StreamState& operator=(const StreamState&) = delete;

 private:
  std::ostream& s_;
  std::ios_base::fmtflags flags_;
  std::streamsize precision_;
  char fill_;
};

/// Makes `dir` the working directory for a scope.
class WorkingDir {
 public:
  explicit WorkingDir(const std::filesystem::path& dir) : saved_(std::filesystem::current_path()) {
    std::filesystem::current_path(dir);
  }
  ~WorkingDir() { std::filesystem::current_path(saved_); }
  WorkingDir(const WorkingDir&) = delete;
  WorkingDir& operator=(const WorkingDir&) = delete;

 private:
  std::filesystem::path saved_;
};

}  // namespace detail

/// `touchstone <args>` with `dir` as the working directory: stdout, stderr and the exit code. The
/// command's code runs in this process (ts::cli::run_touchstone, what main() runs) with stdout
/// and stderr captured, unless `launcher` is given, the arguments need a shell (redirections,
/// variables, globs) or use --mpi; then the built program runs (touchstone_process). The capture
/// files are removed again, so `dir` holds only what the command wrote. TS_CLI_PROCESS=1 in the
/// environment runs every command as a process.
inline CliRun touchstone(const TempDir& dir, const std::string& args, const std::string& launcher = "") {
  const auto words = detail::shell_words(args);
  const char* force = std::getenv("TS_CLI_PROCESS");
  if (!launcher.empty() || !words || args.find("--mpi") != std::string::npos || (force && std::string(force) == "1"))
    return touchstone_process(dir, args, launcher);
  std::vector<std::string> argv_words{"touchstone"};
  argv_words.insert(argv_words.end(), words->begin(), words->end());
  std::vector<char*> argv;
  for (auto& w : argv_words) argv.push_back(w.data());
  argv.push_back(nullptr);
  const auto out = dir / ".stdout.txt", err = dir / ".stderr.txt";
  CliRun r;
  {
    std::cout.flush();
    std::cerr.flush();
    std::fflush(nullptr);
    detail::StreamState cout_state(std::cout), cerr_state(std::cerr);
    detail::WorkingDir cwd(dir.path());
    detail::FdRedirect to_out(STDOUT_FILENO, out), to_err(STDERR_FILENO, err);
    try {
      r.code = ts::cli::run_touchstone(int(argv_words.size()), argv.data(), TS_VERSION);
    } catch (const std::exception& e) {  // main() would have died of it
      std::cerr << "touchstone: uncaught exception: " << e.what() << '\n';
      r.code = -1;
    }
    std::cout.flush();
    std::cerr.flush();
    std::fflush(nullptr);
  }
  r.out = read_bytes(out);
  r.err = read_bytes(err);
  std::filesystem::remove(out);
  std::filesystem::remove(err);
  return r;
}

}  // namespace ts::test
