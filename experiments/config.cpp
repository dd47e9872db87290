#include "experiments/config.hpp"

#include "experiments/parameters.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <functional>
#include <map>
#include <set>

namespace ts::experiments {

namespace {

struct Ctx {
  const std::string& key;
  const std::string& file;
  [[noreturn]] void fail(const std::string& what) const { throw Error(what, file, key); }
};

std::string joined(const std::vector<std::string>& inputs) {
  std::string s;
  for (const auto& i : inputs) s += (s.empty() ? "" : ",") + i;
  return s;
}

const std::string& single(const std::vector<std::string>& inputs, const Ctx& c) {
  if (inputs.size() != 1)
    c.fail(c.key + " expects one value, got " + std::to_string(inputs.size()) +
           (inputs.empty() ? "" : " ('" + joined(inputs) + "')"));
  return inputs.front();
}

long long parse_integer(const std::string& text, const Ctx& c) {
  long long v = 0;
  const char* b = text.data();
  const char* e = b + text.size();
  if (!text.empty() && *b == '+') ++b;
  auto [p, ec] = std::from_chars(b, e, v);
  if (ec != std::errc() || p != e || text.empty())
    c.fail(c.key + " must be an integer (got '" + text + "')");
  return v;
}

int int_at_least(const std::vector<std::string>& inputs, long long lo, const Ctx& c) {
  const long long v = parse_integer(single(inputs, c), c);
  if (v < lo) c.fail(c.key + " must be at least " + std::to_string(lo) + " (got " + std::to_string(v) + ")");
  if (v > 100000000) c.fail(c.key + " is implausibly large (got " + std::to_string(v) + ")");
  return static_cast<int>(v);
}

double number_in(const std::vector<std::string>& inputs, double lo, double hi, const Ctx& c) {
  const std::string& text = single(inputs, c);
  double v = 0;
  auto [p, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc() || p != text.data() + text.size() || text.empty() || !std::isfinite(v))
    c.fail(c.key + " must be a number (got '" + text + "')");
  if (v < lo || v > hi) {
    std::string range = "[" + std::to_string(lo) + ", " + (std::isinf(hi) ? "inf" : std::to_string(hi)) + "]";
    c.fail(c.key + " must lie in " + range + " (got " + text + ")");
  }
  return v;
}

std::string choice(const std::vector<std::string>& inputs, const std::vector<std::string>& allowed,
                   const Ctx& c) {
  const std::string& v = single(inputs, c);
  if (std::find(allowed.begin(), allowed.end(), v) == allowed.end())
    c.fail(c.key + " must be one of " + joined(allowed) + " (got '" + v + "')");
  return v;
}

/// A list of names: "all" (alone) means empty = everything; inputs may also be comma lists.
std::vector<std::string> name_list(const std::vector<std::string>& inputs, const Ctx& c) {
  std::vector<std::string> out;
  for (const auto& in : inputs) {
    std::size_t start = 0;
    while (start <= in.size()) {
      const std::size_t comma = std::min(in.find(',', start), in.size());
      std::string name = in.substr(start, comma - start);
      name.erase(0, name.find_first_not_of(" \t"));
      name.erase(name.find_last_not_of(" \t") + 1);
      if (name.empty()) c.fail(c.key + " has an empty object name ('" + joined(inputs) + "')");
      out.push_back(name);
      start = comma + 1;
    }
  }
  if (out.empty()) c.fail(c.key + " is empty (use \"all\")");
  if (out.size() == 1 && out.front() == "all") return {};
  std::set<std::string> seen;
  for (const auto& n : out) {
    if (n == "all") c.fail(c.key + ": \"all\" cannot be combined with names");
    if (!seen.insert(n).second) c.fail(c.key + " lists '" + n + "' twice");
  }
  return out;
}

using Setter = std::function<void(ExperimentConfig&, const std::vector<std::string>&, const Ctx&)>;

struct KeyDef {
  std::string key;
  bool sweepable;
  Setter set;
  std::function<nlohmann::ordered_json(const ExperimentConfig&)> get;  ///< null: derived key
};

template <class T>
nlohmann::ordered_json opt(const std::optional<T>& v) {
  return v ? nlohmann::ordered_json(*v) : nlohmann::ordered_json(nullptr);
}

const std::vector<KeyDef>& key_defs() {
  using J = nlohmann::ordered_json;
  static const std::vector<KeyDef> defs = [] {
    std::vector<KeyDef> d;
    auto add = [&](std::string key, bool sweepable, Setter s,
                   std::function<J(const ExperimentConfig&)> g) {
      d.push_back({std::move(key), sweepable, std::move(s), std::move(g)});
    };
    add("name", false, [](auto& c, auto& in, auto& x) { c.name = single(in, x); },
        [](auto& c) { return J(c.name); });
    add("description", false, [](auto& c, auto& in, auto& x) { c.description = joined(in); },
        [](auto& c) { return J(c.description); });
    add("objects", false, [](auto& c, auto& in, auto& x) { c.objects = name_list(in, x); },
        [](auto& c) { return c.objects.empty() ? J("all") : J(c.objects); });
    add("database", false, [](auto& c, auto& in, auto& x) { c.database = name_list(in, x); },
        [](auto& c) { return c.database.empty() ? J("all") : J(c.database); });
    add("database_size", true,
        [](auto& c, auto& in, auto& x) { c.database_size = int_at_least(in, 1, x); },
        [](auto& c) { return opt(c.database_size); });
    // hidden: names of the database file, or "each" (leave-one-out); see config.hpp.
    add("hidden", false, [](auto& c, auto& in, auto& x) { c.hidden = name_list(in, x); },
        [](auto& c) { return J(c.hidden); });
    add("runs", false, [](auto& c, auto& in, auto& x) { c.runs = int_at_least(in, 1, x); },
        [](auto& c) { return J(c.runs); });
    add("steps", false, [](auto& c, auto& in, auto& x) { c.steps = int_at_least(in, 1, x); },
        [](auto& c) { return J(c.steps); });
    add("pool", false, [](auto& c, auto& in, auto& x) { c.pool = int_at_least(in, 1, x); },
        [](auto& c) { return J(c.pool); });
    // protocol: independent (default; a pose and pool per run) | shared_pool (the paper's: a
    // pose and pool per object). Not sweepable: variants share their runs' grasps.
    add("protocol", false,
        [](auto& c, auto& in, auto& x) { c.protocol = choice(in, {"independent", "shared_pool"}, x); },
        [](auto& c) { return J(c.protocol); });
    add("method", true,
        [](auto& c, auto& in, auto& x) {
          c.method = choice(in, {"bricpsf", "batch-ransac", "ransac-icp", "ransac-icp-fs"}, x);
        },
        [](auto& c) { return J(c.method); });
    add("preset", true,
        [](auto& c, auto& in, auto& x) { c.preset = choice(in, {"improved", "paper"}, x); },
        [](auto& c) { return J(c.preset); });
    add("noise", true,
        [](auto& c, auto& in, auto& x) { c.noise = choice(in, {"ideal", "underwater", "deepsea"}, x); },
        [](auto& c) { return J(c.noise); });
    const double inf = std::numeric_limits<double>::infinity();
    add("noise.arm_position_sigma_m", true,
        [=](auto& c, auto& in, auto& x) { c.noise_params.arm_position_sigma_m = number_in(in, 0, 1, x); },
        [](auto& c) { return opt(c.noise_params.arm_position_sigma_m); });
    add("noise.arm_rotation_sigma_deg", true,
        [=](auto& c, auto& in, auto& x) { c.noise_params.arm_rotation_sigma_deg = number_in(in, 0, 90, x); },
        [](auto& c) { return opt(c.noise_params.arm_rotation_sigma_deg); });
    add("noise.sensel_noise", true,
        [=](auto& c, auto& in, auto& x) { c.noise_params.sensel_noise = number_in(in, 0, 10, x); },
        [](auto& c) { return opt(c.noise_params.sensel_noise); });
    add("noise.force_noise", true,
        [=](auto& c, auto& in, auto& x) { c.noise_params.force_noise = number_in(in, 0, 10, x); },
        [](auto& c) { return opt(c.noise_params.force_noise); });
    add("noise.contact_sigma_m", true,
        [=](auto& c, auto& in, auto& x) { c.noise_params.contact_sigma_m = number_in(in, 0, 1, x); },
        [](auto& c) { return opt(c.noise_params.contact_sigma_m); });
    add("sensors", true,
        [](auto& c, auto& in, auto& x) { c.sensors = std::stoi(choice(in, {"1", "6"}, x)); },
        [](auto& c) { return J(c.sensors); });
    add("sensing", false, [](auto& c, auto& in, auto& x) { c.sensing = choice(in, {"pads", "probe"}, x); },
        [](auto& c) { return J(c.sensing); });
    add("seed", false,
        [](auto& c, auto& in, auto& x) {
          const std::string& t = single(in, x);
          std::uint64_t v = 0;
          auto [p, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
          if (ec != std::errc() || p != t.data() + t.size() || t.empty())
            x.fail("seed must be an unsigned integer (got '" + t + "')");
          c.seed = v;
        },
        [](auto& c) { return J(c.seed); });
    // ransac.samples = "NxR": ransac.triplets and ransac.registrations together.
    add("ransac.samples", true,
        [](auto& c, auto& in, auto& x) {
          const std::string& t = single(in, x);
          const auto cross = t.find_first_of("xX*");
          if (cross == std::string::npos)
            x.fail("ransac.samples must read NxR, e.g. 15x200 (got '" + t + "')");
          auto part = [&](const std::string& text, const char* what) {
            long long v = 0;
            auto [p, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
            if (ec != std::errc() || p != text.data() + text.size() || text.empty() || v < 1 ||
                v > 100000000)
              x.fail(x.key + ": " + what + " must be a positive integer (got '" + t + "')");
            return static_cast<double>(v);
          };
          c.params["ransac.triplets"] = part(t.substr(0, cross), "N");
          c.params["ransac.registrations"] = part(t.substr(cross + 1), "R");
        },
        nullptr);
    // Every method parameter (experiments/parameters.cpp), sweepable; unset: the preset's value.
    for (const Parameter& p : method_parameters())
      add(p.key, true,
          [&p](auto& c, auto& in, auto& x) { c.params[p.key] = parse_value(p, single(in, x), x.file, x.key); },
          [&p](auto& c) {
            const auto it = c.params.find(p.key);
            return it == c.params.end() ? J(nullptr) : p.json(it->second);
          });
    add("memory_budget_mb", false,
        [=](auto& c, auto& in, auto& x) { c.memory_budget_mb = number_in(in, 0, inf, x); },
        [](auto& c) { return opt(c.memory_budget_mb); });
    // calibration: a confidence calibration file (JSON, `touchstone calibrate`); "" none.
    add("calibration", false, [](auto& c, auto& in, auto& x) { c.calibration = single(in, x); },
        [](auto& c) { return J(c.calibration); });
    add("schedule", false,
        [](auto& c, auto& in, auto& x) { c.schedule = choice(in, {"runs", "steps"}, x); },
        [](auto& c) { return J(c.schedule); });
    return d;
  }();
  return defs;
}

const KeyDef* find_def(const std::string& key) {
  for (const auto& d : key_defs())
    if (d.key == key) return &d;
  return nullptr;
}

std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j)
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

[[noreturn]] void unknown_key(const std::string& key, const std::string& file) {
  std::string best;
  std::size_t best_d = 4;
  const std::string bare = key.rfind("sweep.", 0) == 0 ? key.substr(6) : key;
  for (const auto& d : key_defs()) {
    const std::size_t dist = edit_distance(bare, d.key);
    if (dist < best_d) best_d = dist, best = d.key;
  }
  throw Error("unknown key '" + key + "'" + (best.empty() ? "" : " (did you mean '" + best + "'?)"),
              file, key);
}

}  // namespace

const std::vector<std::string>& config_keys() {
  static const std::vector<std::string> keys = [] {
    std::vector<std::string> k;
    for (const auto& d : key_defs()) k.push_back(d.key);
    return k;
  }();
  return keys;
}

void set_key(ExperimentConfig& config, const std::string& key,
             const std::vector<std::string>& inputs, const std::string& file) {
  if (key.rfind("sweep.", 0) == 0) {
    const std::string target = key.substr(6);
    const KeyDef* d = find_def(target);
    if (!d) unknown_key(key, file);
    if (!d->sweepable)
      throw Error("key '" + target + "' cannot be swept (sweepable: method, noise, noise.*, "
                  "sensors, database_size, ransac.*, bricpsf.*, icp.*)", file, key);
    if (inputs.empty()) throw Error(key + " needs at least one value", file, key);
    SweepAxis axis{target, {}};
    std::set<std::string> seen;
    for (const auto& v : inputs) {
      if (!seen.insert(v).second) throw Error(key + " lists '" + v + "' twice", file, key);
      ExperimentConfig probe = config;  // validate each value now, naming the sweep key
      d->set(probe, {v}, Ctx{key, file});
      axis.values.push_back({v});
    }
    for (auto& a : config.sweep)
      if (a.key == target) {
        a = std::move(axis);
        return;
      }
    config.sweep.push_back(std::move(axis));
    return;
  }
  const KeyDef* d = find_def(key);
  if (!d) unknown_key(key, file);
  d->set(config, inputs, Ctx{key, file});
}

void load_config_file(ExperimentConfig& config, const std::filesystem::path& file) {
  const std::string name = file.string();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec))
    throw Error("cannot read the experiment configuration", name);
  std::vector<CLI::ConfigItem> items;
  try {
    CLI::ConfigTOML parser;
    items = parser.from_file(name);
  } catch (const CLI::Error& e) {
    throw Error(std::string("cannot parse the experiment configuration: ") + e.what(), name);
  }
  std::set<std::string> seen;
  for (const auto& item : items) {
    if (item.name == "++" || item.name == "--") continue;  // CLI11's section markers
    const std::string key = item.fullname();
    if (!seen.insert(key).second) throw Error("key given twice", name, key);
    set_key(config, key, item.inputs, name);
  }
  validate(config, name);
}

void validate(const ExperimentConfig& c, const std::string& file) {
  if (c.pool < c.steps)
    throw Error("pool (" + std::to_string(c.pool) + ") must hold at least steps (" +
                    std::to_string(c.steps) + ") grasps: each run draws steps grasps from it "
                    "without repetition", file, "pool");
  if (c.database_size && !c.objects.empty() &&
      static_cast<std::size_t>(*c.database_size) < c.objects.size())
    throw Error("database_size (" + std::to_string(*c.database_size) + ") is smaller than the " +
                    std::to_string(c.objects.size()) + " explored objects", file, "database_size");
  for (const auto& a : c.sweep)
    if (a.key == "database_size" && !c.objects.empty())
      for (const auto& v : a.values)
        if (std::stoll(v.front()) < static_cast<long long>(c.objects.size()))
          throw Error("sweep value " + v.front() + " is smaller than the " +
                          std::to_string(c.objects.size()) + " explored objects", file,
                      "sweep.database_size");
  std::size_t variants = 1;
  for (const auto& a : c.sweep) {
    variants *= a.values.size();
    if (variants > 10000) throw Error("the sweep has more than 10000 variants", file, "sweep");
  }
}

ResolvedObjects resolve_objects(const ExperimentConfig& c,
                                const std::vector<std::string>& names) {
  const std::set<std::string> known(names.begin(), names.end());
  ResolvedObjects r;
  r.explored = c.objects.empty() ? names : c.objects;
  for (const auto& n : r.explored)
    if (!known.count(n)) throw Error("unknown object '" + n + "' (not in the database)", {}, "objects");
  std::vector<std::string> pool = c.database.empty() ? names : c.database;
  for (const auto& n : pool)
    if (!known.count(n)) throw Error("unknown object '" + n + "' (not in the database)", {}, "database");
  // Open set: hidden objects leave the recognizer's database (they may still be explored).
  r.hide_each = c.hidden.size() == 1 && c.hidden.front() == "each";
  std::set<std::string> hidden;
  if (!r.hide_each)
    for (const auto& n : c.hidden) {
      if (n == "each") throw Error("hidden: \"each\" cannot be combined with names", {}, "hidden");
      if (!known.count(n)) throw Error("hidden object '" + n + "' is not in the database", {}, "hidden");
      hidden.insert(n);
    }
  std::erase_if(pool, [&](const std::string& n) { return hidden.count(n) > 0; });
  if (pool.empty()) throw Error("every database object is hidden", {}, "hidden");
  const std::set<std::string> in_pool(pool.begin(), pool.end());
  for (const auto& n : r.explored) {
    if (hidden.count(n)) {
      r.hidden.push_back(n);
      continue;
    }
    if (!in_pool.count(n))
      throw Error("explored object '" + n + "' is not among the database objects", {}, "database");
  }
  if (r.hide_each) r.hidden = r.explored;
  const std::set<std::string> explored(r.explored.begin(), r.explored.end());
  for (const auto& n : r.explored)
    if (!hidden.count(n)) r.database.push_back(n);
  for (const auto& n : pool)
    if (!explored.count(n)) r.database.push_back(n);
  if (c.database_size) {
    if (static_cast<std::size_t>(*c.database_size) < r.explored.size())
      throw Error("database_size (" + std::to_string(*c.database_size) + ") is smaller than the " +
                  std::to_string(r.explored.size()) + " explored objects", {}, "database_size");
    if (static_cast<std::size_t>(*c.database_size) > r.database.size())
      throw Error("database_size (" + std::to_string(*c.database_size) + ") exceeds the " +
                  std::to_string(r.database.size()) + " objects available", {}, "database_size");
    r.database.resize(static_cast<std::size_t>(*c.database_size));
  }
  return r;
}

std::vector<Variant> expand_variants(const ExperimentConfig& config) {
  ExperimentConfig base = config;
  base.sweep.clear();
  std::vector<Variant> out{{"", base}};
  for (const auto& axis : config.sweep) {
    std::vector<Variant> next;
    for (const auto& v : out)
      for (const auto& value : axis.values) {
        Variant n = v;
        set_key(n.config, axis.key, value);
        n.label += (n.label.empty() ? "" : ", ") + axis.key + "=" + joined(value);
        next.push_back(std::move(n));
      }
    out = std::move(next);
  }
  return out;
}

nlohmann::ordered_json to_json(const ExperimentConfig& config) {
  nlohmann::ordered_json j;
  for (const auto& d : key_defs())
    if (d.get) j[d.key] = d.get(config);
  nlohmann::ordered_json sweep = nlohmann::ordered_json::object();
  for (const auto& a : config.sweep) {
    nlohmann::ordered_json values = nlohmann::ordered_json::array();
    for (const auto& v : a.values) values.push_back(joined(v));
    sweep[a.key] = values;
  }
  j["sweep"] = sweep;
  return j;
}

std::string first_difference(const nlohmann::ordered_json& a, const nlohmann::ordered_json& b) {
  static const std::set<std::string> informative{"name", "description", "schedule"};
  std::vector<std::string> keys;
  for (auto it = a.begin(); it != a.end(); ++it) keys.push_back(it.key());
  for (auto it = b.begin(); it != b.end(); ++it)
    if (!a.contains(it.key())) keys.push_back(it.key());
  for (const auto& k : keys) {
    if (informative.count(k)) continue;
    // A key absent on one side is unset there (a store written before the key existed).
    const nlohmann::ordered_json va = a.contains(k) ? a.at(k) : nlohmann::ordered_json(nullptr);
    const nlohmann::ordered_json vb = b.contains(k) ? b.at(k) : nlohmann::ordered_json(nullptr);
    if (va != vb) return k;
  }
  return {};
}

}  // namespace ts::experiments
