// `touchstone experiment` on configurations it cannot run: one error naming the configuration
// file and the key, exit 1, and no run store (nor anything else) left behind.
#include "cli_run.hpp"
#include "db_fixture.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using ts::test::TempDir;

TEST_CASE("cli experiment: sizes that cannot fit in memory are refused before any output exists") {
  // Issue 57: these ended in a bare std::bad_alloc, with a run store made and left behind.
  TempDir dir("cli_exp");
  ts::test::make_db(dir);
  const std::vector<std::pair<std::string, std::string>> configs = {
      {"objects = [\"box\"]\nruns = 1\nsteps = 1\nransac.samples = \"100000000x100000000\"\n", "ransac.samples"},
      {"objects = [\"box\"]\nruns = 1\nsteps = 1\nransac.samples = \"1000000x1000000\"\n", "ransac.samples"},
      {"runs = 100000000\nsteps = 1000000\npool = 1000000\n", "runs"},
  };
  for (const auto& [text, key] : configs) {
    CAPTURE(text);
    ts::test::write_text(dir / "exp.toml", text);
    const auto r = ts::test::touchstone(dir, "experiment --db db.h5 --config exp.toml --out run.h5 --threads 1");
    CHECK(r.code == 1);
    CHECK_MESSAGE(r.err.rfind("touchstone: error: ", 0) == 0, r.err);
    CHECK_MESSAGE(std::count(r.err.begin(), r.err.end(), '\n') == 1, r.err);
    CHECK_MESSAGE(r.err.ends_with("(exp.toml, " + key + ")\n"), r.err);
    CHECK(r.out.empty());
    std::vector<std::string> left;
    for (const auto& e : fs::directory_iterator(dir.path())) left.push_back(e.path().filename().string());
    std::sort(left.begin(), left.end());
    CHECK(left == std::vector<std::string>{"db.h5", "exp.toml"});
  }
}
