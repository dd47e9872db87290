// `touchstone stress`: the stiff and extreme cases study (experiments/runs/stress.hpp,
// docs/testing.md "Stiff and extreme cases (study 10)").
#include "experiments/cli/cli_common.hpp"
#include "experiments/resources.hpp"
#include "experiments/runs/stress.hpp"

#include <algorithm>
#include <filesystem>
#include <iostream>
#include <sstream>

namespace ts::cli {

namespace {

struct StressOptions {
  CommonOptions common;
  std::string config, out, cases;
  int runs = 0;
  bool seed_given = false;   ///< --seed on the command line (else the configuration's seed)
};

int run_stress(const StressOptions& o) {
  experiments::StressStudy study = experiments::load_stress_study(o.config);
  if (o.runs != 0) {
    if (o.runs < 1 || o.runs > 200) throw Error("--runs must lie in 1..200", "", "--runs");
    study.runs = o.runs;
  }
  if (o.seed_given) study.seed = o.common.seed;
  if (!o.cases.empty()) {
    std::vector<experiments::StressCase> keep;
    std::stringstream ss(o.cases);
    std::string name;
    while (std::getline(ss, name, ',')) {
      const auto it = std::find_if(study.cases.begin(), study.cases.end(),
                                   [&](const experiments::StressCase& c) { return c.name == name; });
      if (it == study.cases.end()) throw Error("no case named '" + name + "'", o.config, "--cases");
      keep.push_back(*it);
    }
    study.cases = keep;
  }
  if (!o.out.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(o.out, ec);
    if (ec || !std::filesystem::is_directory(o.out))
      throw Error("cannot create the output folder: " + ec.message(), o.out, "--out");
  }
  std::vector<experiments::StressCaseResult> results;
  for (std::size_t i = 0; i < study.cases.size(); ++i) {
    results.push_back(experiments::run_stress_case(study, i, o.out));
    std::cerr << "stress: " << study.cases[i].name << " done in " << results.back().time_s << " s\n";
  }
  nlohmann::ordered_json j = experiments::stress_json(study, results);
  j["threads"] = thread_count(o.common);
  j["machine"] = experiments::machine_description();
  const std::string bad_json = experiments::first_non_finite(j);
  std::string bad_run;
  for (const auto& r : results)
    for (const auto& run : r.runs)
      if (!run.finite && bad_run.empty()) bad_run = r.config.name + ": " + run.non_finite;
  if (o.common.json) {
    std::cout << j.dump(2) << "\n";
  } else {
    std::cout << experiments::stress_table(results);
    std::cout << "\n" << study.runs << " runs per case, preset " << study.preset << ", seed "
              << study.seed << ", " << thread_count(o.common) << " threads, "
              << experiments::machine_description() << "\n";
    std::cout << "non-finite values in the outputs (steps, JSON"
              << (o.out.empty() ? "" : ", result stores") << "): "
              << (bad_json.empty() && bad_run.empty() ? "none" : "FOUND") << "\n";
  }
  if (!bad_json.empty()) throw Error("a non-finite value in the JSON output", o.config, bad_json);
  if (!bad_run.empty()) throw Error("a non-finite value in an output: " + bad_run, o.config);
  return 0;
}

}  // namespace

void register_stress(CLI::App& app) {
  auto o = std::make_shared<StressOptions>();
  CLI::App* sub = app.add_subcommand(
      "stress", "Stiff and extreme cases: object size, distance from the origin, arm noise, contact "
                "counts, duplicated and collinear contacts, a flat patch, a long rod (docs/testing.md, study 10)");
  sub->add_option("--config", o->config, "Study configuration (TOML), e.g. "
                                         "experiments/studies/stress/study10_extreme.toml")
      ->required();
  sub->add_option("--out", o->out, "Folder for each run's result store (read back and checked)");
  sub->add_option("--cases", o->cases, "Only these cases (comma-separated names)");
  sub->add_option("--runs", o->runs, "Runs per case (default: the configuration's)");
  add_common(sub, o->common);
  sub->callback([o, sub] {
    o->seed_given = sub->get_option("--seed")->count() > 0;
    run_command(o->common, [o] { return run_stress(*o); });
  });
}

}  // namespace ts::cli
