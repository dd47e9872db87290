// Progress where the user is (experiments/cli/progress.hpp): plain lines every 5 % and every
// interval when not on a terminal, JSON lines, nothing with --quiet; the experiment command's
// flags.
#include "experiments/cli/progress.hpp"

#include "cli_run.hpp"
#include "db_fixture.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <sstream>
#include <string>
#include <vector>

using namespace ts;

namespace {
std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);)
    if (!l.empty()) out.push_back(l);
  return out;
}
}  // namespace

TEST_CASE("progress lines: the first, every 5 % and the last; an interval of 0 prints every update") {
  cli::ProgressOptions o;   // auto, not on a terminal: lines
  std::ostringstream out;
  cli::ProgressReport p(o, "experiment", "runs", false, false, out, 1e9);
  for (std::size_t done = 1; done <= 100; ++done) p.update(done, 100, 10.0, 60.0);
  p.finish();
  const auto lines = lines_of(out.str());
  REQUIRE(lines.size() == 21);   // 1 %, then 5, 10, ..., 100 %
  CHECK(lines[0].find("experiment: runs 1/100 (1.0 %), 10.00 runs/min, 1 min 0 s left") != std::string::npos);
  CHECK(lines[1].find("runs 5/100 (5.0 %)") != std::string::npos);
  CHECK(lines.back().find("runs 100/100 (100.0 %)") != std::string::npos);
  CHECK(lines[0].size() > 20);
  CHECK(lines[0][4] == '-');     // starts with the UTC date
  std::ostringstream every;
  cli::ProgressReport q(o, "experiment", "runs", false, false, every, 0.0);
  for (std::size_t done = 1; done <= 7; ++done) q.update(done, 1000, 1.0, std::nullopt);
  CHECK(lines_of(every.str()).size() == 7);
  CHECK(every.str().find("left") == std::string::npos);   // no estimate before a rate
}

TEST_CASE("progress: json lines, a terminal's bar, none and --quiet") {
  cli::ProgressOptions o;
  o.mode = "json";
  std::ostringstream js;
  cli::ProgressReport j(o, "experiment", "runs", true, true, js, 1e9);
  j.note("not in JSON mode");
  for (std::size_t done = 1; done <= 4; ++done) j.update(done, 4, 2.0, done == 4 ? 0.0 : 30.0);
  const auto lines = lines_of(js.str());
  REQUIRE(lines.size() == 4);   // 25 % steps: every update crosses a 5 % mark
  for (std::size_t i = 0; i < lines.size(); ++i) {
    const auto x = nlohmann::json::parse(lines[i]);
    CHECK(x["progress"] == "experiment");
    CHECK(x["done"] == i + 1);
    CHECK(x["total"] == 4);
    CHECK(x["percent"].get<double>() == doctest::Approx(25.0 * static_cast<double>(i + 1)));
    CHECK(x["left_s"].is_number());
  }
  o.mode = "auto";
  std::ostringstream bar;
  cli::ProgressReport b(o, "experiment", "runs", true, false, bar);
  b.update(1, 2, 1.0, 60.0);
  b.finish();
  CHECK(bar.str().rfind("\r  runs 1/2 (50.0 %)", 0) == 0);
  CHECK(bar.str().back() == '\n');
  for (const bool quiet : {false, true}) {
    cli::ProgressOptions n;
    n.mode = quiet ? "auto" : "none";
    n.quiet = quiet;
    std::ostringstream none;
    cli::ProgressReport r(n, "experiment", "runs", false, false, none);
    r.note("hello");
    r.update(1, 1, 1.0, 0.0);
    r.finish();
    CHECK(none.str().empty());
    CHECK_FALSE(r.active());
  }
}

TEST_CASE("cli experiment: --progress lines | json, --quiet, and an unknown format refused") {
  test::TempDir dir("progress");
  test::make_db(dir);
  const std::string base = "experiment --db db.h5 --objects box,nut --runs 1 --steps 2 --pool 2 --json";
  const auto lines = test::touchstone(dir, base + " --progress lines --out a.h5");
  REQUIRE_MESSAGE(lines.code == 0, lines.err);
  CHECK(lines.err.find("Experiment '") != std::string::npos);
  CHECK(lines.err.find("experiment: runs 1/2 (50.0 %)") != std::string::npos);
  CHECK(lines.err.find("experiment: runs 2/2 (100.0 %)") != std::string::npos);
  const auto js = test::touchstone(dir, base + " --progress json --out b.h5");
  REQUIRE_MESSAGE(js.code == 0, js.err);
  const auto jl = lines_of(js.err);
  REQUIRE(jl.size() == 2);
  for (const auto& l : jl) CHECK(nlohmann::json::parse(l)["total"] == 2);
  for (const std::string flags : {" --quiet", ""}) {   // --json alone: no progress unless asked
    const auto quiet = test::touchstone(dir, base + flags + " --out c" + std::to_string(flags.size()) + ".h5");
    REQUIRE_MESSAGE(quiet.code == 0, quiet.err);
    CHECK(quiet.err.empty());
  }
  const auto plain = test::touchstone(dir, "experiment --db db.h5 --objects box,nut --runs 1 --steps 2 --pool 2 --out e.h5");
  REQUIRE_MESSAGE(plain.code == 0, plain.err);
  CHECK(plain.err.find("experiment: runs 2/2 (100.0 %)") != std::string::npos);   // not a terminal: lines
  // recognize over several inputs: a line per 5 % of inputs, here per input.
  for (const std::string object : {"box", "nut"})
    REQUIRE(test::touchstone(dir, "simulate --db db.h5 --object " + object + " --grasps 2 --noise ideal --out " + object +
                                      "_log.h5").code == 0);
  const auto many = test::touchstone(dir, "recognize --db db.h5 --log box_log.h5 nut_log.h5 --progress lines --threads 1");
  REQUIRE_MESSAGE(many.code == 0, many.err);
  CHECK(many.err.find("recognize: inputs 1/2 (50.0 %)") != std::string::npos);
  CHECK(many.err.find("recognize: inputs 2/2 (100.0 %)") != std::string::npos);
  const auto bad = test::touchstone(dir, base + " --progress fancy --out d.h5");
  CHECK(bad.code == 2);
  CHECK(bad.err.find("--progress") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(dir / "d.h5"));
}
