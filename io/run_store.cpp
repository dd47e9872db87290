#include "io/run_store.hpp"

#include "io/pose_row.hpp"

#include "io/atomic_file.hpp"
#include "io/h5.hpp"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <array>
#include <chrono>
#include <thread>
#include <map>
#include <tuple>

namespace ts::io {

namespace {

constexpr const char* kFormat = "touchstone-run";
constexpr std::int64_t kFormatVersion = 1;

const char* kStepDoubles[] = {"weight",           "posterior_true",        "posterior_best",
                              "posterior_entropy", "position_error_m",      "orientation_error_rad",
                              "symmetric_orientation_error_rad",            "mssd_m",
                              "time_s"};
const char* kStepInts[] = {"best_object", "true_rank", "hypotheses", "contacts", "free_points"};

double step_double(const RunStepRecord& s, int k) {
  switch (k) {
    case 0: return s.weight;
    case 1: return s.posterior_true;
    case 2: return s.posterior_best;
    case 3: return s.posterior_entropy;
    case 4: return s.position_error_m;
    case 5: return s.orientation_error_rad;
    case 6: return s.symmetric_orientation_error_rad;
    case 7: return s.mssd_m;
    default: return s.time_s;
  }
}

void set_step_double(RunStepRecord& s, int k, double v) {
  switch (k) {
    case 0: s.weight = v; break;
    case 1: s.posterior_true = v; break;
    case 2: s.posterior_best = v; break;
    case 3: s.posterior_entropy = v; break;
    case 4: s.position_error_m = v; break;
    case 5: s.orientation_error_rad = v; break;
    case 6: s.symmetric_orientation_error_rad = v; break;
    case 7: s.mssd_m = v; break;
    default: s.time_s = v; break;
  }
}

std::int32_t& step_int(RunStepRecord& s, int k) {
  switch (k) {
    case 0: return s.best_object;
    case 1: return s.true_rank;
    case 2: return s.hypotheses;
    case 3: return s.contacts;
    default: return s.free_points;
  }
}

void write_header(h5::Group root, const RunStoreHeader& h) {
  root.set_attribute("format", kFormat);
  root.set_attribute("format_version", kFormatVersion);
  root.set_attribute("steps", static_cast<std::int64_t>(h.steps));
  root.set_attribute("machine", h.machine);
  root.set_attribute("complete", std::int64_t{0});
  if (!h.shard.empty()) root.set_attribute("shard", h.shard);
  h5::Group hg = root.create_group("header");
  hg.write_strings("config", {h.config_json});
  hg.write_strings("database", {h.database_json});
  hg.write_strings("versions", {h.versions_json});
  hg.write_strings("variant_labels", h.variant_labels);
  hg.write_strings("variant_configs", h.variant_configs);
  hg.write_strings("objects", h.objects);
  hg.write_strings("database_objects", h.database_objects);
  hg.write_strings("stages", h.stages);
  if (!h.step_values.empty()) hg.write_strings("step_values", h.step_values);

  const std::uint64_t steps = static_cast<std::uint64_t>(h.steps);
  h5::Group runs = root.create_group("runs");
  runs.create_extendible<std::int32_t>("variant", {});
  runs.create_extendible<std::int32_t>("object", {});
  runs.create_extendible<std::int32_t>("run", {});
  runs.create_extendible<std::int64_t>("first_step_row", {});
  runs.create_extendible<std::int32_t>("grasps", {steps});
  runs.create_extendible<double>("truth", {7});
  runs.create_extendible<double>("wall_time_s", {});
  h5::Group st = root.create_group("steps");
  st.create_extendible<std::int32_t>("step", {});
  st.create_extendible<std::uint8_t>("correct", {});
  for (const char* n : kStepInts) st.create_extendible<std::int32_t>(n, {});
  for (const char* n : kStepDoubles) st.create_extendible<double>(n, {});
  st.create_extendible<double>("pose", {7});
  if (!h.stages.empty()) st.create_extendible<double>("stage_times_s", {h.stages.size()});
  if (!h.step_values.empty()) st.create_extendible<double>("values", {h.step_values.size()});
}

/// "I/N" with 1 <= I <= N <= 1e6, digits only.
bool valid_shard(const std::string& text) {
  const auto slash = text.find('/');
  if (slash == std::string::npos || slash == 0 || slash + 1 >= text.size() || text.size() > 15) return false;
  for (std::size_t k = 0; k < text.size(); ++k)
    if (k != slash && !std::isdigit(static_cast<unsigned char>(text[k]))) return false;
  const long i = std::stol(text.substr(0, slash)), n = std::stol(text.substr(slash + 1));
  return i >= 1 && i <= n && n <= 1000000;
}

RunStoreHeader parse_header(const h5::File& file) {
  h5::Group root = file.root();
  if (!root.has_attribute("format") || root.string_attribute("format") != kFormat)
    throw Error("not a Touchstone run store (no format = \"touchstone-run\")", file.name(), "/@format");
  const std::int64_t version = root.int_attribute("format_version");
  if (version != kFormatVersion)
    throw Error("run store format version " + std::to_string(version) + " is not supported (this "
                "build reads version " + std::to_string(kFormatVersion) + ")", file.name(),
                "/@format_version");
  RunStoreHeader h;
  h.steps = static_cast<std::int32_t>(root.int_attribute("steps"));
  if (h.steps < 1) throw Error("steps must be at least 1", file.name(), "/@steps");
  h.machine = root.string_attribute("machine");
  if (root.has_attribute("shard")) {
    h.shard = root.string_attribute("shard");
    if (!valid_shard(h.shard))
      throw Error("a shard is written I/N with 1 <= I <= N (got '" + h.shard + "')", file.name(), "/@shard");
  }
  h5::Group hg = root.open_group("header");
  auto one = [&](const char* name) {
    auto v = hg.read_strings(name);
    if (v.size() != 1) throw Error("expected one string", file.name(), hg.child_path(name));
    return v.front();
  };
  h.config_json = one("config");
  h.database_json = one("database");
  h.versions_json = one("versions");
  h.variant_labels = hg.read_strings("variant_labels");
  h.variant_configs = hg.read_strings("variant_configs");
  h.objects = hg.read_strings("objects");
  h.database_objects = hg.read_strings("database_objects");
  h.stages = hg.read_strings("stages");
  // Optional (stores written before the per-step values have none).
  if (hg.has_dataset("step_values")) h.step_values = hg.read_strings("step_values");
  if (h.variant_labels.empty() || h.variant_labels.size() != h.variant_configs.size())
    throw Error("variant labels and configurations differ in number", file.name(), "/header/variant_configs");
  return h;
}

void append_runs(h5::Group root, const RunStoreHeader& h, const std::vector<RunRecord>& runs) {
  const std::size_t S = h.stages.size();
  const std::size_t steps = static_cast<std::size_t>(h.steps);
  h5::Group st = root.open_group("steps");
  h5::Group rg = root.open_group("runs");
  std::uint64_t first_row = st.shape("step").at(0);
  // Orphan rows of an interrupted append may make the columns uneven: start after the longest.
  for (const char* n : kStepDoubles) first_row = std::max(first_row, st.shape(n).at(0));
  for (const char* n : kStepInts) first_row = std::max(first_row, st.shape(n).at(0));
  for (const char* n : {"correct", "pose"}) first_row = std::max(first_row, st.shape(n).at(0));
  if (S) first_row = std::max(first_row, st.shape("stage_times_s").at(0));
  const std::size_t V = h.step_values.size();
  if (V) first_row = std::max(first_row, st.shape("values").at(0));
  auto pad_to = [&](const char* name, auto zero) {
    using T = decltype(zero);
    const h5::Shape s = st.shape(name);
    if (s.at(0) >= first_row) return;
    std::uint64_t row = 1;
    for (std::size_t i = 1; i < s.size(); ++i) row *= s[i];
    std::vector<T> pad((first_row - s[0]) * row, zero);
    st.append<T>(name, pad.data(), first_row - s[0]);
  };
  pad_to("step", std::int32_t{0});
  pad_to("correct", std::uint8_t{0});
  for (const char* n : kStepInts) pad_to(n, std::int32_t{0});
  for (const char* n : kStepDoubles) pad_to(n, 0.0);
  pad_to("pose", 0.0);
  if (S) pad_to("stage_times_s", 0.0);
  if (V) pad_to("values", 0.0);

  const std::size_t m = runs.size() * steps;
  std::vector<std::int32_t> step_col(m);
  std::vector<std::uint8_t> correct(m);
  std::vector<std::vector<std::int32_t>> ints(std::size(kStepInts), std::vector<std::int32_t>(m));
  std::vector<std::vector<double>> dbls(std::size(kStepDoubles), std::vector<double>(m));
  std::vector<double> pose(7 * m), stages(S * m), values(V * m);
  std::size_t row = 0;
  for (const RunRecord& r : runs) {
    if (r.steps.size() != steps || r.grasps.size() != steps)
      throw Error("a run must have exactly " + std::to_string(steps) + " steps", root.file(), "/steps");
    for (std::size_t k = 0; k < steps; ++k, ++row) {
      RunStepRecord s = r.steps[k];
      if (s.stage_times_s.size() != S)
        throw Error("a step must have one timing per stage", root.file(), "/steps/stage_times_s");
      if (s.values.size() != V)
        throw Error("a step must have one value per name of /header/step_values", root.file(), "/steps/values");
      step_col[row] = static_cast<std::int32_t>(k + 1);
      correct[row] = s.correct ? 1 : 0;
      for (std::size_t c = 0; c < std::size(kStepInts); ++c) ints[c][row] = step_int(s, static_cast<int>(c));
      for (std::size_t c = 0; c < std::size(kStepDoubles); ++c)
        dbls[c][row] = step_double(s, static_cast<int>(c));
      const auto p = pose_row(s.pose);
      std::copy(p.begin(), p.end(), pose.begin() + static_cast<std::ptrdiff_t>(7 * row));
      std::copy(s.stage_times_s.begin(), s.stage_times_s.end(),
                stages.begin() + static_cast<std::ptrdiff_t>(S * row));
      std::copy(s.values.begin(), s.values.end(), values.begin() + static_cast<std::ptrdiff_t>(V * row));
    }
  }
  st.append("step", step_col.data(), m);
  st.append("correct", correct.data(), m);
  for (std::size_t c = 0; c < std::size(kStepInts); ++c) st.append(kStepInts[c], ints[c].data(), m);
  for (std::size_t c = 0; c < std::size(kStepDoubles); ++c) st.append(kStepDoubles[c], dbls[c].data(), m);
  st.append("pose", pose.data(), m);
  if (S) st.append("stage_times_s", stages.data(), m);
  if (V) st.append("values", values.data(), m);

  // Run rows last: they commit the step rows above. The shortest /runs column decides how
  // many runs are committed, so write the key columns last. Columns left uneven by an
  // interrupted append are padded first; a padded row has variant -1 and is never read.
  std::uint64_t run_rows = 0;
  for (const char* c : {"variant", "object", "run", "first_step_row", "grasps", "truth", "wall_time_s"})
    run_rows = std::max(run_rows, rg.shape(c).at(0));
  auto pad_run = [&](const char* name, auto value) {
    using T = decltype(value);
    const h5::Shape s = rg.shape(name);
    if (s.at(0) >= run_rows) return;
    std::uint64_t row = 1;
    for (std::size_t i = 1; i < s.size(); ++i) row *= s[i];
    std::vector<T> pad((run_rows - s[0]) * row, value);
    rg.append<T>(name, pad.data(), run_rows - s[0]);
  };
  pad_run("first_step_row", std::int64_t{0});
  pad_run("grasps", std::int32_t{0});
  pad_run("truth", 0.0);
  pad_run("wall_time_s", 0.0);
  pad_run("run", std::int32_t{0});
  pad_run("object", std::int32_t{0});
  pad_run("variant", std::int32_t{-1});
  const std::size_t n = runs.size();
  std::vector<std::int64_t> first(n);
  std::vector<std::int32_t> grasps(n * steps), variant(n), object(n), run(n);
  std::vector<double> truth(7 * n), wall(n);
  for (std::size_t i = 0; i < n; ++i) {
    first[i] = static_cast<std::int64_t>(first_row + i * steps);
    std::copy(runs[i].grasps.begin(), runs[i].grasps.end(), grasps.begin() + static_cast<std::ptrdiff_t>(i * steps));
    const auto t = pose_row(runs[i].truth);
    std::copy(t.begin(), t.end(), truth.begin() + static_cast<std::ptrdiff_t>(7 * i));
    wall[i] = runs[i].wall_time_s;
    variant[i] = runs[i].variant;
    object[i] = runs[i].object;
    run[i] = runs[i].run;
  }
  rg.append("first_step_row", first.data(), n);
  rg.append("grasps", grasps.data(), n);
  rg.append("truth", truth.data(), n);
  rg.append("wall_time_s", wall.data(), n);
  rg.append("run", run.data(), n);
  rg.append("object", object.data(), n);
  rg.append("variant", variant.data(), n);
}

/// Committed runs, sorted by key (first copy of a key kept). `rows`, when given, receives each
/// returned run's row in /runs.
std::vector<RunRecord> read_runs(const h5::File& file, const RunStoreHeader& h,
                                 std::vector<std::size_t>* rows = nullptr) {
  h5::Group root = file.root();
  h5::Group rg = root.open_group("runs");
  h5::Group st = root.open_group("steps");
  const std::int64_t steps = h.steps;
  const std::size_t S = h.stages.size();
  auto variant = rg.read<std::int32_t>("variant", {h5::kAny});
  auto object = rg.read<std::int32_t>("object", {h5::kAny});
  auto run = rg.read<std::int32_t>("run", {h5::kAny});
  auto first = rg.read<std::int64_t>("first_step_row", {h5::kAny});
  auto grasps = rg.read<std::int32_t>("grasps", {h5::kAny, steps});
  auto truth = rg.read<double>("truth", {h5::kAny, 7});
  auto wall = rg.read<double>("wall_time_s", {h5::kAny});
  std::size_t n = std::min({variant.size(), object.size(), run.size(), first.size(),
                            grasps.size() / static_cast<std::size_t>(steps), truth.size() / 7, wall.size()});

  auto step_col = st.read<std::int32_t>("step", {h5::kAny});
  auto correct = st.read<std::uint8_t>("correct", {h5::kAny});
  std::vector<std::vector<std::int32_t>> ints;
  for (const char* c : kStepInts) ints.push_back(st.read<std::int32_t>(c, {h5::kAny}));
  std::vector<std::vector<double>> dbls;
  for (const char* c : kStepDoubles) dbls.push_back(st.read<double>(c, {h5::kAny}));
  auto pose = st.read<double>("pose", {h5::kAny, 7});
  std::vector<double> stage;
  if (S) stage = st.read<double>("stage_times_s", {h5::kAny, static_cast<std::int64_t>(S)});
  const std::size_t V = h.step_values.size();
  std::vector<double> values;
  if (V) values = st.read<double>("values", {h5::kAny, static_cast<std::int64_t>(V)});
  std::size_t m = std::min({step_col.size(), correct.size(), pose.size() / 7});
  for (const auto& c : ints) m = std::min(m, c.size());
  for (const auto& c : dbls) m = std::min(m, c.size());
  if (S) m = std::min(m, stage.size() / S);
  if (V) m = std::min(m, values.size() / V);

  std::vector<RunRecord> out;
  std::vector<std::size_t> source;
  out.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    RunRecord r;
    r.variant = variant[i];
    r.object = object[i];
    r.run = run[i];
    const std::string where = "/runs row " + std::to_string(i);
    if (r.variant == -1) continue;  // padding left by an interrupted append
    if (r.variant < 0 || static_cast<std::size_t>(r.variant) >= h.variant_labels.size() ||
        r.object < 0 || static_cast<std::size_t>(r.object) >= h.objects.size() || r.run < 0)
      throw Error("run key out of range", file.name(), where);
    if (first[i] < 0 || static_cast<std::size_t>(first[i]) + static_cast<std::size_t>(steps) > m)
      throw Error("run refers to missing step rows", file.name(), where);
    r.grasps.assign(grasps.begin() + static_cast<std::ptrdiff_t>(i * steps),
                    grasps.begin() + static_cast<std::ptrdiff_t>((i + 1) * steps));
    r.truth = pose_from_row(&truth[7 * i]);
    r.wall_time_s = wall[i];
    for (std::int64_t k = 0; k < steps; ++k) {
      const std::size_t row = static_cast<std::size_t>(first[i] + k);
      if (step_col[row] != k + 1) throw Error("step rows out of order", file.name(), where);
      RunStepRecord s;
      s.correct = correct[row] != 0;
      for (std::size_t c = 0; c < std::size(kStepInts); ++c) step_int(s, static_cast<int>(c)) = ints[c][row];
      for (std::size_t c = 0; c < std::size(kStepDoubles); ++c)
        set_step_double(s, static_cast<int>(c), dbls[c][row]);
      s.pose = pose_from_row(&pose[7 * row]);
      s.stage_times_s.assign(stage.begin() + static_cast<std::ptrdiff_t>(S * row),
                             stage.begin() + static_cast<std::ptrdiff_t>(S * (row + 1)));
      s.values.assign(values.begin() + static_cast<std::ptrdiff_t>(V * row),
                      values.begin() + static_cast<std::ptrdiff_t>(V * (row + 1)));
      r.steps.push_back(std::move(s));
    }
    out.push_back(std::move(r));
    source.push_back(i);
  }
  // Sort by key; keep the first copy of a key (duplicates cannot arise from our writer, but a
  // reader should not double-count if they ever do).
  std::vector<std::size_t> order(out.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return std::tie(out[a].variant, out[a].object, out[a].run) <
           std::tie(out[b].variant, out[b].object, out[b].run);
  });
  std::vector<RunRecord> sorted;
  sorted.reserve(out.size());
  if (rows) rows->clear();
  for (std::size_t i : order) {
    if (!sorted.empty() && sorted.back().same_key(out[i])) continue;
    sorted.push_back(std::move(out[i]));
    if (rows) rows->push_back(source[i]);
  }
  return sorted;
}

/// Open a store, retrying for a while when the file is momentarily locked by another process
/// (HDF5 locks files: `touchstone report` reading a store while the experiment appends to it).
/// Missing and foreign files fail at once.
h5::File open_store(const std::filesystem::path& path, h5::File::Access access) {
  for (int attempt = 0;; ++attempt) {
    try {
      return h5::File::open(path, access);
    } catch (const Error& e) {
      // Only another process's lock is waited out; a corrupt file is refused at once (matching
      // the word "lock" alone also matched "superblock" and kept a damaged store retrying ~55 s).
      if (attempt >= 100 || !h5::is_lock_contention(e)) throw;
      std::this_thread::sleep_for(std::chrono::milliseconds(50 + 10 * attempt));
    }
  }
}


/// The folder of runs appended since the store was last rewritten: "<store>.runs/", one file a
/// batch, named by an 8-digit serial ("00000001.h5"); anything else in it (a writer's temporary
/// file) is ignored.
std::filesystem::path pending_dir(const std::filesystem::path& store) {
  return std::filesystem::path(store.string() + ".runs");
}

/// Serials of the pending run files, ascending.
std::vector<std::uint64_t> pending_serials(const std::filesystem::path& store) {
  std::vector<std::uint64_t> out;
  std::error_code ec;
  const auto dir = pending_dir(store);
  if (!std::filesystem::is_directory(dir, ec)) return out;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
    const std::string n = e.path().filename().string();
    if (n.size() != 11 || n.substr(8) != ".h5") continue;
    if (!std::all_of(n.begin(), n.begin() + 8, [](char c) { return c >= '0' && c <= '9'; })) continue;
    out.push_back(std::stoull(n.substr(0, 8)));
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::filesystem::path pending_file(const std::filesystem::path& store, std::uint64_t serial) {
  char name[32];
  std::snprintf(name, sizeof name, "%08llu.h5", static_cast<unsigned long long>(serial));
  return pending_dir(store) / name;
}

/// A pending file belongs to its store: the same configuration and layout.
void check_pending_header(const RunStoreHeader& store, const RunStoreHeader& pending,
                          const std::filesystem::path& file) {
  if (pending.config_json != store.config_json || pending.database_json != store.database_json ||
      pending.steps != store.steps ||
      pending.stages != store.stages || pending.step_values != store.step_values ||
      pending.objects != store.objects ||
      pending.variant_labels != store.variant_labels || pending.database_objects != store.database_objects ||
      pending.shard != store.shard)
    throw Error("these runs belong to another experiment than their store (remove the file, or the store)",
                file.string(), "/config");
}

/// Fold pending runs in after this many files.
constexpr std::size_t kFoldPending = 64;

struct MissingPending {};   ///< a pending file went away while reading (folded by a writer)

/// Committed runs of the store and of its pending files, merged (first copy of a key kept:
/// the store's, then the files' in serial order), and where each returned run was read:
/// files[0] is the store, source[i] = (file, row of /runs) of runs[i].
struct Merged {
  RunStoreContents contents;
  std::vector<std::filesystem::path> files;
  std::vector<std::pair<std::size_t, std::size_t>> source;
};
Merged read_merged(const std::filesystem::path& path) {
  // The pending files are listed before the store is read: a writer folds them into a new store
  // (renamed in) before it removes them, so a listed file that has gone means the store read
  // may predate the fold (the caller reads again).
  const std::vector<std::uint64_t> serials = pending_serials(path);
  Merged m;
  RunStoreContents& c = m.contents;
  std::vector<std::pair<RunRecord, std::pair<std::size_t, std::size_t>>> all;
  {
    h5::File f = open_store(path, h5::File::Access::read);
    c.header = parse_header(f);
    std::vector<std::size_t> rows;
    std::vector<RunRecord> runs = read_runs(f, c.header, &rows);
    c.complete = f.root().int_attribute("complete") != 0;
    m.files.push_back(path);
    for (std::size_t i = 0; i < runs.size(); ++i) all.push_back({std::move(runs[i]), {0, rows[i]}});
  }
  for (std::uint64_t serial : serials) {
    const auto file = pending_file(path, serial);
    std::error_code ec;
    if (!std::filesystem::exists(file, ec)) throw MissingPending{};
    h5::File f = open_store(file, h5::File::Access::read);
    const RunStoreHeader h = parse_header(f);
    check_pending_header(c.header, h, file);
    std::vector<std::size_t> rows;
    std::vector<RunRecord> runs = read_runs(f, h, &rows);
    for (std::size_t i = 0; i < runs.size(); ++i) all.push_back({std::move(runs[i]), {m.files.size(), rows[i]}});
    m.files.push_back(file);
  }
  if (!serials.empty()) c.complete = false;
  std::stable_sort(all.begin(), all.end(), [](const auto& a, const auto& b) {
    return std::tie(a.first.variant, a.first.object, a.first.run) <
           std::tie(b.first.variant, b.first.object, b.first.run);
  });
  for (auto& [run, where] : all) {
    if (!c.runs.empty() && c.runs.back().same_key(run)) continue;
    c.runs.push_back(std::move(run));
    m.source.push_back(where);
  }
  return m;
}

Merged read_consistent(const std::filesystem::path& path) {
  for (int attempt = 0;; ++attempt) {
    try {
      return read_merged(path);
    } catch (const MissingPending&) {
      if (attempt >= 100) throw Error("the store keeps changing while being read", path.string());
    }
  }
}

}  // namespace

void RunStore::create(const std::filesystem::path& path, const RunStoreHeader& header) {
  std::error_code ec;
  if (std::filesystem::exists(path, ec))
    throw Error("the run store already exists (continue it with --resume, or remove it)", path.string());
  if (std::filesystem::exists(pending_dir(path), ec))
    throw Error("runs of an earlier store of this name are pending here (remove the folder)",
                pending_dir(path).string());
  if (header.steps < 1) throw Error("steps must be at least 1", path.string(), "steps");
  AtomicOutput out(path);
  {
    h5::File f = h5::File::create(out);
    write_header(f.root(), header);
    f.close();
  }
  out.commit();
}

RunStoreHeader RunStore::read_header(const std::filesystem::path& path) {
  h5::File f = open_store(path, h5::File::Access::read);
  return parse_header(f);
}

RunStoreContents RunStore::read(const std::filesystem::path& path) {
  return read_consistent(path).contents;
}

void RunStore::append(const std::filesystem::path& path, const std::vector<RunRecord>& runs) {
  if (runs.empty()) return;
  const RunStoreHeader h = read_header(path);
  for (const RunRecord& r : runs)
    if (r.variant < 0 || static_cast<std::size_t>(r.variant) >= h.variant_labels.size() ||
        r.object < 0 || static_cast<std::size_t>(r.object) >= h.objects.size() || r.run < 0)
      throw Error("run key out of range", path.string(), "/runs");
  // The store itself is never written in place: the runs go to a new pending file, complete
  // before it appears under its name (AtomicOutput: fsync, rename, fsync of the folder).
  const auto dir = pending_dir(path);
  std::filesystem::create_directories(dir);
  const std::vector<std::uint64_t> serials = pending_serials(path);
  const std::uint64_t serial = serials.empty() ? 1 : serials.back() + 1;
  if (serial > 99999999) throw Error("too many pending run files (fold them: touchstone experiment --resume)", dir.string());
  {
    AtomicOutput out(pending_file(path, serial));
    {
      h5::File f = h5::File::create(out);
      write_header(f.root(), h);
      append_runs(f.root(), h, runs);
      f.close();
    }
    out.commit();
  }
  if (serials.size() + 1 >= kFoldPending) compact(path, false);
}

namespace {

/// The columns of one file's /runs and /steps as stored (no round trip through Pose).
struct Columns {
  std::vector<std::int32_t> variant, object, run, grasps, step;
  std::vector<std::int64_t> first;
  std::vector<double> truth, wall, pose, stage, values;
  std::vector<std::uint8_t> correct;
  std::vector<std::vector<std::int32_t>> ints;
  std::vector<std::vector<double>> dbls;
};

Columns read_columns(const std::filesystem::path& file, const RunStoreHeader& h) {
  Columns c;
  h5::File f = open_store(file, h5::File::Access::read);
  h5::Group rg = f.root().open_group("runs");
  h5::Group st = f.root().open_group("steps");
  const std::size_t S = h.stages.size();
  c.variant = rg.read<std::int32_t>("variant", {h5::kAny});
  c.object = rg.read<std::int32_t>("object", {h5::kAny});
  c.run = rg.read<std::int32_t>("run", {h5::kAny});
  c.grasps = rg.read<std::int32_t>("grasps", {h5::kAny, h.steps});
  c.truth = rg.read<double>("truth", {h5::kAny, 7});
  c.wall = rg.read<double>("wall_time_s", {h5::kAny});
  c.first = rg.read<std::int64_t>("first_step_row", {h5::kAny});
  c.step = st.read<std::int32_t>("step", {h5::kAny});
  c.correct = st.read<std::uint8_t>("correct", {h5::kAny});
  for (const char* n : kStepInts) c.ints.push_back(st.read<std::int32_t>(n, {h5::kAny}));
  for (const char* n : kStepDoubles) c.dbls.push_back(st.read<double>(n, {h5::kAny}));
  c.pose = st.read<double>("pose", {h5::kAny, 7});
  if (S) c.stage = st.read<double>("stage_times_s", {h5::kAny, static_cast<std::int64_t>(S)});
  const std::size_t V = h.step_values.size();
  if (V) c.values = st.read<double>("values", {h5::kAny, static_cast<std::int64_t>(V)});
  f.close();
  return c;
}

/// Append row `r` (`width` values a row) of `from` to `to`.
template <class T>
void take_row(std::vector<T>& to, const std::vector<T>& from, std::size_t r, std::size_t width) {
  to.insert(to.end(), from.begin() + static_cast<std::ptrdiff_t>(r * width),
            from.begin() + static_cast<std::ptrdiff_t>((r + 1) * width));
}

/// Write the runs `source` names ((file, row) pairs into `in`, in order) as a new store with
/// header `h` to `path` (atomically), copying the stored values themselves.
void write_folded(const std::filesystem::path& path, const RunStoreHeader& h, const std::vector<Columns>& in,
                  const std::vector<std::pair<std::size_t, std::size_t>>& source, bool complete) {
  const auto steps = static_cast<std::size_t>(h.steps);
  const std::size_t S = h.stages.size(), V = h.step_values.size();
  Columns c;
  c.ints.resize(std::size(kStepInts));
  c.dbls.resize(std::size(kStepDoubles));
  for (const auto& [part, r] : source) {
    const Columns& x = in[part];
    take_row(c.variant, x.variant, r, 1);
    take_row(c.object, x.object, r, 1);
    take_row(c.run, x.run, r, 1);
    take_row(c.grasps, x.grasps, r, steps);
    take_row(c.truth, x.truth, r, 7);
    take_row(c.wall, x.wall, r, 1);
    for (std::size_t k = 0; k < steps; ++k) {   // read_runs checked these rows exist
      const auto row = static_cast<std::size_t>(x.first[r]) + k;
      take_row(c.step, x.step, row, 1);
      take_row(c.correct, x.correct, row, 1);
      for (std::size_t i = 0; i < c.ints.size(); ++i) take_row(c.ints[i], x.ints[i], row, 1);
      for (std::size_t i = 0; i < c.dbls.size(); ++i) take_row(c.dbls[i], x.dbls[i], row, 1);
      take_row(c.pose, x.pose, row, 7);
      if (S) take_row(c.stage, x.stage, row, S);
      if (V) take_row(c.values, x.values, row, V);
    }
  }
  const std::size_t n = source.size(), rows = n * steps;
  AtomicOutput out(path);
  {
    h5::File f = h5::File::create(out);
    write_header(f.root(), h);
    h5::Group st = f.root().open_group("steps");
    h5::Group rg = f.root().open_group("runs");
    st.append("step", c.step.data(), rows);
    st.append("correct", c.correct.data(), rows);
    for (std::size_t i = 0; i < std::size(kStepInts); ++i) st.append(kStepInts[i], c.ints[i].data(), rows);
    for (std::size_t i = 0; i < std::size(kStepDoubles); ++i) st.append(kStepDoubles[i], c.dbls[i].data(), rows);
    st.append("pose", c.pose.data(), rows);
    if (S) st.append("stage_times_s", c.stage.data(), rows);
    if (V) st.append("values", c.values.data(), rows);
    std::vector<std::int64_t> first(n);
    for (std::size_t i = 0; i < n; ++i) first[i] = static_cast<std::int64_t>(i * steps);
    rg.append("first_step_row", first.data(), n);
    rg.append("grasps", c.grasps.data(), n);
    rg.append("truth", c.truth.data(), n);
    rg.append("wall_time_s", c.wall.data(), n);
    rg.append("run", c.run.data(), n);
    rg.append("object", c.object.data(), n);
    rg.append("variant", c.variant.data(), n);
    f.root().set_attribute("complete", std::int64_t{complete ? 1 : 0});
    f.close();
  }
  out.commit();
}

}  // namespace

void RunStore::compact(const std::filesystem::path& path, bool complete) {
  // Copy the stored values themselves (no round trip through Pose), so compacting twice changes
  // nothing and equal runs give equal bytes however often their store was resumed. The pending
  // files are folded in; the new store is renamed in before they are removed (a kill between
  // the two leaves runs present twice, which read as once).
  const Merged m = read_consistent(path);
  std::vector<Columns> in;
  for (const auto& file : m.files) in.push_back(read_columns(file, m.contents.header));
  write_folded(path, m.contents.header, in, m.source, complete);
  for (std::size_t i = 1; i < m.files.size(); ++i) std::filesystem::remove(m.files[i]);
  std::error_code ec;
  std::filesystem::remove(pending_dir(path), ec);   // only when empty (no writer's temporary)
}

void RunStore::merge(const std::filesystem::path& out, const RunStoreHeader& header,
                     const std::vector<std::filesystem::path>& inputs, bool complete, bool first_copy) {
  std::error_code ec;
  if (std::filesystem::exists(out, ec) || std::filesystem::exists(pending_dir(out), ec))
    throw Error("the merged store already exists (remove it, or choose another name)", out.string());
  struct Entry {
    std::int32_t variant, object, run;
    std::size_t input;            // which of `inputs`
    std::pair<std::size_t, std::size_t> where;   // (file in `in`, row)
  };
  std::vector<Columns> in;
  std::vector<Entry> entries;
  for (std::size_t k = 0; k < inputs.size(); ++k) {
    const Merged m = read_consistent(inputs[k]);
    const RunStoreHeader& h = m.contents.header;
    if (h.steps != header.steps || h.stages != header.stages || h.step_values != header.step_values ||
        h.objects != header.objects || h.variant_labels != header.variant_labels ||
        h.database_objects != header.database_objects)
      throw Error("the store's layout (steps, stages, values, objects or variants) differs from the merged "
                  "store's", inputs[k].string(), "/header");
    const std::size_t base = in.size();
    for (const auto& file : m.files) in.push_back(read_columns(file, h));
    for (std::size_t i = 0; i < m.contents.runs.size(); ++i) {
      const RunRecord& r = m.contents.runs[i];
      entries.push_back({r.variant, r.object, r.run, k, {base + m.source[i].first, m.source[i].second}});
    }
  }
  std::stable_sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) {
    return std::tie(a.variant, a.object, a.run) < std::tie(b.variant, b.object, b.run);
  });
  std::vector<std::pair<std::size_t, std::size_t>> source;
  for (std::size_t i = 0; i < entries.size(); ++i) {
    const Entry& e = entries[i];
    const bool repeat = i > 0 && std::tie(e.variant, e.object, e.run) ==
                                     std::tie(entries[i - 1].variant, entries[i - 1].object, entries[i - 1].run);
    if (repeat && first_copy) continue;   // stable sort: the earlier input's copy came first
    if (repeat)
      throw Error("run " + std::to_string(e.run) + " of object " + header.objects.at(static_cast<std::size_t>(e.object)) +
                      " (variant " + std::to_string(e.variant) + ") is also in " + inputs[entries[i - 1].input].string(),
                  inputs[e.input].string(), "/runs");
    source.push_back(e.where);
  }
  write_folded(out, header, in, source, complete);
}

}  // namespace ts::io
