#include "experiments/cli/progress.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <iomanip>
#include <sstream>

namespace ts::cli {

void add_progress(CLI::App* sub, ProgressOptions& o) {
  sub->add_option("--progress", o.mode,
                  "auto (a line rewritten on a terminal, else a plain line every 30 s and every 5 %; none "
                  "with --json), bar, lines, json (one JSON object a line), none")
      ->check(CLI::IsMember({"auto", "bar", "lines", "json", "none"}));
  sub->add_flag("--quiet", o.quiet, "No progress (as --progress none)");
}

std::string eta_text(double s) {
  std::ostringstream o;
  if (s < 60) {
    o << static_cast<int>(std::ceil(s)) << " s";
  } else if (s < 3600) {
    o << static_cast<int>(s / 60) << " min " << static_cast<int>(std::fmod(s, 60)) << " s";
  } else {
    o << static_cast<int>(s / 3600) << " h " << static_cast<int>(std::fmod(s, 3600) / 60) << " min";
  }
  return o.str();
}

namespace {
std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}
}  // namespace

ProgressReport::ProgressReport(const ProgressOptions& o, std::string command, std::string unit, bool terminal,
                               bool json_output, std::ostream& out, double line_interval_s)
    : command_(std::move(command)), unit_(std::move(unit)), out_(out), interval_s_(line_interval_s) {
  if (o.quiet || o.mode == "none" || (o.mode == "auto" && json_output))
    mode_ = Mode::none;
  else if (o.mode == "json")
    mode_ = Mode::json;
  else if (o.mode == "lines" || (o.mode == "auto" && !terminal))
    mode_ = Mode::lines;
  else
    mode_ = Mode::bar;
}

void ProgressReport::update(std::size_t done, std::size_t total, double rate_per_min, std::optional<double> left_s) {
  if (mode_ == Mode::none) return;
  const double percent = 100.0 * static_cast<double>(done) / static_cast<double>(total > 0 ? total : 1);
  if (mode_ == Mode::bar) {
    std::ostringstream line;
    line << "\r  " << unit_ << ' ' << done << "/" << total << " (" << std::fixed << std::setprecision(1) << percent
         << " %), " << std::setprecision(2) << rate_per_min << ' ' << unit_ << "/min";
    if (left_s) line << ", " << eta_text(*left_s) << " left";
    out_ << line.str() << "      " << std::flush;
    bar_open_ = true;
    return;
  }
  // Lines: the first, then every interval and every 5 %, and the last.
  const auto now = std::chrono::steady_clock::now();
  const int twentieth = static_cast<int>(std::floor(percent / 5.0));
  const bool due = !printed_ || twentieth > last_twentieth_ || done >= total ||
                   std::chrono::duration<double>(now - last_line_).count() >= interval_s_;
  if (!due) return;
  printed_ = true;
  last_twentieth_ = twentieth;
  last_line_ = now;
  if (mode_ == Mode::json) {
    nlohmann::ordered_json j;
    j["progress"] = command_;
    j["time"] = utc_now();
    j["unit"] = unit_;
    j["done"] = done;
    j["total"] = total;
    j["percent"] = percent;
    j["rate_per_min"] = rate_per_min;
    j["left_s"] = left_s ? nlohmann::ordered_json(*left_s) : nlohmann::ordered_json(nullptr);
    out_ << j.dump() << '\n' << std::flush;
    return;
  }
  std::ostringstream line;
  line << utc_now() << ' ' << command_ << ": " << unit_ << ' ' << done << "/" << total << " (" << std::fixed
       << std::setprecision(1) << percent << " %), " << std::setprecision(2) << rate_per_min << ' ' << unit_ << "/min";
  if (left_s) line << ", " << eta_text(*left_s) << " left";
  out_ << line.str() << '\n' << std::flush;
}

void ProgressReport::update(std::size_t done, std::size_t total) {
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count();
  update(done, total, 60.0 * static_cast<double>(done) / std::max(1e-9, elapsed),
         done ? std::optional<double>(elapsed / static_cast<double>(done) * static_cast<double>(total - done))
              : std::nullopt);
}

void ProgressReport::note(const std::string& text) {
  if (mode_ == Mode::bar || mode_ == Mode::lines) out_ << text << '\n' << std::flush;
}

void ProgressReport::finish() {
  if (bar_open_) out_ << '\n' << std::flush;
  bar_open_ = false;
}

}  // namespace ts::cli
