#include "experiments/runs/shards.hpp"

#include "experiments/params/config.hpp"
#include "io/run_store.hpp"

#include <nlohmann/json.hpp>

#include <map>
#include <set>

namespace ts::experiments {

std::string Shard::label() const {
  return std::to_string(index) + "/" + std::to_string(count);
}

Shard parse_shard(const std::string& text, const std::string& field) {
  const auto slash = text.find('/');
  auto number = [&](const std::string& t) {
    if (t.empty() || t.size() > 7 || t.find_first_not_of("0123456789") != std::string::npos) return -1;
    return std::stoi(t);
  };
  Shard s;
  if (slash != std::string::npos) {
    s.index = number(text.substr(0, slash));
    s.count = number(text.substr(slash + 1));
  }
  if (slash == std::string::npos || s.index < 1 || s.count < 1 || s.index > s.count || s.count > 1000000)
    throw Error("expected I/N, shard I of N with 1 <= I <= N <= 1000000 (got '" + text + "')", {}, field);
  return s;
}

std::vector<RunTask> shard_tasks(const std::vector<RunTask>& tasks, const Shard& shard) {
  std::vector<RunTask> out;
  for (std::size_t k = static_cast<std::size_t>(shard.index - 1); k < tasks.size();
       k += static_cast<std::size_t>(shard.count))
    out.push_back(tasks[k]);
  return out;
}

namespace {

/// The runs per object and variant of the experiment a store belongs to (its configuration).
int configured_runs(const io::RunStoreHeader& h, const std::string& path) {
  const auto c = nlohmann::ordered_json::parse(h.config_json, nullptr, false);
  if (!c.is_object() || !c.contains("runs") || !c["runs"].is_number_integer() || c["runs"].get<long long>() < 1 ||
      c["runs"].get<long long>() > 100000000)
    throw Error("the run store's configuration has no valid \"runs\"", path, "/header/config");
  return c["runs"].get<int>();
}

}  // namespace

std::size_t merge_shards(const std::filesystem::path& out, const std::vector<std::filesystem::path>& shards,
                         const std::function<void(std::size_t, std::size_t)>& progress) {
  if (shards.empty()) throw Error("no shard stores to merge", out.string(), "SHARD");
  std::error_code ec;
  if (std::filesystem::exists(out, ec))
    throw Error("the merged store already exists (remove it, or choose another name)", out.string());
  std::vector<io::RunStoreContents> stores;
  for (const auto& path : shards) {
    stores.push_back(io::RunStore::read(path));
    if (progress) progress(stores.size(), shards.size() + 1);
  }
  const io::RunStoreHeader& first = stores.front().header;
  const std::string first_path = shards.front().string();
  std::map<int, std::string> seen;   // shard index -> its store
  int count = 0;
  std::set<std::string> machines;
  for (std::size_t k = 0; k < shards.size(); ++k) {
    const io::RunStoreHeader& h = stores[k].header;
    const std::string path = shards[k].string();
    if (h.shard.empty())
      throw Error("not a shard store (written without --shard): nothing to merge it with", path, "/@shard");
    const Shard s = parse_shard(h.shard, "/@shard");
    if (k == 0) count = s.count;
    if (s.count != count)
      throw Error("shard " + h.shard + " is of a split into " + std::to_string(s.count) + ", " + first_path +
                      " of a split into " + std::to_string(count), path, "/@shard");
    if (const auto it = seen.find(s.index); it != seen.end())
      throw Error("shard " + h.shard + " is given twice: also " + it->second, path, "/@shard");
    seen[s.index] = path;
    // One experiment: the same results-determining configuration, database and layout.
    io::RunStoreHeader same = h;
    same.shard = first.shard;
    check_resumable(first, same, path);   // names the first differing key
    if (h.variant_configs != first.variant_configs)
      throw Error("the store's variants differ from " + first_path + "'s", path, "/header/variant_configs");
    // Complete: exactly the runs of its share.
    const auto planned = shard_tasks(all_tasks(h, configured_runs(h, path)), s);
    std::set<RunTask> want(planned.begin(), planned.end()), have;
    for (const auto& r : stores[k].runs) have.insert({r.variant, r.object, r.run});
    for (const RunTask& t : have)
      if (!want.count(t))
        throw Error("run " + std::to_string(t.run) + " of object " + h.objects.at(static_cast<std::size_t>(t.object)) +
                        " is not of shard " + h.shard, path, "/runs");
    if (have.size() != want.size())
      throw Error("shard " + h.shard + " is incomplete: " + std::to_string(have.size()) + " of its " +
                      std::to_string(want.size()) + " runs (finish it with experiment --shard " + h.shard +
                      " --resume)", path, "/runs");
    machines.insert(h.machine);
  }
  for (int i = 1; i <= count; ++i)
    if (!seen.count(i))
      throw Error("shard " + std::to_string(i) + "/" + std::to_string(count) + " is missing (" +
                      std::to_string(seen.size()) + " of " + std::to_string(count) + " given)", out.string(), "SHARD");
  io::RunStoreHeader merged = first;
  merged.shard.clear();
  merged.machine.clear();
  for (const auto& m : machines) merged.machine += (merged.machine.empty() ? "" : "; ") + m;
  io::RunStore::merge(out, merged, shards, true);
  if (progress) progress(shards.size() + 1, shards.size() + 1);
  std::size_t runs = 0;
  for (const auto& c : stores) runs += c.runs.size();
  return runs;
}

}  // namespace ts::experiments
