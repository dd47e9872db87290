// `touchstone experiment` and `touchstone report`: run an experiment into a run store (resumable)
// and report it as tables, the interface's JSON, and figures. `touchstone calibrate`: fit the
// step confidence (experiments/analysis/calibration.hpp) on run stores.
#include "experiments/allocator.hpp"
#include "experiments/analysis/calibration.hpp"
#include "experiments/analysis/report.hpp"
#include "experiments/cli/cli_common.hpp"
#include "experiments/cli/progress.hpp"
#include "experiments/params/config.hpp"
#include "experiments/params/parameters.hpp"
#include "experiments/resources.hpp"
#include "experiments/runs/driver.hpp"
#include "experiments/runs/mpi_runs.hpp"
#include "experiments/runs/recognition_engine.hpp"
#include "experiments/runs/shards.hpp"
#include "io/run_store.hpp"

#include <algorithm>
#include <chrono>
#include <csignal>
#include <map>
#include <optional>
#include <set>
#include <cmath>
#include <cstdio>
#include <functional>
#include <iomanip>
#include <iostream>
#include <limits>
#include <sstream>

namespace ts::cli {

namespace {

using experiments::ExperimentConfig;

/// A set answer's score as a reader takes it: a log-weight gap, or outside the state the shape
/// prior's gap (engine/recognition/answer_set.hpp).
std::string set_score_text(double score) {
  std::ostringstream o;
  o << std::setprecision(3);
  if (std::isinf(score))
    o << "every class";
  else if (outside_state(score))
    o << "classes without hypotheses within " << score - kOutsideState << " nats of the shape prior's best";
  else
    o << "a log-weight gap of " << score;
  return o.str();
}

struct ExperimentOptions {
  CommonOptions common;
  std::string db, config_file, out, plots;
  experiments::ParameterFlags flags;   ///< the simulator and experiment parameters' flags
  std::vector<std::string> set;   ///< KEY=VALUE, any configuration key
  std::string shard;              ///< "I/N": this process runs shard I of N (experiments/runs/shards.hpp)
  bool mpi = false;               ///< one rank of an MPI job (mpi_runs.hpp)
  bool resume = false;
  bool seed_given = false;
  ProgressOptions progress;
};

struct MergeOptions {
  CommonOptions common;
  std::string out;
  std::vector<std::string> shards;   ///< the positionals: the shards (or, without --out, OUT then the shards)
  ProgressOptions progress;
};

struct ReportOptions {
  CommonOptions common;
  std::string store, plots, calibration, runs;
  std::string runs_old;   ///< --runs A:B, the old spelling of --run-range
};

struct CalibrateOptions {
  CommonOptions common;
  std::vector<std::string> stores;
  std::string out, runs;
  std::string runs_old;          ///< --runs A:B, the old spelling of --run-range
  double open_set_drop = 0.03;   ///< known-object recognition the open-set threshold may cost
  double open_set_confidence = 0.9;   ///< ... in this share of resamples of the explored objects
  int open_set_step = 20;        ///< at this step (the last when the runs are shorter)
  std::string step_ranges;       ///< first steps of the ranges, "1,2,3,..." ("": the default)
  std::optional<double> alpha;   ///< --alpha: the answer sets' level (unset: 0.05 when the stores allow)
  double tie_nats = 0.0;         ///< --tie-nats: gaps below this score as the answer's class
  ProgressOptions progress;
};

/// --step-ranges: first steps, ascending from 1.
std::vector<int> parse_step_ranges(const std::string& text) {
  if (text.empty()) return experiments::default_step_ranges();
  std::vector<int> out;
  std::stringstream in(text);
  std::string item;
  while (std::getline(in, item, ',')) {
    std::size_t used = 0;
    int v = 0;
    try {
      v = std::stoi(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != item.size() || (out.empty() ? v != 1 : v <= out.back()))
      throw Error("expected ascending first steps starting at 1, e.g. 1,2,3,5,7,9,12,16 (got '" + text + "')",
                  {}, "--step-ranges");
    out.push_back(v);
  }
  if (out.empty()) throw Error("expected at least one range", {}, "--step-ranges");
  return out;
}

/// --run-range A:B, the runs A <= run < B of every object ("" : all).
struct RunRange {
  int first = 0, end = std::numeric_limits<int>::max();
  bool has(int run) const { return run >= first && run < end; }
  bool all() const { return first == 0 && end == std::numeric_limits<int>::max(); }
};

RunRange parse_runs(const std::string& text) {
  static const std::string flag = "--run-range";
  RunRange r;
  if (text.empty()) return r;
  const auto colon = text.find(':');
  auto number = [&](const std::string& t) {
    std::size_t used = 0;
    int v = -1;
    try {
      v = std::stoi(t, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (t.empty() || used != t.size() || v < 0)
      throw Error(flag + " expects A:B, the runs A <= run < B (got '" + text + "')", {}, flag);
    return v;
  };
  if (colon == std::string::npos) throw Error(flag + " expects A:B (got '" + text + "')", {}, flag);
  r.first = number(text.substr(0, colon));
  r.end = number(text.substr(colon + 1));
  if (r.end <= r.first) throw Error(flag + " A:B needs A < B (got '" + text + "')", {}, flag);
  return r;
}

/// --runs A:B, the old spelling of --run-range (--runs counts runs in `experiment` and `stress`):
/// taken, with a note; both given is an error.
std::string run_range_of(const std::string& range, const std::string& old, const char* command) {
  if (old.empty()) return range;
  if (!range.empty()) throw Error("give --run-range only (--runs A:B is its old spelling)", {}, "--runs");
  std::cerr << "touchstone: note: `" << command << " --runs " << old << "` is the old spelling; write `--run-range "
            << old << "` (--runs counts runs in experiment and stress)\n";
  return old;
}

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

/// Configuration: defaults, then the file, then each flag (validated by the same setter; a bad
/// flag's error names the flag).
ExperimentConfig build_config(const ExperimentOptions& o) {
  ExperimentConfig c;
  if (!o.config_file.empty()) experiments::load_config_file(c, o.config_file);
  // The flags (--runs 5, --noise.sensel-noise 0.1, ...), in the declaration's order.
  experiments::apply_flags(o.flags, c);
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

/// The MPI mode: every rank reads what is done (the store and the rank stores of an earlier job),
/// the runs left are handed out over the job, and rank 0 folds the rank stores into --out.
int run_mpi(const ExperimentOptions& o, const ExperimentConfig& config, experiments::RunEngine& engine,
            const io::RunStoreHeader& header, int threads, experiments::MpiSession& mpi) {
  const std::filesystem::path out = o.out;
  const auto earlier = experiments::rank_stores(out);
  std::error_code ec;
  const bool have_out = std::filesystem::exists(out, ec);
  if ((have_out || !earlier.empty()) && !o.resume)
    throw Error("the run store already exists: continue it with --resume, or remove it" +
                    std::string(have_out ? "" : " (and its folder of rank stores)"), o.out, "--out");
  std::set<experiments::RunTask> done;
  auto take_done = [&](const std::filesystem::path& path) {
    experiments::check_resumable(io::RunStore::read_header(path), header, path.string());
    for (const auto& r : io::RunStore::read(path).runs) done.insert({r.variant, r.object, r.run});
  };
  if (have_out) take_done(out);
  for (const auto& r : earlier) take_done(r);
  const auto tasks = experiments::all_tasks(header, config.runs);
  std::vector<experiments::RunTask> todo;
  for (const auto& t : tasks)
    if (!done.count(t)) todo.push_back(t);
  // Every rank has read what is done before any rank writes; and all read the same. The error
  // is printed once, by rank 0 (the others end quietly; rank 0's error stops the job).
  const bool root = mpi.rank() == 0;
  const std::string shared = " (on a cluster: --out on a file system shared by every node)";
  if (!mpi.same_on_every_rank(experiments::plan_fingerprint(header, todo))) {
    if (!root) return 1;
    throw Error("the MPI ranks disagree on the experiment or on the runs left to do: each rank must see "
                "the same configuration, database and stores" + shared, o.out, "--out");
  }
  try {
    const auto own = experiments::rank_store(out, mpi.rank());
    if (root && !todo.empty()) std::filesystem::create_directories(experiments::rank_folder(out));
    mpi.barrier();
    // The folder rank 0 made must be the one every rank sees.
    const bool sees = todo.empty() || std::filesystem::is_directory(experiments::rank_folder(out), ec);
    if (!mpi.same_on_every_rank(sees ? 1 : 0) || !sees) {
      if (!root) return 1;
      throw Error("some MPI ranks do not see the folder of rank stores rank 0 made, " +
                  experiments::rank_folder(out).string() + shared, o.out, "--out");
    }
    if (!todo.empty() && !std::filesystem::exists(own, ec)) io::RunStore::create(own, header);
    if (root && stderr_is_terminal())
      std::cerr << "Experiment '" << config.name << "': " << todo.size() << " of " << tasks.size()
                << " runs to do over " << mpi.size() << " MPI ranks x " << threads << " threads\n";
    experiments::DriveOutcome outcome;
    if (!todo.empty()) {
      engine.prepare_lazily(todo);   // the grasp pools by the runs that need them, on their rank
      experiments::release_free_memory();
    }
    {
      // Every rank takes part, even with nothing to do: rank 0 waits for each rank's "done".
      experiments::DriveSettings ds;
      g_stop = false;
      ds.stop = &g_stop;
      SignalGuard guard;
      outcome = mpi.drive(engine, todo, own, threads, ds);
    }
    mpi.barrier();
    if (outcome.interrupted || g_stop) {
      if (root)
        std::cerr << "touchstone: interrupted: the finished runs are in " << experiments::rank_folder(out).string()
                  << "; continue with the same command and --resume\n";
      return 130;
    }
    if (!root) return 0;
    // Fold: the store (when resuming) and every rank store into a new store renamed over --out.
    std::vector<std::filesystem::path> inputs;
    if (have_out) inputs.push_back(out);
    for (const auto& r : experiments::rank_stores(out)) inputs.push_back(r);
    if (!inputs.empty() && !(inputs.size() == 1 && have_out)) {
      const std::filesystem::path folded = out.string() + ".fold.h5";
      std::filesystem::remove(folded, ec);   // left by a fold that was killed
      io::RunStore::merge(folded, header, inputs, false, true);
      std::filesystem::rename(folded, out);
      for (const auto& r : experiments::rank_stores(out)) {   // its pending runs first, then the store
        std::filesystem::remove_all(r.string() + ".runs", ec);
        std::filesystem::remove(r);
      }
      std::filesystem::remove(experiments::rank_folder(out), ec);
    }
    const std::size_t stored = io::RunStore::read(out).runs.size();
    if (stored != tasks.size())
      throw Error("the folded store holds " + std::to_string(stored) + " of " + std::to_string(tasks.size()) +
                  " runs", o.out, "--out");
    io::RunStore::compact(out, true);
    experiments::ReportSettings rs;
    rs.threads = threads;
    rs.machine = experiments::machine_description() + ", " + std::to_string(mpi.size()) + " MPI ranks";
    emit_report(io::RunStore::read(out), rs, o.out, o.common.json, o.plots);
    return 0;
  } catch (const std::exception& e) {
    // After the first barrier the other ranks may wait for this one: stop the whole job.
    std::cerr << "touchstone: error (MPI rank " << mpi.rank() << "): " << e.what() << "\n";
    mpi.abort(1);
  }
}

int run_experiment_in(const ExperimentOptions& o, experiments::MpiSession* mpi);

int run_experiment(const ExperimentOptions& o) {
  std::unique_ptr<experiments::MpiSession> mpi;
  if (o.mpi) {
    if (!o.shard.empty()) throw Error("--mpi hands the runs out itself: give --shard or --mpi, not both", {}, "--mpi");
    mpi = std::make_unique<experiments::MpiSession>();
    if (mpi->size() > 1) {
      // An error in one rank (a database it cannot read, memory) would leave the others waiting
      // at a barrier: stop the whole job.
      try {
        return run_experiment_in(o, mpi.get());
      } catch (const std::exception& e) {
        std::cerr << "touchstone: error (MPI rank " << mpi->rank() << "): " << e.what() << "\n";
        mpi->abort(1);
      }
    }
  }
  return run_experiment_in(o, mpi.get());
}

int run_experiment_in(const ExperimentOptions& o, experiments::MpiSession* mpi) {
  const ExperimentConfig config = build_config(o);
  std::optional<experiments::Shard> shard;
  if (!o.shard.empty()) shard = experiments::parse_shard(o.shard, "--shard");
  const int threads = thread_count(o.common);
  std::function<void(const std::string&)> note;
  if (stderr_is_terminal()) note = [](const std::string& line) { std::cerr << line << "\n"; };
  std::unique_ptr<experiments::RunEngine> engine;
  try {
    engine = experiments::make_recognition_engine(config, experiments::open_database(o.db), threads, note);
  } catch (const Error& e) {
    // An unknown object: name where it was listed (the --objects flag, or the configuration
    // file's key) and the database that lacks it.
    if (!e.file().empty() || (e.field() != "objects" && e.field() != "database" && e.field() != "hidden")) throw;
    const bool flag = o.flags.given.count(e.field()) > 0;
    if (flag || o.config_file.empty()) throw Error(e.message(), o.db, flag ? "--" + e.field() : e.field());
    std::string message = e.message();
    const std::string lacks = "(not in the database)";
    if (const auto at = message.find(lacks); at != std::string::npos) message.replace(at, lacks.size(), "(not in the database " + o.db + ")");
    throw Error(message, o.config_file, e.field());
  }
  io::RunStoreHeader header = engine->header();
  if (shard) header.shard = shard->label();
  // Sizes again with the explored objects known (all of the database), before any output.
  experiments::check_memory(config, header.objects.size(), o.config_file);
  if (mpi) return run_mpi(o, config, *engine, header, threads, *mpi);
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

  auto tasks = experiments::all_tasks(header, config.runs);
  if (shard) tasks = experiments::shard_tasks(tasks, *shard);
  experiments::DriveSettings ds;
  ds.parallel_runs = config.schedule == "runs";
  g_stop = false;
  ds.stop = &g_stop;
  ProgressReport progress(o.progress, "experiment", "runs", stderr_is_terminal(), o.common.json, std::cerr);
  if (progress.active())
    ds.on_progress = [&](const experiments::Progress& p) {
      progress.update(p.done, p.total, 60.0 * static_cast<double>(p.session_done) / std::max(1e-9, p.elapsed_s),
                      p.remaining_s());
    };
  {
    std::ostringstream line;
    line << "Experiment '" << config.name << "': " << tasks.size() << " runs ("
         << (shard ? "shard " + shard->label() + " of " : std::string()) << header.variant_labels.size()
         << " variant(s) x " << header.objects.size() << " object(s) x " << config.runs << " runs x "
         << config.steps << " steps), " << threads << " threads";
    progress.note(line.str());
  }
  experiments::DriveOutcome outcome;
  {
    SignalGuard guard;
    outcome = experiments::drive(*engine, tasks, out, ds);
  }
  progress.finish();
  if (outcome.interrupted) {
    const auto stored = io::RunStore::read(out).runs.size();
    std::cerr << "touchstone: interrupted: " << stored << " of " << tasks.size()
              << " runs are stored in " << o.out << "; continue with --resume\n";
    return 130;
  }
  io::RunStore::compact(out, true);
  if (shard && stderr_is_terminal())
    std::cerr << "Shard " << shard->label() << " is complete in " << o.out
              << "; fold the shards into one store with: touchstone merge OUT.h5 SHARD.h5 ...\n";
  experiments::ReportSettings rs;
  rs.threads = threads;
  rs.machine = experiments::machine_description();
  emit_report(io::RunStore::read(out), rs, o.out, o.common.json, o.plots);
  return 0;
}

int run_merge(MergeOptions o) {
  if (o.out.empty()) {   // the old form, `merge OUT SHARD...`: still taken, with a note
    if (o.shards.size() < 2)
      throw Error("name the merged store with --out (merge --out OUT SHARD...)", {}, "--out");
    o.out = o.shards.front();
    o.shards.erase(o.shards.begin());
    std::cerr << "touchstone: note: `merge OUT SHARD...` is the old form; write `merge --out " << o.out
              << " SHARD...` (the old form will be removed in a later version)\n";
  }
  std::vector<std::filesystem::path> shards(o.shards.begin(), o.shards.end());
  ProgressReport progress(o.progress, "merge", "stores", stderr_is_terminal(), o.common.json, std::cerr);
  std::function<void(std::size_t, std::size_t)> on_progress;
  if (progress.active()) on_progress = [&](std::size_t done, std::size_t total) { progress.update(done, total); };
  const std::size_t runs = experiments::merge_shards(o.out, shards, on_progress);
  progress.finish();
  if (o.common.json) {
    nlohmann::ordered_json j;
    j["out"] = o.out;
    j["shards"] = o.shards;
    j["runs"] = runs;
    std::cout << j.dump(1) << "\n";
  } else {
    std::cout << "Merged " << shards.size() << " shard stores (" << runs << " runs) into " << o.out
              << "; report it with: touchstone report " << o.out << "\n";
  }
  return 0;
}

/// The database fingerprint a run store's header records ("" when none).
std::string store_fingerprint(const io::RunStoreHeader& h) {
  const auto db = nlohmann::ordered_json::parse(h.database_json, nullptr, false);
  return db.is_object() && db.contains("fingerprint") && db["fingerprint"].is_string()
             ? db["fingerprint"].get<std::string>()
             : std::string();
}

int run_report(const ReportOptions& o) {
  io::RunStoreContents contents = io::RunStore::read(o.store);
  const RunRange range = parse_runs(run_range_of(o.runs, o.runs_old, "report"));
  if (!range.all())   // only these runs (e.g. those a calibration was not fitted on)
    std::erase_if(contents.runs, [&](const io::RunRecord& r) { return !range.has(r.run); });
  experiments::ReportSettings rs;
  std::optional<experiments::Calibration> calibration;
  if (!o.calibration.empty()) {
    calibration = experiments::read_calibration(o.calibration, store_fingerprint(contents.header));
    rs.calibration = &*calibration;
    rs.calibration_path = o.calibration;
  }
  emit_report(contents, rs, o.store, o.common.json, o.plots);
  return 0;
}

/// Fit the confidence models on every step of the stores' runs (their features and outcomes):
/// per range of steps, P(right) and P(pose within 1 cm) on the runs of known objects, and the
/// in-database score on known against hidden runs (when the stores hold hidden runs).
int run_calibrate(const CalibrateOptions& o) {
  const auto& names = experiments::confidence_feature_names();
  const std::vector<int> first = parse_step_ranges(o.step_ranges);
  std::vector<experiments::CalibrationRow> rows;
  // Explored objects by name across the stores, numbered in the order of first appearance here
  // and renumbered below in database order, so that the folds and resamples (which follow the
  // number) do not depend on the order the stores are given in.
  std::map<std::string, int> groups;
  auto object_group = [&](const std::string& name) { return groups.emplace(name, static_cast<int>(groups.size())).first->second; };
  std::vector<std::string> database_order;
  std::string fingerprint;
  // Set answers: per simulation (the guarantee is for runs simulated alike; a noise sweep's variants
  // each have theirs) and step, the true class's log-weight gap of every run of a known object.
  struct SetRuns {
    nlohmann::ordered_json simulation;
    std::vector<std::vector<double>> gaps;   ///< per step
    std::size_t shortest_run = std::numeric_limits<std::size_t>::max();
  };
  std::map<std::string, SetRuns> set_runs;   // by the simulation's JSON: an order of the contents alone
  std::string no_set_reason;
  nlohmann::ordered_json sources = nlohmann::ordered_json::array();
  const RunRange range = parse_runs(run_range_of(o.runs, o.runs_old, "calibrate"));
  // Progress over the stores read (the fit that follows takes seconds).
  ProgressReport progress(o.progress, "calibrate", "stores", stderr_is_terminal(), o.common.json, std::cerr);
  for (const std::string& path : o.stores) {
    io::RunStoreContents c = io::RunStore::read(path);
    std::erase_if(c.runs, [&](const io::RunRecord& r) { return !range.has(r.run); });
    const std::string fp = store_fingerprint(c.header);
    if (fp.empty()) throw Error("the run store records no database fingerprint", path, "/header/database");
    if (fingerprint.empty()) fingerprint = fp, database_order = c.header.database_objects;
    if (fp != fingerprint)
      throw Error("the run store explored another database than " + o.stores.front() +
                  " (fingerprints differ): a calibration is for one database", path, "/header/database");
    std::vector<std::size_t> cols;
    for (const std::string& f : names) {
      const auto& v = c.header.step_values;
      const auto it = std::find(v.begin(), v.end(), "feature." + f);
      if (it == v.end())
        throw Error("the run store has no per-step feature '" + f + "' (written by an older build?)", path,
                    "/header/step_values");
      cols.push_back(static_cast<std::size_t>(it - v.begin()));
    }
    const std::set<int> hidden = experiments::hidden_explored_objects(c.header);
    const experiments::ClassMap classes = experiments::class_map(c.header);
    const auto& sv = c.header.step_values;
    auto gap_column = std::find(sv.begin(), sv.end(), "set.truth_score");
    if (gap_column == sv.end()) {   // written before classes without hypotheses were ranked by the prior
      gap_column = std::find(sv.begin(), sv.end(), "set.truth_gap_to_answer");
      if (gap_column != sv.end())
        std::cerr << "touchstone calibrate: note: " << path
                  << " records set.truth_gap_to_answer, written before classes without hypotheses were ranked by the "
                     "shape prior: its sets are those of then, which exclude no class while the truth lacks hypotheses "
                     "in more than alpha of the runs; rerun it for sets that do\n";
    }
    const auto config_json = nlohmann::ordered_json::parse(c.header.config_json, nullptr, false);
    // database = "each" (the configuration's list of names holds only "each")
    if (config_json.is_object() && config_json.value("database", nlohmann::ordered_json()) == nlohmann::ordered_json::array({"each"})) {
      if (no_set_reason.empty()) no_set_reason = path + " localized each explored object alone (database = \"each\"): no rival to rank";
    } else if (gap_column == sv.end()) {
      if (no_set_reason.empty()) no_set_reason = path + " has no per-step 'set.truth_score' (written before set answers scored against the answer: rerun it)";
    } else {
      // Each variant's simulation (a sweep of noise settings: one per level). Variants that
      // simulate alike but differ otherwise (a sweep of the method) would pool unlike runs.
      const std::size_t variants = std::max<std::size_t>(c.header.variant_labels.size(), 1);
      std::vector<SetRuns*> of_variant;
      std::map<std::string, std::size_t> variant_of_sim;
      for (std::size_t v = 0; v < variants; ++v) {
        const auto variant_json = v < c.header.variant_configs.size()
                                      ? nlohmann::ordered_json::parse(c.header.variant_configs[v], nullptr, false)
                                      : config_json;
        if (!variant_json.is_object())
          throw Error("the configuration of variant " + std::to_string(v) + " is not a JSON object", path,
                      "/header/variant_configs");
        const auto sim = experiments::simulation_of(variant_json);
        const auto [it, first] = variant_of_sim.emplace(sim.dump(), v);
        if (!first)
          throw Error("variants '" + c.header.variant_labels.at(it->second) + "' and '" + c.header.variant_labels.at(v) +
                      "' simulate alike (" + sim.dump() + ") but differ otherwise: answer sets are calibrated per "
                      "simulation on runs of one configuration; calibrate on a store of one of them", path,
                      "/header/variant_labels");
        SetRuns& e = set_runs[sim.dump()];
        e.simulation = sim;
        of_variant.push_back(&e);
      }
      const auto col = static_cast<std::size_t>(gap_column - c.header.step_values.begin());
      for (const io::RunRecord& r : c.runs) {
        if (hidden.count(r.object)) continue;
        if (r.variant < 0 || static_cast<std::size_t>(r.variant) >= variants)
          throw Error("run " + std::to_string(r.run) + " has no variant " + std::to_string(r.variant), path, "/runs/variant");
        SetRuns& e = *of_variant[static_cast<std::size_t>(r.variant)];
        e.shortest_run = std::min(e.shortest_run, r.steps.size());
        if (e.gaps.size() < r.steps.size()) e.gaps.resize(r.steps.size());
        for (std::size_t k = 0; k < r.steps.size(); ++k) {
          const double g = r.steps[k].values.at(col);
          if (std::isnan(g) || g < 0.0)
            throw Error("run " + std::to_string(r.run) + " of '" + c.header.objects.at(static_cast<std::size_t>(r.object)) +
                        "' has a gap that is not a number >= 0 at step " + std::to_string(k + 1), path, "/steps/values");
          e.gaps[k].push_back(g);
        }
      }
    }
    std::size_t steps = 0, hidden_runs = 0;
    for (const io::RunRecord& r : c.runs) {
      hidden_runs += hidden.count(r.object) ? 1 : 0;
      for (const io::RunStepRecord& s : r.steps) {
        experiments::CalibrationRow row;
        for (std::size_t k : cols) row.features.push_back(s.values.at(k));
        row.step = static_cast<int>(&s - r.steps.data()) + 1;
        row.hidden = hidden.count(r.object) > 0;
        row.copy_in_database = row.hidden && experiments::correct_in_class(c.header, r, s, classes);
        row.group = object_group(c.header.objects.at(static_cast<std::size_t>(r.object)));
        row.right = s.correct;
        row.pose_right = s.correct && s.position_error_m < 0.01;
        rows.push_back(std::move(row));
        ++steps;
      }
    }
    const auto config = nlohmann::ordered_json::parse(c.header.config_json, nullptr, false);
    nlohmann::ordered_json src;
    src["store"] = path;
    src["seed"] = config.is_object() ? config.value("seed", nlohmann::ordered_json(nullptr)) : nullptr;
    src["protocol"] = config.is_object() ? config.value("protocol", nlohmann::ordered_json("shared_pool")) : nullptr;
    src["objects"] = c.header.objects.size();
    src["runs"] = c.runs.size();
    src["hidden_runs"] = hidden_runs;
    src["run_range"] = range.all() ? nlohmann::ordered_json("all")
                                   : nlohmann::ordered_json::array({range.first, range.end});
    src["step_answers"] = steps;
    sources.push_back(src);
    progress.update(sources.size(), o.stores.size());
  }
  progress.finish();
  if (rows.empty()) throw Error("the run stores hold no runs to fit on", o.stores.front(), "/runs");
  {  // database order (objects outside it after, by name)
    std::vector<std::pair<std::size_t, std::string>> keyed;
    for (const auto& [name, id] : groups) {
      const auto it = std::find(database_order.begin(), database_order.end(), name);
      keyed.emplace_back(static_cast<std::size_t>(it - database_order.begin()), name);
    }
    std::sort(keyed.begin(), keyed.end());
    std::vector<int> renumber(groups.size());
    for (std::size_t k = 0; k < keyed.size(); ++k) renumber[static_cast<std::size_t>(groups.at(keyed[k].second))] = static_cast<int>(k);
    for (auto& r : rows) r.group = renumber[static_cast<std::size_t>(r.group)];
    // Rows in an order of their contents alone (sums, folds and resamples follow it).
    auto key = [](const experiments::CalibrationRow& r) {
      return std::tie(r.group, r.hidden, r.step, r.right, r.pose_right, r.copy_in_database, r.features);
    };
    std::stable_sort(rows.begin(), rows.end(), [&](const auto& a, const auto& b) { return key(a) < key(b); });
  }
  const bool open_set = std::any_of(rows.begin(), rows.end(), [](const auto& r) { return r.hidden; });
  experiments::Calibration cal;
  cal.database_fingerprint = fingerprint;
  cal.features = names;
  cal.ranges = experiments::fit_step_models(rows, first);
  // Open set: the threshold on the in-database score that costs the known objects' runs at most
  // --open-set-drop of their right answers at --open-set-step.
  int last = 0;
  for (const auto& r : rows) last = std::max(last, r.step);
  const int at = std::min(o.open_set_step, last);
  std::vector<experiments::KnownAnswer> known_at;
  std::size_t right_at = 0;
  if (open_set) {
    // Scored out of fold (objects held out): the in-sample scores of the known runs are
    // optimistic, and a threshold chosen on them costs held-out runs more than --open-set-drop.
    const auto& range = cal.at(at);
    const std::vector<double> score =
        experiments::out_of_fold_in_database(rows, first, at, range.l2[2]);
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const auto& r = rows[i];
      if (r.step != at || r.hidden) continue;
      const bool right = r.right && std::isfinite(score[i]);
      known_at.push_back({r.group, right, right ? score[i] : 0.0});
      right_at += right ? 1 : 0;
    }
    constexpr int kResamples = 2000;
    constexpr std::uint64_t kResampleSeed = 1;
    cal.open_set_threshold = experiments::choose_open_set_threshold_clustered(
        known_at, o.open_set_drop, o.open_set_confidence, kResamples, kResampleSeed);
    cal.provenance["open_set"] = {{"score", "in_database, out of fold (5 folds by object)"},
                                  {"in_database", "known objects, and hidden ones whose congruent copy was named"},
                                  {"max_drop", o.open_set_drop}, {"confidence", o.open_set_confidence},
                                  {"rule", "the (1 - confidence) quantile of the max_drop thresholds of "
                                           "resamples of the explored objects (ts::Rng(seed))"},
                                  {"resamples", kResamples}, {"seed", kResampleSeed},
                                  {"step", at}, {"known_runs", known_at.size()}, {"right", right_at}};
  } else {
    cal.provenance["open_set"] = nullptr;   // no hidden runs: no open-set score
  }
  // Set answers: the gaps of steps every run of a known object reached (a store without them, or
  // of hidden objects only, gives none; --alpha then is an error).
  if (!no_set_reason.empty()) set_runs.clear();
  std::erase_if(set_runs, [](const auto& e) { return e.second.gaps.empty(); });   // hidden objects' runs only
  if (set_runs.empty() && no_set_reason.empty()) no_set_reason = "no runs of known objects";
  if (!set_runs.empty()) {
    nlohmann::ordered_json per_simulation = nlohmann::ordered_json::array();
    for (auto& [key, e] : set_runs) {
      e.gaps.resize(std::min(e.gaps.size(), e.shortest_run));
      experiments::AnswerSetCalibration a;
      a.alpha = o.alpha.value_or(0.05);
      a.tie_nats = o.tie_nats;
      a.simulation = e.simulation;
      for (auto& g : e.gaps) a.steps.emplace_back(std::move(g)).set_tie(a.tie_nats);
      per_simulation.push_back({{"simulation", a.simulation}, {"runs_per_step", a.steps.front().size()},
                                {"steps", a.steps.size()}});
      cal.answer_sets.push_back(std::move(a));
    }
    cal.provenance["answer_sets"] = {{"per_simulation", per_simulation},
                                     {"assumes", "a run is drawn as the calibration runs of its simulation were (its "
                                                 "object, pose and grasps alike); runs of one object are not "
                                                 "independent, so the coverage is marginal over objects: check it on "
                                                 "held-out runs"}};
  } else if (o.alpha) {
    throw Error("answer sets need the true class's gap at every step: " + no_set_reason, o.stores.front(), "--alpha");
  }
  cal.provenance["fitted_on"] = sources;
  cal.provenance["step_answers"] = rows.size();
  experiments::write_calibration(o.out, cal);
  // In-sample calibration (the fit's own data; judge it on other runs with `report --calibration`).
  std::vector<double> po, pp;
  std::vector<int> object_right, pose_right;
  for (const auto& r : rows) {
    if (r.hidden) continue;
    po.push_back(cal.object_confidence(r.step, r.features));
    pp.push_back(cal.pose_confidence(r.step, r.features));
    object_right.push_back(r.right ? 1 : 0);
    pose_right.push_back(r.pose_right ? 1 : 0);
  }
  const auto a = experiments::confidence_calibration(po, object_right);
  const auto b = experiments::confidence_calibration(pp, pose_right);
  nlohmann::ordered_json j = experiments::to_json(cal);
  j["in_sample"] = {{"object_ece", a.ece}, {"object_brier", a.brier}, {"pose_ece", b.ece}, {"pose_brier", b.brier}};
  if (o.common.json) {
    std::cout << j.dump(1) << "\n";
  } else {
    std::cout << "Calibration written to " << o.out << ": " << rows.size() << " step answers of "
              << o.stores.size() << " run store(s), " << first.size() << " ranges of steps; in-sample object ECE "
              << std::fixed << std::setprecision(3) << a.ece << ", Brier " << a.brier << "; pose ECE " << b.ece
              << ", Brier " << b.brier;
    if (cal.open_set_threshold)
      std::cout << "; open-set threshold " << *cal.open_set_threshold << " on the in-database score (at most "
                << std::setprecision(1) << o.open_set_drop * 100 << " % of the known objects' runs lose their right "
                << "answer at step " << at << ", in " << o.open_set_confidence * 100
                << " % of resamples of the explored objects)" << std::setprecision(3);
    else
      std::cout << "; no open-set score (no runs of hidden objects)";
    if (!cal.answer_sets.empty()) {
      for (const auto& a : cal.answer_sets)
        std::cout << "; answer sets at alpha " << std::setprecision(2) << a.alpha << " over " << a.steps.size()
                  << " steps of " << a.steps.front().size() << " runs"
                  << (cal.answer_sets.size() > 1 ? " simulated with " + a.simulation.dump() : std::string())
                  << " (admitted at step " << a.steps.size() << ": " << std::setprecision(3)
                  << set_score_text(a.steps.back().threshold(a.alpha)) << ")";
    } else {
      std::cout << "; no answer sets (" << no_set_reason << ")";
    }
    std::cout << "; judge it on other runs: touchstone report STORE --calibration " << o.out << "\n";
  }
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
  // Every simulator and experiment parameter as a flag (--runs, --noise, --memory-budget, ...;
  // experiments/params/parameters.cpp); --seed is the common flag.
  experiments::add_parameter_flags(*e, eo->flags, "Simulator and experiment parameters (touchstone params)",
                                   [](const experiments::Parameter& p) {
                                     return p.kind != experiments::Parameter::Kind::method && p.key != "seed";
                                   });
  e->add_option("--set", eo->set,
                "Any configuration key, KEY=VALUE (repeatable), e.g. --set ransac.samples=50x200 "
                "or --set sweep.method=bricpsf,ransac-icp");
  e->add_option("--out", eo->out, "Run store to write (HDF5)")->required();
  e->add_flag("--resume", eo->resume,
              "Continue an interrupted experiment in --out (same configuration and database)");
  e->add_option("--shard", eo->shard,
                "Run only shard I of N of the runs (I/N; every N-th run in key order) into --out; "
                "fold the N shard stores with `touchstone merge`");
  e->add_flag("--mpi", eo->mpi,
              "One rank of an MPI job (mpirun -n K touchstone experiment --mpi ...): the runs are "
              "handed out over the ranks, each appends to OUT.ranks/rank-R.h5, rank 0 folds them into --out");
  e->add_option("--plots", eo->plots, "Also write the figures (PNG) into this folder");
  add_common(e, eo->common);
  add_progress(e, eo->progress);
  e->callback([eo, e] {
    eo->seed_given = e->get_option("--seed")->count() > 0;
    run_command(eo->common, [eo] { return run_experiment(*eo); });
  });

  auto mo = std::make_shared<MergeOptions>();
  CLI::App* m = app.add_subcommand(
      "merge", "Fold the shard stores of one experiment (experiment --shard I/N) into one run store");
  m->add_option("--out", mo->out, "Run store to write (HDF5; must not exist)");
  m->add_option("shards", mo->shards,
                "The N shard stores, in any order (the old form `merge OUT SHARD...` still works, with a note)")
      ->required();
  add_common(m, mo->common, kJson);   // copies the shards' runs: no draws, no parallel work
  add_progress(m, mo->progress);
  m->callback([mo] { run_command(mo->common, [mo] { return run_merge(*mo); }); });

  auto ro = std::make_shared<ReportOptions>();
  CLI::App* r = app.add_subcommand("report", "Report a run store: tables, JSON (--json), figures (--plots)");
  r->add_option("store,--store", ro->store, "Run store (HDF5) written by `touchstone experiment`")->required();
  r->add_option("--plots", ro->plots, "Write the figures (PNG) into this folder");
  r->add_option("--run-range", ro->runs,
                "Report only the runs A <= run < B of every object (A:B), e.g. those a calibration "
                "was not fitted on");
  r->add_option("--runs", ro->runs_old, "Old spelling of --run-range (taken, with a note)")->group("");
  r->add_option("--calibration", ro->calibration,
                "Confidence calibration file (touchstone calibrate): the confidences are recomputed "
                "from the store's features and judged against its outcomes (ECE, Brier, reliability)");
  add_common(r, ro->common, kThreads | kJson);
  r->callback([ro] { run_command(ro->common, [ro] { return run_report(*ro); }); });

  auto co = std::make_shared<CalibrateOptions>();
  CLI::App* cb = app.add_subcommand(
      "calibrate", "Fit the step confidence (object right; pose within 1 cm) on run stores' steps");
  cb->add_option("stores", co->stores, "Run stores (HDF5) of simulated runs of one database")->required();
  cb->add_option("--out", co->out, "Calibration file to write (JSON)")->required();
  cb->add_option("--run-range", co->runs, "Fit on the runs A <= run < B of every object only (A:B)");
  cb->add_option("--runs", co->runs_old, "Old spelling of --run-range (taken, with a note)")->group("");
  cb->add_option("--open-set-drop", co->open_set_drop,
                 "Open set (needs runs of hidden objects, config hidden): the threshold on the "
                 "in-database score may cost at most this share of the known objects' runs their right answer "
                 "(default 0.03)")->check(CLI::Range(0.0, 0.99));
  cb->add_option("--open-set-confidence", co->open_set_confidence,
                 "Open set: ... in at least this share of resamples of the explored objects (their runs "
                 "fail together; 0: on the calibration runs as they are; default 0.9)")
      ->check(CLI::Range(0.0, 0.99));
  cb->add_option("--step-ranges", co->step_ranges,
                 "First steps of the ranges of steps with their own models, ascending from 1 "
                 "(default 1,2,3,5,7,9,12,16)");
  cb->add_option("--alpha", co->alpha,
                 "Set answers: the level their coverage guarantee is for (the set holds the truth with "
                 "probability at least 1 - alpha; default 0.05; recognize --alpha overrides it)")
      ->check(CLI::Range(1e-9, 1.0 - 1e-9));
  cb->add_option("--tie-nats", co->tie_nats,
                 "Set answers: a class whose log-weight gap to the answer is below this (nats) scores 0, as the "
                 "answer's own does, on the calibration runs and the step alike (near-twins the weights cannot "
                 "split; default 0)")
      ->check(CLI::Range(0.0, 100.0));
  cb->add_option("--open-set-step", co->open_set_step,
                 "Open set: ... at this step (default 20; the last when runs are shorter)")
      ->check(CLI::PositiveNumber);
  add_common(cb, co->common, kThreads | kJson);
  add_progress(cb, co->progress);
  cb->callback([co] { run_command(co->common, [co] { return run_calibrate(*co); }); });
}

}  // namespace ts::cli
