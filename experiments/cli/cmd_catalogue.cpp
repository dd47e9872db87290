// `touchstone catalogue`: generate parametric subsea objects (datasets/catalogue/catalogue.hpp).
#include "experiments/cli/cli_common.hpp"
#include "experiments/cli/progress.hpp"

#include "datasets/catalogue/catalogue.hpp"
#include "experiments/resources.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>

namespace ts::cli {

namespace {

using json = nlohmann::ordered_json;

struct CatalogueOptions {
  CommonOptions common;
  long long count = 0;
  std::string out, families, config;
  bool force = false;
  double coarsen = 1.0;
  ProgressOptions progress;
};

/// --config FILE (TOML or INI, CLI11's parser): sections are families, keys are parameters
/// given as [min, max] (or one number for both), and `weight`:
///   [flange_blind]
///   thickness_ratio = [0.9, 1.1]
///   weight = 2
void load_config(catalogue::FamilySet& set, const std::string& file) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec)) throw Error("cannot read the catalogue configuration", file);
  std::vector<CLI::ConfigItem> items;
  try {
    CLI::ConfigTOML parser;
    items = parser.from_file(file);
  } catch (const CLI::Error& e) {
    throw Error(std::string("cannot parse the catalogue configuration: ") + e.what(), file);
  }
  std::set<std::string> seen;
  for (const auto& item : items) {
    if (item.name == "++" || item.name == "--") continue;
    const std::string key = item.fullname();
    if (!seen.insert(key).second) throw Error("key given twice", file, key);
    if (item.parents.size() != 1)
      throw Error("expected a key inside a [family] section, e.g. [flange_blind] thickness_ratio = [0.9, 1.1]", file, key);
    std::vector<double> v;
    for (const auto& text : item.inputs) {
      try {
        std::size_t used = 0;
        v.push_back(std::stod(text, &used));
        if (used != text.size()) throw std::invalid_argument(text);
      } catch (const std::exception&) {
        throw Error("'" + text + "' is not a number", file, key);
      }
    }
    if (v.size() == 1) v.push_back(v[0]);
    if (v.size() != 2) throw Error("expected [min, max] or one number", file, key);
    set.set_range(item.parents[0], item.name, v[0], v[1], file);
  }
  set.validate(file);
}

int run_catalogue(const CatalogueOptions& o) {
  catalogue::CatalogueSettings s;
  if (o.count < 1 || o.count > 100000)
    throw Error("--count must lie in 1..100000, not " + std::to_string(o.count), "", "--count");
  s.count = static_cast<std::size_t>(o.count);
  s.seed = o.common.seed;
  s.force = o.force;
  s.build.coarsen = o.coarsen;
  s.families = catalogue::FamilySet::select(o.families);
  if (!o.config.empty()) load_config(s.families, o.config);
  // Progress with the time left (progress.hpp); objects finish on several threads.
  ProgressReport progress(o.progress, "catalogue", "objects", stderr_is_terminal(), o.common.json, std::cerr);
  std::mutex progress_mutex;
  if (progress.active())
    s.progress = [&](std::size_t done, std::size_t total) {
      std::lock_guard<std::mutex> lock(progress_mutex);
      progress.update(done, total);
    };
  const auto r = catalogue::generate_catalogue(o.out, s);
  progress.finish();

  std::map<std::string, std::size_t> per_family;
  std::size_t remeshed = 0, tri_sum = 0, tri_max = 0, tri_min = r.objects.empty() ? 0 : r.objects[0].triangles;
  for (const auto& ob : r.objects) {
    ++per_family[ob.family];
    remeshed += ob.remeshed > 0;
    tri_sum += ob.triangles;
    tri_max = std::max(tri_max, ob.triangles);
    tri_min = std::min(tri_min, ob.triangles);
  }
  const double tri_mean = r.objects.empty() ? 0.0 : double(tri_sum) / double(r.objects.size());
  const int threads = thread_count(o.common);
  if (o.common.json) {
    json j;
    j["out"] = o.out;
    j["count"] = r.objects.size();
    j["seed"] = s.seed;
    j["generator"] = catalogue::kGeneratorVersion;
    json fam = json::object();
    for (const auto& f : s.families.families) fam[f.name] = per_family[f.name];
    j["families"] = fam;
    j["redraws"] = r.redraws;
    j["remeshed"] = remeshed;
    j["triangles"] = {{"mean", tri_mean}, {"min", tri_min}, {"max", tri_max}};
    j["bytes"] = r.bytes;
    json pairs = json::array();
    for (const auto& p : r.closest)
      pairs.push_back({{"a", r.objects[p.a].name}, {"b", r.objects[p.b].name}, {"distance", p.distance}});
    j["closest_pairs"] = pairs;
    j["tolerance"] = s.tolerance;
    j["seconds"] = r.seconds;
    j["threads"] = threads;
    j["machine"] = experiments::machine_description();
    std::cout << j.dump(2) << '\n';
    return 0;
  }
  char line[256];
  std::snprintf(line, sizeof line, "catalogue of %zu objects (seed %llu, %s) in %s: %.1f s on %d thread%s (%s)\n",
                r.objects.size(), static_cast<unsigned long long>(s.seed), catalogue::kGeneratorVersion, o.out.c_str(),
                r.seconds, threads, threads == 1 ? "" : "s", experiments::machine_description().c_str());
  std::cout << line;
  std::cout << "objects per family:\n";
  for (const auto& f : s.families.families) {
    std::snprintf(line, sizeof line, "  %-18s %zu\n", f.name.c_str(), per_family[f.name]);
    std::cout << line;
  }
  std::snprintf(line, sizeof line, "triangles per mesh: mean %.0f, min %zu, max %zu; mesh files %.1f MB\n", tri_mean, tri_min,
                tri_max, double(r.bytes) / 1e6);
  std::cout << line;
  std::snprintf(line, sizeof line, "redrawn as congruent to an earlier object (signature distance <= %g): %zu\n",
                s.tolerance, r.redraws);
  std::cout << line;
  std::snprintf(line, sizeof line, "meshed again at a finer voxel after a failed mesh check: %zu\n", remeshed);
  std::cout << line << "closest pairs (signature distance, max |ln ratio| of volume, area, inertia):\n";
  for (const auto& p : r.closest) {
    std::snprintf(line, sizeof line, "  %-24s %-24s %.5f\n", r.objects[p.a].name.c_str(), r.objects[p.b].name.c_str(),
                  p.distance);
    std::cout << line;
  }
  return 0;
}

}  // namespace

void register_catalogue(CLI::App& app) {
  auto opt = std::make_shared<CatalogueOptions>();
  auto* sub = app.add_subcommand("catalogue",
                                 "Generate parametric subsea objects (pipework, valves, fasteners, ROV tooling) as "
                                 "closed meshes in metres, with manifest.tsv and catalogue.tsv");
  sub->add_option("--count", opt->count, "Number of objects (1..100000)")->required();
  sub->add_option("--out", opt->out, "Output folder (must not exist unless --force)")->required();
  sub->add_option("--families", opt->families, "Comma-separated subset of families (default: all)");
  sub->add_option("--config", opt->config,
                  "TOML/INI file: [family] sections with param = [min, max] and weight = w");
  sub->add_flag("--force", opt->force, "Replace an existing output folder (only once the new catalogue is complete)");
  sub->add_option("--coarsen", opt->coarsen, "Multiply every voxel size (faster, coarser meshes)")
      ->check(CLI::Range(0.25, 20.0))->capture_default_str();
  add_common(sub, opt->common);
  add_progress(sub, opt->progress);
  std::string list;
  for (const auto& f : catalogue::all_families()) list += "  " + f.name + ": " + f.description + "\n";
  sub->footer("Families:\n" + list);
  sub->callback([opt] { run_command(opt->common, [opt] { return run_catalogue(*opt); }); });
}

}  // namespace ts::cli
