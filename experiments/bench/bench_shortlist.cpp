// Benchmark of the object shortlist (engine/recognition/shortlist.hpp) on a database file with simulated
// tactile logs: how often the explored object is among the K objects the shortlist keeps
// (recall@K), per step, and what the screening costs. For comparison, the same recall for
// object evidence from features alone (naive Bayes nearest neighbour: every object's nearest
// feature to each contact feature, distances summed), which the shortlist does not use.
//
//   build/bench/bench_shortlist --db DB.h5 [--seeds 2] [--grasps 20] [--noise underwater]
//       [--explore all|originals] [--max-explore 45] [--queries 64]
//
// --explore originals explores only objects whose name has no "_v<k>" suffix (the originals of
// scripts/make_variants.py databases). Batch RANSAC runs with the improved preset's settings.
// Also the geometry an explored object holds in memory (what --memory-budget counts). Prints
// the machine, thread count and every figure.
#include "datasets/simulator.hpp"
#include "engine/recognition/ransac.hpp"
#include "engine/recognition/recognizer.hpp"
#include "engine/recognition/shortlist.hpp"
#include "engine/touch/fusion.hpp"
#include "experiments/params/parameters.hpp"
#include "experiments/resources.hpp"
#include "io/db_store.hpp"

#include <CLI/CLI.hpp>

#include <tbb/info.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

namespace {

using namespace ts;
using Clock = std::chrono::steady_clock;



}  // namespace

int main(int argc, char** argv) {
  std::string db_path, noise = "underwater", explore = "all";
  std::size_t seeds = 2, grasps = 20, max_explore = 45, queries_n = 64;
  CLI::App app{"bench_shortlist: recall of the object shortlist per step, and its cost"};
  app.add_option("--db", db_path, "Object database (HDF5)")->required();
  app.add_option("--seeds", seeds, "Logs per explored object")->check(CLI::Range(1, 100000));
  app.add_option("--grasps", grasps, "Steps (grasps) of each log")->check(CLI::Range(1, 100000));
  app.add_option("--explore", explore, "all | originals (objects without a _v<k> suffix)")
      ->check(CLI::IsMember({"all", "originals"}));
  app.add_option("--max-explore", max_explore, "At most this many explored objects, evenly spread")
      ->check(CLI::Range(1, 1000000));
  app.add_option("--queries", queries_n, "Contact features that vote (features alone)")->check(CLI::Range(1, 1000000));
  // --noise: the declared simulator parameter (touchstone params), underwater by default here.
  experiments::ParameterFlags run_flags;
  experiments::add_parameter_flags(app, run_flags, "Simulator parameters (touchstone params)",
                                   [](const experiments::Parameter& p) { return p.key == "noise"; });
  CLI11_PARSE(app, argc, argv);
  if (const auto it = run_flags.given.find("noise"); it != run_flags.given.end()) noise = it->second;
  try {
    std::vector<std::size_t> steps = {5, 10, 20};
    const std::vector<std::size_t> Ks = {4, 8, 16, 24, 32, 48, 64};
    steps.erase(std::remove_if(steps.begin(), steps.end(), [&](std::size_t s) { return s > grasps; }), steps.end());
    steps.push_back(grasps);
    std::sort(steps.begin(), steps.end());
    steps.erase(std::unique(steps.begin(), steps.end()), steps.end());

    auto reader = std::make_shared<io::DbReader>(db_path);
    Database db(reader);
    // A variant's name ends in _v and digits (the regular expression .*_v[0-9]+$).
    const auto is_variant = [](const std::string& name) {
      const auto v = name.rfind("_v");
      return v != std::string::npos && v + 2 < name.size() &&
             std::all_of(name.begin() + static_cast<std::ptrdiff_t>(v + 2), name.end(),
                         [](char c) { return c >= '0' && c <= '9'; });
    };
    std::vector<std::size_t> explored;
    for (std::size_t o = 0; o < db.size(); ++o)
      if (explore == "all" || !is_variant(db.info(o).name)) explored.push_back(o);
    if (explored.size() > max_explore) {  // evenly spread
      std::vector<std::size_t> pick;
      for (std::size_t i = 0; i < max_explore; ++i) pick.push_back(explored[i * explored.size() / max_explore]);
      explored = pick;
    }
    std::printf("bench_shortlist: object shortlist recall and cost\nmachine: %s, %d threads\n"
                "database: %s (%zu objects), %zu explored objects x %zu logs, %zu grasps, noise %s, %zu voting features\n",
                experiments::machine_description().c_str(), tbb::info::default_concurrency(), db_path.c_str(), db.size(),
                explored.size(), seeds, grasps, noise.c_str(), queries_n);
    auto t0 = Clock::now();
    const RecognizerSettings rs = RecognizerSettings::improved();
    FeatureSearch search;
    search.table = FeatureTable::shared(db);
    const auto& table = search.table;
    std::printf("feature table: %zu features, %.1f MB, built in %.2f s\n", table->features(),
                double(table->memory_bytes()) / 1e6,
                std::chrono::duration<double>(Clock::now() - t0).count());

    // (step, k, vote) -> ranks; time per k
    std::map<std::pair<std::size_t, int>, std::vector<std::size_t>> ranks;  // (step, rule) -> ranks
    std::vector<double> screen_time, prune_time, register_time;
    std::vector<std::size_t> reached;
    std::vector<std::size_t> allowed_counts;
    SceneSettings scene_settings;
    scene_settings.descriptor = db.settings().descriptor;
    for (std::size_t o : explored) {
      for (std::size_t seed = 1; seed <= seeds; ++seed) {
        datasets::SimulatorSettings ss;
        ss.grasps = grasps;
        ss.noise = datasets::noise_profile(noise);
        ss.seed = 1000 * seed + o;
        datasets::Simulator sim(reader->load_mesh(o), db.info(o).name, Gripper(), ss);
        const TactileLog log = sim.run().log;
        ExplorationSettings es;
        es.free.s_obj_max = largest_object_extent(db);
        Exploration ex(log, es);
        for (std::size_t step : steps) {
          ex.advance_to(step);
          const Scene scene = prepare_scene(ex.contact_cloud(), {}, db.settings().fpfh, scene_settings, seed, step);
          const std::vector<std::uint8_t> allowed = objects_spanning(scene, db, RansacSettings{}.size_slack);
          allowed_counts.push_back(static_cast<std::size_t>(std::count(allowed.begin(), allowed.end(), 1)));
          FeatureRows q(scene.features.dim());  // spread over the scene, interior first
          for (int pass = 0; pass < 2; ++pass)
            for (std::uint32_t i : scene.order)
              if (q.size() < queries_n && scene.feature_valid[i] && (scene.interior[i] != 0) == (pass == 0))
                q.push_back(scene.features.row(i));
          {  // the shortlist: Batch RANSAC over every allowed object, candidates screened
            RansacStats st;
            const auto cands = ransac_candidates(scene, db, search, allowed, rs.ransac, seed, step, &st);
            t0 = Clock::now();
            // every object's exact best (the recognizer's shortlist computes only its K best)
            const std::vector<double> best = screen_objects(scene, db, cands, ShortlistSettings{});
            screen_time.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
            Shortlist sl;
            for (const Candidate& c : cands) sl.ranked.push_back(c.object);
            std::sort(sl.ranked.begin(), sl.ranked.end());
            sl.ranked.erase(std::unique(sl.ranked.begin(), sl.ranked.end()), sl.ranked.end());
            std::stable_sort(sl.ranked.begin(), sl.ranked.end(),
                             [&](std::uint32_t a, std::uint32_t b) { return best[a] < best[b]; });
            prune_time.push_back(st.time_prune_s);
            register_time.push_back(st.time_register_s);
            reached.push_back(st.objects_reached);
            const auto it = std::find(sl.ranked.begin(), sl.ranked.end(), o);
            ranks[{step, 0}].push_back(it == sl.ranked.end() ? SIZE_MAX : std::size_t(it - sl.ranked.begin()));
          }
          {  // reference: features alone (NBNN)
            const auto per = table->knn_per_object(q, 1, allowed);
            std::vector<double> score(db.size(), 0.0);
            std::vector<std::uint8_t> seen(db.size(), 0);
            for (const auto& list : per)
              for (const Neighbour& n : list) {
                score[table->ref(n.index).object] += n.sq_distance;
                seen[table->ref(n.index).object] = 1;
              }
            std::size_t r = 0;
            for (std::size_t x = 0; x < db.size(); ++x)
              if (seen[x] && x != o && (score[x] < score[o] || (score[x] == score[o] && x < o))) ++r;
            ranks[{step, 1}].push_back(allowed[o] && seen[o] ? r : SIZE_MAX);
          }
        }
      }
      std::fprintf(stderr, "\r%s done", db.info(o).name.c_str());
    }
    std::fprintf(stderr, "\n");
    auto median = [](std::vector<double> v) {
      std::sort(v.begin(), v.end());
      return v.empty() ? 0.0 : v[v.size() / 2];
    };
    {  // what the memory budget counts, per explored object
      double fine = 0, tree = 0, field = 0;
      for (std::size_t o : explored) {
        const GeometryRef g = db.geometry(o);
        fine += double((g->fine.points.capacity() + g->fine.normals.capacity()) * sizeof(Vec3));
        tree += double(g->tree.memory_bytes());
        field += double(g->field.memory_bytes());
      }
      const double n = 1e6 * double(explored.size());
      std::printf("geometry per explored object, mean: %.1f MB (fine cloud %.1f, k-d tree %.1f, distance field %.1f)\n",
                  (fine + tree + field) / n, fine / n, tree / n, field / n);
    }
    std::printf("objects allowed by the size filter: median %zu of %zu; reached by a RANSAC candidate: median %zu\n",
                allowed_counts[allowed_counts.size() / 2], db.size(), reached[reached.size() / 2]);
    std::printf("\nrecall@K: share of (object, log) whose explored object is among the K first\n");
    std::printf("%5s %-22s", "step", "ranking");
    for (std::size_t K : Ks) std::printf("  K=%-4zu", K);
    std::printf("\n");
    for (const auto& [key, r] : ranks) {
      std::printf("%5zu %-22s", key.first, key.second ? "features alone (NBNN)" : "shortlist screening");
      for (std::size_t K : Ks) {
        const auto hit = std::count_if(r.begin(), r.end(), [&](std::size_t x) { return x < K; });
        std::printf("  %5.1f%%", 100.0 * double(hit) / double(r.size()));
      }
      std::printf("\n");
    }
    std::printf("\nmedian per step: pruning %.1f ms, registration %.1f ms, screening %.1f ms\n",
                1e3 * median(prune_time), 1e3 * median(register_time), 1e3 * median(screen_time));
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_shortlist: %s\n", e.what());
    return 1;
  }
}
