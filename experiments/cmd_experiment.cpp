// `touchstone experiment` and `touchstone report`: run an experiment into a run store (resumable)
// and report it as tables, the interface's JSON, and figures.
#include "experiments/cli_common.hpp"
#include "experiments/config.hpp"
#include "experiments/driver.hpp"
#include "experiments/recognition_engine.hpp"
#include "experiments/report.hpp"
#include "io/run_store.hpp"

#include <csignal>
#include <cmath>
#include <cstdio>
#include <iomanip>
#include <iostream>
#include <sstream>

namespace ts::cli {

namespace {

using experiments::ExperimentConfig;

struct ExperimentOptions {
  CommonOptions common;
  std::string db, config_file, out, plots;
  std::string objects, runs, steps, pool, method, preset, noise, sensors, schedule, memory_budget;
  std::vector<std::string> set;   ///< KEY=VALUE, any configuration key
  bool resume = false;
  bool seed_given = false;
};

struct ReportOptions {
  CommonOptions common;
  std::string store, plots;
};

// --- Ctrl-C: finish cleanly (runs in flight are dropped, the store stays consistent) ---------
std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) { g_stop = true; }

class SignalGuard {
 public:
  SignalGuard() {
    struct sigaction sa {};
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, &old_int_);
    sigaction(SIGTERM, &sa, &old_term_);
  }
  ~SignalGuard() {
    sigaction(SIGINT, &old_int_, nullptr);
    sigaction(SIGTERM, &old_term_, nullptr);
  }

 private:
  struct sigaction old_int_ {}, old_term_ {};
};

std::string duration_text(double s) {
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

/// Configuration: defaults, then the file, then each flag (validated by the same setter; a bad
/// flag's error names the flag).
ExperimentConfig build_config(const ExperimentOptions& o) {
  ExperimentConfig c;
  if (!o.config_file.empty()) experiments::load_config_file(c, o.config_file);
  auto flag = [&](const std::string& value, const std::string& key) {
    if (value.empty()) return;
    try {
      experiments::set_key(c, key, {value});
    } catch (const Error& e) {
      throw Error(e.message(), {}, "--" + key);
    }
  };
  flag(o.objects, "objects");
  flag(o.runs, "runs");
  flag(o.steps, "steps");
  flag(o.pool, "pool");
  flag(o.method, "method");
  flag(o.preset, "preset");
  flag(o.noise, "noise");
  flag(o.sensors, "sensors");
  flag(o.schedule, "schedule");
  flag(o.memory_budget, "memory_budget_mb");
  if (o.seed_given) c.seed = o.common.seed;
  for (const std::string& kv : o.set) {
    const auto eq = kv.find('=');
    if (eq == std::string::npos || eq == 0)
      throw Error("--set expects KEY=VALUE (got '" + kv + "')", {}, "--set");
    const std::string key = kv.substr(0, eq), value = kv.substr(eq + 1);
    std::vector<std::string> inputs;
    if (key.rfind("sweep.", 0) == 0) {  // --set sweep.method=bricpsf,ransac-icp
      std::size_t start = 0;
      while (start <= value.size()) {
        const std::size_t comma = std::min(value.find(',', start), value.size());
        inputs.push_back(value.substr(start, comma - start));
        start = comma + 1;
      }
    } else {
      inputs.push_back(value);
    }
    experiments::set_key(c, key, inputs);
  }
  experiments::validate(c, o.config_file);
  return c;
}

void emit_report(const io::RunStoreContents& contents, const experiments::ReportSettings& rs,
                 const std::string& store, bool json, const std::string& plots) {
  const auto report = experiments::report_json(contents, rs, store);
  if (!plots.empty()) {
    const auto files = experiments::write_plots(report, plots);
    if (!json) {
      std::cerr << "Plots:";
      for (const auto& f : files) std::cerr << " " << f.filename().string();
      std::cerr << " (in " << plots << ")\n";
    }
  }
  if (json) {
    std::cout << report.dump(1) << "\n";
  } else {
    experiments::print_report(report, std::cout);
  }
}

int run_experiment(const ExperimentOptions& o) {
  const ExperimentConfig config = build_config(o);
  const int threads = thread_count(o.common);
  std::function<void(const std::string&)> note;
  if (stderr_is_terminal()) note = [](const std::string& line) { std::cerr << line << "\n"; };
  std::unique_ptr<experiments::RunEngine> engine;
  try {
    engine = experiments::make_recognition_engine(config, experiments::open_database(o.db), threads, note);
  } catch (const Error& e) {
    // An unknown object: name where it was listed (the --objects flag, or the configuration
    // file's key) and the database that lacks it.
    if (!e.file().empty() || (e.field() != "objects" && e.field() != "database")) throw;
    const bool flag = e.field() == "objects" && !o.objects.empty();
    if (flag || o.config_file.empty()) throw Error(e.message(), o.db, flag ? "--objects" : e.field());
    std::string message = e.message();
    const std::string lacks = "(not in the database)";
    if (const auto at = message.find(lacks); at != std::string::npos) message.replace(at, lacks.size(), "(not in the database " + o.db + ")");
    throw Error(message, o.config_file, e.field());
  }
  const io::RunStoreHeader& header = engine->header();
  const std::filesystem::path out = o.out;
  std::error_code ec;
  if (std::filesystem::exists(out, ec)) {
    if (!o.resume)
      throw Error("the run store already exists: continue it with --resume, or remove it", o.out, "--out");
    experiments::check_resumable(io::RunStore::read_header(out), header, o.out);
  } else {
    if (o.resume && stderr_is_terminal()) std::cerr << "Nothing to resume: starting " << o.out << "\n";
    io::RunStore::create(out, header);
  }

  const auto tasks = experiments::all_tasks(header, config.runs);
  experiments::DriveSettings ds;
  ds.parallel_runs = config.schedule == "runs";
  g_stop = false;
  ds.stop = &g_stop;
  if (stderr_is_terminal()) {
    ds.on_progress = [&](const experiments::Progress& p) {
      std::ostringstream line;
      line << "\r  runs " << p.done << "/" << p.total << " (" << std::fixed << std::setprecision(1)
           << 100.0 * static_cast<double>(p.done) / static_cast<double>(std::max<std::size_t>(1, p.total))
           << " %), " << std::setprecision(2) << 60.0 * static_cast<double>(p.session_done) / std::max(1e-9, p.elapsed_s)
           << " runs/min";
      if (auto left = p.remaining_s()) line << ", " << duration_text(*left) << " left";
      line << "      ";
      std::cerr << line.str() << std::flush;
    };
  }
  if (stderr_is_terminal())
    std::cerr << "Experiment '" << config.name << "': " << tasks.size() << " runs ("
              << header.variant_labels.size() << " variant(s) x " << header.objects.size()
              << " object(s) x " << config.runs << " runs x " << config.steps << " steps), "
              << threads << " threads\n";
  experiments::DriveOutcome outcome;
  {
    SignalGuard guard;
    outcome = experiments::drive(*engine, tasks, out, ds);
  }
  if (stderr_is_terminal() && outcome.completed > 0) std::cerr << "\n";
  if (outcome.interrupted) {
    const auto stored = io::RunStore::read(out).runs.size();
    std::cerr << "touchstone: interrupted: " << stored << " of " << tasks.size()
              << " runs are stored in " << o.out << "; continue with --resume\n";
    return 130;
  }
  io::RunStore::compact(out, true);
  experiments::ReportSettings rs;
  rs.threads = threads;
  rs.machine = machine_description();
  emit_report(io::RunStore::read(out), rs, o.out, o.common.json, o.plots);
  return 0;
}

int run_report(const ReportOptions& o) {
  const io::RunStoreContents contents = io::RunStore::read(o.store);
  emit_report(contents, {}, o.store, o.common.json, o.plots);
  return 0;
}

}  // namespace

void register_experiment(CLI::App& app) {
  auto eo = std::make_shared<ExperimentOptions>();
  CLI::App* e = app.add_subcommand(
      "experiment",
      "Run an experiment (objects x runs x steps, Section 5.2) into a resumable run store");
  e->add_option("--db", eo->db, "Object database (HDF5)")->required();
  e->add_option("--config", eo->config_file,
                "Experiment configuration (TOML or INI; see experiments/studies/)");
  e->add_option("--objects", eo->objects, "Explored objects: all, or a,b,c");
  e->add_option("--runs", eo->runs, "Exploration runs per object (default 20)");
  e->add_option("--steps", eo->steps, "Exploration steps (grasps) per run (default 40)");
  e->add_option("--pool", eo->pool, "Simulated grasps per object that runs draw from (default 50)");
  e->add_option("--method", eo->method, "bricpsf | batch-ransac | ransac-icp | ransac-icp-fs");
  e->add_option("--preset", eo->preset,
                "improved (default): Touchstone's extensions; paper: the paper's parameters exactly");
  e->add_option("--noise", eo->noise, "ideal | underwater | deepsea");
  e->add_option("--sensors", eo->sensors, "Tactile pads: 1 (the paper's) or 6");
  e->add_option("--schedule", eo->schedule,
                "runs: runs in parallel (throughput, default); steps: one run at a time, each "
                "step on every thread (latency). Never changes results");
  e->add_option("--memory-budget", eo->memory_budget,
                "Resident object geometry in MB, loaded on demand and evicted least-recently-used "
                "(default 256; 0: no limit). Never changes results");
  e->add_option("--set", eo->set,
                "Any configuration key, KEY=VALUE (repeatable), e.g. --set ransac.samples=50x200 "
                "or --set sweep.method=bricpsf,ransac-icp");
  e->add_option("--out", eo->out, "Run store to write (HDF5)")->required();
  e->add_flag("--resume", eo->resume,
              "Continue an interrupted experiment in --out (same configuration and database)");
  e->add_option("--plots", eo->plots, "Also write the figures (PNG) into this folder");
  add_common(e, eo->common);
  e->callback([eo, e] {
    eo->seed_given = e->get_option("--seed")->count() > 0;
    run_command(eo->common, [eo] { return run_experiment(*eo); });
  });

  auto ro = std::make_shared<ReportOptions>();
  CLI::App* r = app.add_subcommand("report", "Report a run store: tables, JSON (--json), figures (--plots)");
  r->add_option("store", ro->store, "Run store (HDF5) written by `touchstone experiment`")->required();
  r->add_option("--plots", ro->plots, "Write the figures (PNG) into this folder");
  add_common(r, ro->common);
  r->callback([ro] { run_command(ro->common, [ro] { return run_report(*ro); }); });
}

}  // namespace ts::cli
