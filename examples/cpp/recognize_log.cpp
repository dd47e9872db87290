// Recognize a tactile log against an object database, step by step, as `touchstone recognize
// --log` does: the same settings, fusion and seed give the same answers.
//   recognize_log DATABASE.h5 LOG.h5 [SEED]
// Prints one line a step (the object, its posterior, the pose's position) and, when the log
// carries its ground truth, the last step's errors.
#include "engine/recognition/recognizer.hpp"
#include "engine/touch/fusion.hpp"
#include "experiments/runs/engine_database.hpp"
#include "experiments/runs/log_steps.hpp"
#include "io/log_store.hpp"

#include <cstdio>
#include <cstdlib>
#include <string>

int main(int argc, char** argv) {
  if (argc < 3 || argc > 4) {
    std::fprintf(stderr, "usage: recognize_log DATABASE.h5 LOG.h5 [SEED]\n");
    return 2;
  }
  try {
    // The database file: objects, features and fields, loaded as the steps need them.
    const ts::experiments::EngineDatabase file = ts::experiments::open_database(argv[1]);
    const ts::Database db(file.source);
    const ts::TactileLog log = ts::io::read_log(argv[2]);

    // Touchstone's preset (the paper's method with its extensions), BRICPSF, one seed.
    ts::RecognizerSettings settings = ts::RecognizerSettings::improved();
    if (argc == 4) settings.seed = std::stoull(argv[3]);
    // What the log's sensing needs (a probe's path is free by its ball radius only).
    const ts::RecognizerSettings rs = ts::experiments::log_settings(settings, log, false);
    ts::Recognizer recognizer(db, rs);
    // Contacts fused grasp by grasp (a 2 mm voxel filter), free space swept by the hand (Eq. 2-3).
    ts::Exploration exploration(log, ts::experiments::log_exploration(db, settings, 0.002));

    ts::StepResult r;
    for (std::size_t k = 1; k <= log.grasps.size(); ++k) {
      const ts::experiments::StepInput in = ts::experiments::step_input(exploration, k, rs.method);
      r = recognizer.step(in.contacts, in.free, in.grasps);
      const ts::Vec3 t = r.best.pose.translation();
      // The raw posterior: the answer's weights summed by object, normalized (not a probability:
      // docs/recognition.md, Confidence).
      std::printf("step %2zu  %-24s posterior %.3f  at (%+.4f, %+.4f, %+.4f) m\n", k,
                  r.valid ? db.info(r.best.object).name.c_str() : "(none)", r.posterior, t.x(), t.y(), t.z());
    }
    if (log.truth && r.valid) {
      const ts::Pose& truth = log.truth->object_pose;
      const double position_mm = 1000.0 * (r.best.pose.translation() - truth.translation()).norm();
      std::printf("truth %s: answer %s, position off by %.1f mm\n", log.object.c_str(),
                  db.info(r.best.object).name == log.object ? "right" : "wrong", position_mm);
    }
  } catch (const ts::Error& e) {   // bad input: the file and the field
    std::fprintf(stderr, "recognize_log: %s\n", e.what());
    return 1;
  }
  return 0;
}
