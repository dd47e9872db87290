#include "experiments/params/config.hpp"

#include "engine/recognition/evaluate.hpp"
#include "engine/touch/fusion.hpp"
#include "experiments/params/parameters.hpp"
#include "experiments/resources.hpp"
#include "io/run_store.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <functional>
#include <iterator>
#include <map>
#include <optional>
#include <set>

namespace ts::experiments {

namespace {

std::string joined_inputs(const std::vector<std::string>& inputs) {
  std::string s;
  for (const auto& i : inputs) s += (s.empty() ? "" : ",") + i;
  return s;
}

/// The parameter of a configuration key (exactly its key; experiments/params/parameters.cpp).
const Parameter* find_def(const std::string& key) {
  for (const auto& p : parameters())
    if (p.key == key) return &p;
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
  for (const auto& d : parameters()) {
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
    for (const auto& d : parameters()) k.push_back(d.key);
    return k;
  }();
  return keys;
}

void set_key(ExperimentConfig& config, const std::string& key,
             const std::vector<std::string>& inputs, const std::string& file) {
  if (key.rfind("sweep.", 0) == 0) {
    const std::string target = key.substr(6);
    const Parameter* d = find_def(target);
    if (!d) unknown_key(key, file);
    if (!d->sweepable) {
      std::string sweepable;
      for (const auto& p : parameters())
        if (p.sweepable && p.kind != Parameter::Kind::method) sweepable += p.key + ", ";
      throw Error("key '" + target + "' cannot be swept (sweepable: " + sweepable + "every method parameter)",
                  file, key);
    }
    if (inputs.empty()) throw Error(key + " needs at least one value", file, key);
    SweepAxis axis{target, {}};
    std::set<std::string> seen;
    for (const auto& v : inputs) {
      if (!seen.insert(v).second) throw Error(key + " lists '" + v + "' twice", file, key);
      ExperimentConfig probe = config;  // validate each value now, naming the sweep key
      d->set_config(probe, {v}, file, key);
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
  const Parameter* d = find_def(key);
  if (!d) unknown_key(key, file);
  d->set_config(config, inputs, file, key);
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

void check_scene_keys(const ExperimentConfig& c, const std::string& file) {
  const SceneOverrides& sc = c.scene_params;
  if (c.scene == "cluttered" || c.scene == "none") return;   // (scene none ignores every scene.* key)
  for (const auto& [key, given] : {std::pair{"scene.neighbours", sc.neighbours.has_value()},
                                   std::pair{"scene.neighbour_distance_m", sc.neighbour_distance_m.has_value()},
                                   std::pair{"scene.neighbour_share", sc.neighbour_share.has_value()}})
    if (given) throw Error(std::string(key) + " is only for scene = cluttered (scene is " + c.scene + ")", file, key);
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
  if (c.scene != "none" && c.sensing == "probe")
    throw Error("scene " + c.scene + " needs sensing = pads or fingertips (the probe does not touch scenes yet)", file,
                "scene");
  check_scene_keys(c, file);
  std::size_t variants = 1;
  for (const auto& a : c.sweep) {
    variants *= a.values.size();
    if (variants > 10000) throw Error("the sweep has more than 10000 variants", file, "sweep");
  }
  check_memory(c, std::max<std::size_t>(c.objects.size(), 1), file);
}

void check_memory(const ExperimentConfig& c, std::size_t explored_objects, const std::string& file,
                  double memory_bytes) {
  if (memory_bytes <= 0.0) memory_bytes = physical_memory_bytes();
  if (memory_bytes <= 0.0) return;   // unknown: nothing to compare with
  auto refuse = [&](const std::string& what, double count, double element_bytes, const std::string& key) {
    const double bytes = count * element_bytes;
    if (bytes <= memory_bytes) return;
    char text[400];
    std::snprintf(text, sizeof text, "%s: at least %.3g GB (%.0f bytes each), more than the %.3g GB of this machine's memory",
                  what.c_str(), bytes / 1e9, element_bytes, memory_bytes / 1e9);
    throw Error(text, file, key);
  };
  const std::vector<Variant> variants = expand_variants(c);
  // The step records: the largest factor names the key.
  const std::pair<double, std::string> factors[] = {{static_cast<double>(c.runs), "runs"},
                                                    {static_cast<double>(c.steps), "steps"},
                                                    {static_cast<double>(variants.size()), "sweep"},
                                                    {static_cast<double>(explored_objects), "objects"}};
  const auto largest = std::max_element(std::begin(factors), std::end(factors),
                                        [](const auto& a, const auto& b) { return a.first < b.first; });
  refuse("runs x steps x variants x explored objects = " + std::to_string(c.runs) + " x " + std::to_string(c.steps) +
             " x " + std::to_string(variants.size()) + " x " + std::to_string(explored_objects) + " step records",
         static_cast<double>(c.runs) * c.steps * static_cast<double>(variants.size()) * static_cast<double>(explored_objects),
         static_cast<double>(sizeof(io::RunStepRecord)), largest->second);
  refuse("a pool of " + std::to_string(c.pool) + " simulated grasps", c.pool,
         static_cast<double>(sizeof(GraspRecord) + sizeof(Pose)), "pool");
  std::string swept;   // the sweep's key of the RANSAC sampling, if any
  for (const auto& a : c.sweep)
    if (a.key == "ransac.samples" || a.key == "ransac.triplets" || a.key == "ransac.registrations") swept = "sweep." + a.key;
  for (const Variant& v : variants) {
    const RansacSettings& r = method_settings(v.config).recognizer.ransac;
    refuse("ransac.triplets x ransac.registrations = " + std::to_string(r.triplets) + " x " + std::to_string(r.registrations) +
               " registrations a step" + (v.label.empty() ? std::string() : " (" + v.label + ")"),
           static_cast<double>(r.triplets) * r.registrations, static_cast<double>(sizeof(std::optional<Candidate>)),
           v.label.empty() || swept.empty() ? "ransac.samples" : swept);
  }
}

ResolvedObjects resolve_objects(const ExperimentConfig& c,
                                const std::vector<std::string>& names) {
  const std::set<std::string> known(names.begin(), names.end());
  ResolvedObjects r;
  r.explored = c.objects.empty() ? names : c.objects;
  for (const auto& n : r.explored)
    if (!known.count(n)) throw Error("unknown object '" + n + "' (not in the database)", {}, "objects");
  // Known-object localization: each run's recognizer may name only its explored object.
  r.known_each = c.database.size() == 1 && c.database.front() == "each";
  if (r.known_each && !c.hidden.empty())
    throw Error("database = \"each\" (localize each object) cannot be combined with hidden objects", {}, "hidden");
  std::vector<std::string> pool = r.known_each ? r.explored : c.database.empty() ? names : c.database;
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
        n.label += (n.label.empty() ? "" : ", ") + axis.key + "=" + joined_inputs(value);
        next.push_back(std::move(n));
      }
    out = std::move(next);
  }
  return out;
}

nlohmann::ordered_json to_json(const ExperimentConfig& config) {
  nlohmann::ordered_json j;
  for (const auto& p : parameters())
    if (p.get_config) j[p.key] = p.get_config(config);
  nlohmann::ordered_json sweep = nlohmann::ordered_json::object();
  for (const auto& a : config.sweep) {
    nlohmann::ordered_json values = nlohmann::ordered_json::array();
    for (const auto& v : a.values) values.push_back(joined_inputs(v));
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
