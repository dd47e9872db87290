#include "io/atomic_file.hpp"

#include "engine/core.hpp"

#include <unistd.h>

namespace ts::io {

AtomicOutput::AtomicOutput(std::filesystem::path target) : target_(std::move(target)) {
  temp_ = target_;
  temp_ += ".tmp-" + std::to_string(::getpid());
  const auto dir = target_.has_parent_path() ? target_.parent_path() : std::filesystem::path(".");
  if (!std::filesystem::is_directory(dir))
    throw Error("output directory does not exist", target_.string());
}

AtomicOutput::~AtomicOutput() {
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove(temp_, ec);
  }
}

void AtomicOutput::commit() {
  std::error_code ec;
  std::filesystem::rename(temp_, target_, ec);
  if (ec) throw Error("cannot move the finished output into place: " + ec.message(), target_.string());
  committed_ = true;
}

}  // namespace ts::io
