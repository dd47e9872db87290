#include "io/atomic_file.hpp"

#include "engine/core.hpp"

#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstring>
#include <fcntl.h>
#include <mutex>
#include <unistd.h>

namespace ts::io {

namespace {

// Temporary files in progress, for the SIGINT/SIGTERM handler: fixed slots of C strings, so
// that the handler only reads memory and calls unlink (both async-signal-safe).
constexpr int kSlots = 32;
constexpr std::size_t kPathMax = 4096;
char g_paths[kSlots][kPathMax];
std::atomic<bool> g_used[kSlots];
std::mutex g_mutex;  // registration only (never taken in the handler)

extern "C" void remove_temporaries_and_reraise(int sig) {
  for (int i = 0; i < kSlots; ++i)
    if (g_used[i].load()) ::unlink(g_paths[i]);
  std::signal(sig, SIG_DFL);  // then die of the signal as if unhandled
  std::raise(sig);
}

int register_temp(const std::filesystem::path& p) {
  const std::string s = std::filesystem::absolute(p).string();
  if (s.size() >= kPathMax) return -1;
  std::lock_guard<std::mutex> lock(g_mutex);
  for (int i = 0; i < kSlots; ++i)
    if (!g_used[i].load()) {
      std::memcpy(g_paths[i], s.c_str(), s.size() + 1);
      g_used[i].store(true);
      return i;
    }
  return -1;  // more than kSlots outputs at once: the destructor still cleans up
}

void unregister_temp(int slot) {
  if (slot < 0) return;
  std::lock_guard<std::mutex> lock(g_mutex);
  g_used[slot].store(false);
}

}  // namespace

void remove_temporaries_on_interrupt() {
  for (int sig : {SIGINT, SIGTERM}) {
    struct sigaction sa {};
    sa.sa_handler = remove_temporaries_and_reraise;
    sigemptyset(&sa.sa_mask);
    sigaction(sig, &sa, nullptr);
  }
}

namespace {

/// Flush a file's (or a directory's) data and metadata to the disk; errors are reported.
void sync_path(const std::filesystem::path& p, const std::string& what, const std::string& target) {
  const int fd = ::open(p.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw Error("cannot open " + what + " to flush it: " + std::strerror(errno), target);
  const int rc = ::fsync(fd);
  const int err = errno;
  ::close(fd);
  if (rc != 0 && err != EINVAL)   // (EINVAL: a file system without fsync on this kind of file)
    throw Error("cannot flush " + what + " to the disk: " + std::strerror(err), target);
}

std::atomic<unsigned long> g_serial{0};

}  // namespace

AtomicOutput::AtomicOutput(std::filesystem::path target) : target_(std::move(target)) {
  // Unique within the process as well: two outputs to one target (threads) never share a file.
  temp_ = target_;
  temp_ += ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(g_serial.fetch_add(1));
  const auto dir = target_.has_parent_path() ? target_.parent_path() : std::filesystem::path(".");
  if (!std::filesystem::is_directory(dir))
    throw Error("output directory does not exist", target_.string());
  slot_ = register_temp(temp_);
}

AtomicOutput::~AtomicOutput() {
  unregister_temp(slot_);
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove(temp_, ec);
  }
}

void AtomicOutput::commit() {
  // The data reach the disk before the name does: after a power cut the target is the old file
  // or the whole new one, never a renamed file whose blocks were not written yet.
  sync_path(temp_, "the finished output", target_.string());
  std::error_code ec;
  std::filesystem::rename(temp_, target_, ec);
  if (ec) throw Error("cannot move the finished output into place: " + ec.message(), target_.string());
  const auto dir = target_.has_parent_path() ? target_.parent_path() : std::filesystem::path(".");
  sync_path(dir, "the output's folder", target_.string());   // the rename itself
  committed_ = true;
  unregister_temp(slot_);
  slot_ = -1;
}

}  // namespace ts::io
