// Benchmark of the recognizer (Section 4.3-4.4) on a database file with simulated tactile logs:
//
//   speed     BRICPSF (or --method) through `grasps` steps of a few logs, with 1 and with 2
//             threads: the median time of the last step (cumulative cloud after `grasps`
//             grasps) and of every step, a per-stage breakdown, and the 1 -> 2 thread speed-up.
//             An untimed pass first loads what the steps read; then `rounds` timed rounds, each
//             with 1 and 2 threads, the order alternating. Results of every round and thread
//             count must be identical (checked).
//   accuracy  every object x `seeds` logs (noise profile `noise`): the share of logs whose last
//             step names the right object with a position error below 1 cm (also symmetric
//             orientation error statistics); and class-aware: an object congruent with the right
//             one also counts, its pose carried over, when the database records classes.
//
//   build/bench/bench_recognize --db DB.h5 [--grasps 20] [--speed-logs 6] [--rounds 3] [--seeds 3]
//       [--noise underwater] [--method bricpsf] [--objects N] [--database-size N] [--skip-speed] [--skip-accuracy]
//       [--preset improved|paper] [--KEY VALUE ...] [--set KEY=VALUE ...]
//       [--accuracy-threads N] [--answers FILE]
//   Method parameters (experiments/params/parameters.cpp, `touchstone params`) as `touchstone recognize`
//   takes them: the preset's values (improved by default), then each --KEY (e.g. --ransac.triplets
//   15, or an older flag, -N 15) or --set KEY=VALUE (a key or an older name: --set N=15).
//   --method, --preset, --noise, its overrides (--arm-position-sigma, ...) and --sensors are the
//   declared experiment and simulator parameters (the noise defaults to underwater here);
//   --objects N (the first N objects of the database) is the benchmark's own selection of the
//   objects it explores; --database-size N cuts the recognizer's database to the first N objects
//   (and the explored ones to those).
//
// --answers FILE writes every step of every accuracy log, exactly (hexadecimal floats): the log, the
// step, the answer's object, ln wt and pose, the posterior, and every hypothesis's object and
// ln wt, so that two builds (or thread counts, --accuracy-threads) are compared with `cmp`.
//
// Prints the machine, thread counts, parameters and every figure (with the speed part, the peak
// resident memory).
#include "datasets/simulator.hpp"
#include "engine/database/symmetry_cache.hpp"
#include "engine/geometry/pose_error.hpp"
#include "engine/recognition/recognizer.hpp"
#include "engine/touch/fusion.hpp"
#include "experiments/allocator.hpp"
#include "experiments/params/config.hpp"
#include "experiments/params/parameters.hpp"
#include "experiments/resources.hpp"
#include "experiments/runs/grasp_pools.hpp"
#include "io/db_store.hpp"

#include <CLI/CLI.hpp>
#include <sys/resource.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <iostream>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

using namespace ts;

double cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

/// Resident memory now and at its peak so far (GB).
std::pair<double, double> resident_gb() {
  long pages = 0, resident = 0;
  if (FILE* f = std::fopen("/proc/self/statm", "r")) {
    if (std::fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = 0;
    std::fclose(f);
  }
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);   // ru_maxrss: KiB on Linux
  return {static_cast<double>(resident) * static_cast<double>(sysconf(_SC_PAGESIZE)) / 1e9,
          static_cast<double>(usage.ru_maxrss) * 1024.0 / 1e9};
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t i = std::min(v.size() - 1, static_cast<std::size_t>(q * double(v.size() - 1) + 0.5));
  return v[i];
}

struct Log {
  std::size_t object;
  TactileLog log;
};

/// The clouds of every step of a log (fusion is not part of the recognizer's timing).
struct Steps {
  std::vector<PointCloud> contacts;
  std::vector<std::vector<Vec3>> free;
  std::vector<GraspGroups> grasps;
};

Steps clouds_of(const TactileLog& log, std::size_t grasps, double s_obj_max, double res_free,
                double contact_voxel) {
  ExplorationSettings es;
  es.contact_voxel = contact_voxel;
  es.free.s_obj_max = s_obj_max;
  es.free.res_free = res_free;
  Exploration ex(log, es);
  Steps s;
  for (std::size_t k = 1; k <= grasps; ++k) {
    ex.advance_to(k);
    s.contacts.push_back(ex.contact_cloud());
    s.free.push_back(ex.free_cloud().points);
    s.grasps.push_back(ex.grasp_groups());
  }
  return s;
}

Log simulate(const io::DbReader& db, std::size_t object, std::size_t grasps,
             const datasets::SimulatorSettings& base, std::uint64_t seed) {
  datasets::SimulatorSettings ss = base;
  ss.grasps = grasps;
  ss.seed = seed;
  datasets::Simulator sim(db.load_mesh(object), db.info(object).name, Gripper(), ss);
  return {object, sim.run().log};
}

}  // namespace

int main(int argc, char** argv) {
  std::string db_path, noise, method, preset;
  std::size_t grasps = 20, speed_logs = 6, seeds = 3, objects = 0, database_size = 0, rounds = 3;
  int accuracy_threads = 0;
  std::string answers_path;
  bool skip_speed = false, skip_accuracy = false;
  std::vector<std::string> sets;
  experiments::ParameterFlags flags, run_flags;
  experiments::MethodSettings settings;
  datasets::SimulatorSettings simulation;
  CLI::App app{"bench_recognize: recognizer speed and accuracy on simulated logs"};
  app.add_option("--db", db_path, "Object database (HDF5)")->required();
  app.add_option("--grasps", grasps, "Steps (grasps) of each log")->check(CLI::Range(1, 100000));
  app.add_option("--speed-logs", speed_logs, "Logs of the speed part")->check(CLI::Range(1, 100000));
  app.add_option("--rounds", rounds,
                 "Timed rounds of the speed part, after an untimed one; each runs every log with 1 and 2 threads, "
                 "the order alternating")
      ->check(CLI::Range(1, 1000));
  app.add_option("--seeds", seeds, "Logs per object of the accuracy part")->check(CLI::Range(1, 100000));
  app.add_option("--objects", objects, "First N objects of the database (0: all)");
  app.add_option("--database-size", database_size,
                 "The recognizer's database cut to its first N objects, the logs' objects among them (0: all)");
  app.add_flag("--skip-speed", skip_speed, "Skip the speed part");
  app.add_flag("--skip-accuracy", skip_accuracy, "Skip the accuracy part");
  app.add_option("--accuracy-threads", accuracy_threads, "Worker threads of the accuracy part (0: all cores)")
      ->check(CLI::Range(0, 4096));
  app.add_option("--answers", answers_path,
                 "Write every accuracy step's answer, exactly, to this file (compare two builds with cmp)");
  app.add_option("--set", sets, "KEY=VALUE: a method parameter by its key or an older name (touchstone params)");
  // --method, --preset and the simulator's pad parameters (--noise, its overrides, --sensors).
  experiments::add_parameter_flags(app, run_flags, "Experiment and simulator parameters (touchstone params)",
                                   experiments::bench_run_parameter);
  experiments::add_parameter_flags(app, flags, "Method parameters (touchstone params)");
  try {
    app.parse(argc, argv);
    for (const std::string& kv : sets) {   // --set KEY=VALUE: the key's flag, given
      const auto eq = kv.find('=');
      const experiments::Parameter* p = eq == std::string::npos ? nullptr : experiments::find_parameter(kv.substr(0, eq));
      if (p && p->kind != experiments::Parameter::Kind::method) p = nullptr;
      if (!p) throw CLI::ValidationError("--set", "expects KEY=VALUE with a method parameter's key (got '" + kv + "')");
      flags.given[p->key] = kv.substr(eq + 1);
    }
    experiments::ExperimentConfig c;
    c.noise = "underwater";
    try {
      experiments::apply_flags(run_flags, c);
    } catch (const Error& e) {   // a value out of its declared range: name the flag
      throw CLI::ValidationError(e.field(), e.message());
    }
    noise = c.noise;
    method = c.method;
    preset = c.preset;
    simulation = experiments::simulation_settings(c);
    experiments::MethodSettings ms = experiments::MethodSettings::preset(preset);
    experiments::apply_flags(flags, ms);
    settings = ms;
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    const bool speed = !skip_speed, accuracy = !skip_accuracy;
    RecognizerSettings rs = settings.recognizer;
    const auto m = parse_method(method);
    if (!m) throw Error("unknown method", {}, method);
    rs.method = *m;

    auto reader = std::make_shared<io::DbReader>(db_path);
    Database db(reader);
    db.set_surface(needs_surface(rs, db.settings()));   // as `touchstone recognize` does
    if (database_size > 0 && database_size < db.size()) {   // as `experiment --database-size`
      rs.objects.assign(db.size(), 0);
      std::fill_n(rs.objects.begin(), database_size, std::uint8_t{1});
    }
    const std::size_t allowed = rs.objects.empty() ? db.size() : database_size;
    const std::size_t n_obj = std::min(objects > 0 ? std::min(objects, db.size()) : db.size(), allowed);
    std::printf("bench_recognize: %s\nmachine: %s; first touch of fresh memory %.2f ms/MB\ndatabase: %s (%zu objects, the recognizer's %zu), method %s, %zu grasps, noise %s\n",
                "recognizer speed and accuracy", experiments::machine_description().c_str(),
                experiments::first_touch_ms_per_mb(), db_path.c_str(),
                db.size(), allowed, method.c_str(), grasps, noise.c_str());
    std::printf("parameters (preset %s):", preset.c_str());
    {
      experiments::MethodSettings shown = settings;
      shown.recognizer = rs;
      for (const auto& [key, value] : experiments::stored_parameters(shown))
        std::printf(" %s %s,", key.c_str(), experiments::find_parameter(key)->text(value).c_str());
      std::printf("\n");
    }
    const double s_obj_max = largest_object_extent(db);

    auto t0 = std::chrono::steady_clock::now();
    std::shared_ptr<const FeatureIndex> index;
    std::shared_ptr<const FeatureTable> table;
    if (rs.ransac.feature_table) {
      table = FeatureTable::shared(db, rs.objects);
    } else {
      index = std::make_shared<FeatureIndex>(build_feature_index(db, rs.index, rs.objects));
    }
    std::printf("feature search: %s, %zu features, built in %.2f s\n",
                table ? "exact batched table" : "FeatureIndex", table ? table->features() : index->size(),
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    const auto [table_now, table_peak] = resident_gb();
    std::printf("memory with the feature search built: %.2f GB resident (peak %.2f GB), the table %.2f GB\n", table_now,
                table_peak, table ? static_cast<double>(table->memory_bytes()) / 1e9 : 0.0);

    if (speed) {
      // A few logs spread over the database; every step run with 1 and with 2 threads.
      std::vector<Log> logs;
      std::vector<Steps> steps;
      tbb::task_arena sim_arena(2);
      for (std::size_t i = 0; i < speed_logs; ++i) {
        const std::size_t obj = (i * 7 + 3) % n_obj;
        sim_arena.execute([&] {
          logs.push_back(simulate(*reader, obj, grasps, simulation, 1000 + i));
          steps.push_back(clouds_of(logs.back().log, grasps, s_obj_max, rs.evaluate.res_free, settings.contact_voxel));
        });
      }
      std::map<int, std::vector<double>> last, all, cpu_last;
      std::map<int, std::vector<StageTimes>> stages;
      std::map<int, std::vector<StepResult>> finals;
      // One pass over every log, each step timed, or none (the warm-up).
      const auto pass = [&](int threads, bool timed) {
        tbb::task_arena arena(threads);
        arena.execute([&] {
          for (std::size_t i = 0; i < logs.size(); ++i) {
            Recognizer rec(db, index, rs);
            StepResult r;
            for (std::size_t k = 0; k < grasps; ++k) {
              const double c0 = cpu_seconds();
              r = rec.step(steps[i].contacts[k], steps[i].free[k], steps[i].grasps[k]);
              if (!timed) continue;
              if (k + 1 == grasps) cpu_last[threads].push_back(cpu_seconds() - c0);
              all[threads].push_back(r.times.total_s);
            }
            if (!timed) continue;
            last[threads].push_back(r.times.total_s);
            stages[threads].push_back(r.times);
            finals[threads].push_back(r);
          }
        });
      };
      // An untimed pass first loads what the steps read (object geometry, keypoints, pair
      // tables), so that neither thread count pays the first loads; then the rounds alternate
      // which thread count goes first (1 2, 2 1, 1 2, ...), so that a drift of the machine falls
      // on both.
      pass(2, false);
      for (std::size_t round = 0; round < rounds; ++round)
        for (int threads : round % 2 == 0 ? std::array<int, 2>{1, 2} : std::array<int, 2>{2, 1}) pass(threads, true);
      const auto same_result = [](const StepResult& a, const StepResult& b) {
        if (a.hypotheses.size() != b.hypotheses.size()) return false;
        for (std::size_t j = 0; j < a.hypotheses.size(); ++j)
          if (!(a.hypotheses[j].pose.matrix() == b.hypotheses[j].pose.matrix() &&
                a.hypotheses[j].log_weight == b.hypotheses[j].log_weight))
            return false;
        return true;
      };
      bool same = true;   // every round and thread count against the first round's 1 thread
      for (std::size_t i = 0; i < finals[2].size(); ++i) {
        const StepResult& first = finals[1][i % logs.size()];
        same = same && same_result(first, finals[1][i]) && same_result(first, finals[2][i]);
      }
      for (int threads : {1, 2}) {
        std::vector<double> pre, pr, re, ic, ev;
        for (const StageTimes& t : stages[threads]) {
          pre.push_back(t.prepare_s);
          pr.push_back(t.prune_s);
          re.push_back(t.register_s);
          ic.push_back(t.icp_s);
          ev.push_back(t.evaluate_s);
        }
        std::printf("threads %d: step %zu median %.1f ms (p90 %.1f ms, cpu %.1f ms); all steps median %.1f ms; stages at step %zu "
                    "(median ms): prepare %.1f, prune %.1f, register %.1f, icp %.1f, evaluate %.1f\n",
                    threads, grasps, 1e3 * median(last[threads]), 1e3 * percentile(last[threads], 0.9),
                    1e3 * median(cpu_last[threads]),
                    1e3 * median(all[threads]), grasps, 1e3 * median(pre), 1e3 * median(pr), 1e3 * median(re),
                    1e3 * median(ic), 1e3 * median(ev));
        // The pipeline's own stages (StepResult::stages, in their order; 0 where a stage was
        // left out), their sum and what the step spent outside them.
        std::vector<std::string> names;
        std::map<std::string, std::vector<double>> by_stage;
        std::vector<double> outside;
        for (const StepResult& r : finals[threads]) {
          double inside = 0.0;
          for (const StageRun& sr : r.stages) {
            if (!by_stage.count(sr.name)) names.push_back(sr.name);
            by_stage[sr.name].push_back(sr.seconds);
            inside += sr.seconds;
          }
          outside.push_back(r.times.total_s - inside);
        }
        std::printf("threads %d: pipeline stages at step %zu (median ms):", threads, grasps);
        for (std::size_t n = 0; n < names.size(); ++n)
          std::printf("%s %s %.2f", n ? "," : "", names[n].c_str(), 1e3 * median(by_stage[names[n]]));
        std::printf("; outside the stages %.2f\n", 1e3 * median(outside));
      }
      std::printf("speed-up 1 -> 2 threads: %.2fx at step %zu, %.2fx over all steps; identical results: %s\n",
                  median(last[1]) / median(last[2]), grasps, median(all[1]) / median(all[2]), same ? "yes" : "NO");
      // What stays: the object geometry (no budget here: every object the steps reached) and
      // the keypoints (every allowed object's on a database large enough for the shape prior,
      // whose histograms read them; summed after the reading, loading any not yet in use; a
      // k-d tree only where the screening built it).
      const auto [now, peak] = resident_gb();
      double keypoints = 0.0;
      for (std::size_t o = 0; o < n_obj; ++o) {
        const ObjectKeypoints& k = db.keypoints(o);
        keypoints += static_cast<double>(k.coarse.points.capacity() * sizeof(Vec3) +
                                         k.coarse.normals.capacity() * sizeof(Vec3) +
                                         (k.tree_built() ? k.tree().memory_bytes() : 0));
      }
      std::printf("peak memory so far: %.2f GB resident (the database's geometry loaded as the steps needed it); now %.2f GB, "
                  "of which object geometry %.2f GB (its peak %.2f GB, %zu loads); the %zu objects' keypoints %.2f GB\n",
                  peak, now, static_cast<double>(db.geometry_bytes()) / 1e9,
                  static_cast<double>(db.geometry_peak_bytes()) / 1e9, db.geometry_loads(), n_obj, keypoints / 1e9);
    }

    if (accuracy) {
      SymmetryCache symmetries;
      std::size_t right = 0, right_1cm = 0, total = 0;
      // Class-aware: an answer congruent with the explored object counts as right, its pose
      // carried into the explored object's frame by the motion the database stored.
      const io::CongruenceRecord* congruence = reader->congruence();
      std::size_t right_class = 0, right_class_1cm = 0;
      std::vector<double> pos, sym_ori;
      std::vector<std::string> failures;
      double time_total = 0.0;
      // --answers: written beside, renamed when complete (an interrupted run leaves no file).
      const std::string answers_part = answers_path + ".part";
      std::FILE* answers = nullptr;
      if (!answers_path.empty() && !(answers = std::fopen(answers_part.c_str(), "w")))
        throw std::runtime_error("cannot write " + answers_part);
      const auto write_answer = [&](std::size_t obj, std::size_t seed, const StepResult& r) {
        if (!answers) return;
        std::fprintf(answers, "%s\t%zu\t%d\t%d\t%u\t%a\t%a", db.info(obj).name.c_str(), seed, r.step,
                     int(r.valid), r.best.object, r.best.log_weight, r.posterior);
        const Eigen::Matrix4d M = r.best.pose.matrix();
        for (int i = 0; i < 12; ++i) std::fprintf(answers, "\t%a", M(i % 3, i / 3));
        std::fprintf(answers, "\t%zu", r.hypotheses.size());
        for (const Hypothesis& h : r.hypotheses) std::fprintf(answers, "\t%u:%a", h.object, h.log_weight);
        std::fprintf(answers, "\n");
      };
      tbb::task_arena accuracy_arena(accuracy_threads > 0 ? accuracy_threads : tbb::task_arena::automatic);
      try {
        accuracy_arena.execute([&] {
          for (std::size_t obj = 0; obj < n_obj; ++obj) {
            for (std::size_t seed = 1; seed <= seeds; ++seed) {
              const Log log = simulate(*reader, obj, grasps, simulation, seed);
              const Steps st = clouds_of(log.log, grasps, s_obj_max, rs.evaluate.res_free, settings.contact_voxel);
              Recognizer rec(db, index, rs);
              StepResult r;
              for (std::size_t k = 0; k < grasps; ++k) {
                r = rec.step(st.contacts[k], st.free[k], st.grasps[k]);
                time_total += r.times.total_s;
                write_answer(obj, seed, r);
              }
              ++total;
              const Pose truth = log.log.truth->object_pose;
              const bool ok = r.valid && r.best.object == obj;
              std::string line = db.info(obj).name + " seed " + std::to_string(seed) + ": ";
              if (ok) {
                ++right;
                const PoseError e = pose_error(r.best.pose, truth, &symmetries.get(db, obj));
                pos.push_back(e.symmetric_position_m);
                sym_ori.push_back(e.symmetric_orientation_deg);
                if (e.position_m < 0.01 || e.symmetric_position_m < 0.01) ++right_1cm;
                else failures.push_back(line + "position error " + std::to_string(e.position_m) + " m");
              } else {
                std::string twin;
                if (r.valid && congruence && congruence->same_class(r.best.object, obj)) {
                  ++right_class;
                  twin = ", congruent: right class-aware";
                  if (const auto T = congruence->motion(obj, r.best.object)) {
                    const Eigen::Affine3d P = Eigen::Affine3d(r.best.pose.matrix()) * *T;
                    Pose carried = Pose::Identity();
                    carried.linear() = P.linear();
                    carried.translation() = P.translation();
                    const PoseError e = pose_error(carried, truth, &symmetries.get(db, obj));
                    if (e.position_m < 0.01 || e.symmetric_position_m < 0.01) ++right_class_1cm;
                    else twin += " but position error " + std::to_string(e.position_m) + " m";
                  }
                }
                failures.push_back(line + "recognized " + (r.valid ? db.info(r.best.object).name : "nothing") +
                                   " (posterior " + std::to_string(r.posterior) + twin + ")");
              }
              std::fprintf(stderr, "\r%zu/%zu logs", total, n_obj * seeds);
            }
          }
        });
      } catch (...) {   // nothing half-written
        if (answers) {
          std::fclose(answers);
          std::remove(answers_part.c_str());
        }
        throw;
      }
      std::fprintf(stderr, "\n");
      if (answers) {
        const bool ok = std::fflush(answers) == 0 && !std::ferror(answers);
        std::fclose(answers);
        if (!ok || std::rename(answers_part.c_str(), answers_path.c_str()) != 0) {
          std::remove(answers_part.c_str());
          throw std::runtime_error("cannot write " + answers_path);
        }
        std::printf("answers of %zu steps written to %s\n", total * grasps, answers_path.c_str());
      }
      std::printf("accuracy (%zu logs, %s, step %zu, %d threads): right object %.1f %%, right object and position error < 1 cm "
                  "%.1f %%; over right objects: position error median %.4f m, symmetric orientation error "
                  "median %.2f deg (p90 %.2f deg); mean step time %.1f ms\n",
                  total, noise.c_str(), grasps, accuracy_arena.max_concurrency(), 100.0 * double(right) / double(total),
                  100.0 * double(right_1cm) / double(total), median(pos), median(sym_ori),
                  percentile(sym_ori, 0.9), 1e3 * time_total / double(total * grasps));
      if (congruence)
        std::printf("class-aware (an answer congruent with the explored object counts, tolerance %g): right object "
                    "%.1f %%, and position error < 1 cm %.1f %% (%zu of %zu)\n",
                    congruence->settings.tolerance, 100.0 * double(right + right_class) / double(total),
                    100.0 * double(right_1cm + right_class_1cm) / double(total), right_1cm + right_class_1cm, total);
      else
        std::printf("class-aware: the database records no congruent classes (touchstone db classes adds them)\n");
      for (const std::string& f : failures) std::printf("  miss: %s\n", f.c_str());
    }
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_recognize: error: %s\n", e.what());
    return 1;
  }
}
