#include "experiments/runs/grasp_pools.hpp"

#include "engine/touch/gripper.hpp"
#include "experiments/runs/driver.hpp"
#include "io/log_store.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <sstream>

namespace ts::experiments {

namespace {
constexpr std::uint64_t kPoolStream = 0x706f6f6cULL;  // "pool"
constexpr std::uint64_t kRunPoolStream = 0x72706f6cULL;  // "rpol": a run's own pool (independent)
}  // namespace

datasets::SimulatorSettings simulation_settings(const ExperimentConfig& c) {
  datasets::SimulatorSettings s;
  s.sensors = c.sensors;
  s.noise = datasets::noise_profile(c.noise);
  auto take = [](const auto& value, auto& field) {   // unset: the default stays
    if (value) field = *value;
  };
  const NoiseOverrides& n = c.noise_params;
  take(n.arm_position_sigma_m, s.noise.arm_position_sigma);
  take(n.arm_rotation_sigma_deg, s.noise.arm_rotation_sigma_deg);
  if (n.arm_scale) {
    s.noise.arm_position_sigma *= *n.arm_scale;
    s.noise.arm_rotation_sigma_deg *= *n.arm_scale;
  }
  take(n.sensel_noise, s.noise.signal_noise);
  take(n.force_noise, s.noise.force_noise);
  take(n.contact_sigma_m, s.noise.lateral_sigma);
  take(n.joint_sigma_deg, s.noise.joint_sigma_deg);
  s.sensing = parse_sensing(c.sensing, {}, "sensing");
  if (s.sensing == Sensing::probe && n.contact_sigma_m) {   // the probe's own contact noise
    s.probe.contact_sigma = *n.contact_sigma_m;
    s.noise.lateral_sigma = 0.0;
  }
  const ProbeOverrides& p = c.probe_params;
  take(p.ball_radius_m, s.probe.spec.ball_radius);
  s.probe.spec.shaft_radius = std::min(s.probe.spec.shaft_radius, s.probe.spec.ball_radius);
  take(p.tilt_deg, s.probe.max_tilt_deg);
  take(p.quantization_m, s.probe.quantization);
  const FingertipOverrides& t = c.fingertip_params;
  take(t.quantization_m, s.fingertips.quantization);
  take(t.normals_deg, s.fingertips.normal_sigma_deg);
  check_scene_keys(c);
  s.scene.kind = datasets::parse_scene_kind(c.scene, {}, "scene");
  const SceneOverrides& sc = c.scene_params;
  take(sc.slope_deg, s.scene.slope_deg);
  take(sc.relief_m, s.scene.relief_m);
  take(sc.relief_wavelength_m, s.scene.relief_wavelength_m);
  take(sc.gap_m, s.scene.gap_m);
  take(sc.off_target, s.scene.off_target);
  take(sc.off_target_radius_m, s.scene.off_target_radius_m);
  take(sc.extent_m, s.scene.extent_m);
  take(sc.pipe_radius_m, s.scene.pipe_radius_m);
  take(sc.neighbours, s.scene.neighbours);
  take(sc.neighbour_distance_m, s.scene.neighbour_distance_m);
  take(sc.neighbour_share, s.scene.neighbour_share);
  s.grasps = static_cast<std::size_t>(c.pool);
  return s;
}

std::string pool_key(const datasets::SimulatorSettings& s) {
  std::ostringstream k;
  k.precision(17);
  k << s.noise.name << '|' << s.noise.arm_position_sigma << '|' << s.noise.arm_rotation_sigma_deg
    << '|' << s.noise.joint_sigma_deg << '|' << s.noise.signal_noise << '|' << s.noise.force_noise
    << '|' << s.noise.lateral_sigma << '|' << s.noise.fold_detect << '|' << s.sensors << '|'
    << s.grasps << '|' << to_string(s.sensing) << '|' << s.probe.contact_sigma << '|' << s.probe.spec.ball_radius
    << '|' << s.probe.spec.shaft_radius << '|' << s.probe.max_tilt_deg << '|' << s.probe.quantization;
  if (s.sensing == Sensing::fingertips)   // (pads and probe keys as before: their cached pools stay valid)
    k << '|' << s.fingertips.quantization << '|' << s.fingertips.normal_sigma_deg;
  if (s.scene.kind != datasets::SceneKind::none) {   // (scene-free keys as before)
    const datasets::SceneSettings& sc = s.scene;
    k << "|scene " << to_string(sc.kind) << '|' << sc.slope_deg << '|' << sc.relief_m << '|'
      << sc.relief_wavelength_m << '|' << sc.gap_m << '|' << sc.off_target << '|' << sc.off_target_radius_m << '|'
      << sc.extent_m;
    if (sc.kind == datasets::SceneKind::pipe) k << '|' << sc.pipe_radius_m;   // (other scenes' keys as before)
    if (sc.kind == datasets::SceneKind::cluttered)
      k << '|' << sc.neighbours << '|' << sc.neighbour_distance_m << '|' << sc.neighbour_share;
  }
  return k.str();
}

std::uint64_t pool_seed(std::uint64_t seed, const std::string& object, std::optional<int> run) {
  if (!run) return Rng(seed, kPoolStream, name_hash(object)).next();
  return Rng(seed, kRunPoolStream, name_hash(object), static_cast<std::uint64_t>(*run)).next();
}

TactileLog log_from_pool(const TactileLog& pool, const std::vector<std::int32_t>& grasps) {
  TactileLog log = io::log_of(io::header_of(pool));   // its header: a probe pool stays a probe log
  LogGroundTruth truth;
  truth.object_pose = pool.truth->object_pose;
  truth.scene = pool.truth->scene;
  truth.support = pool.truth->support;
  truth.neighbours = pool.truth->neighbours;
  for (std::int32_t g : grasps) {
    const auto gi = static_cast<std::size_t>(g);
    log.grasps.push_back(pool.grasps.at(gi));
    if (gi < pool.truth->arm_poses.size()) truth.arm_poses.push_back(pool.truth->arm_poses[gi]);
    if (gi < pool.truth->joints.size()) truth.joints.push_back(pool.truth->joints[gi]);
  }
  log.truth = std::move(truth);
  return log;
}

TactileLog simulate_run_pool(const Mesh& mesh, const std::string& name, datasets::SimulatorSettings s,
                             std::uint64_t seed, const std::vector<std::int32_t>& grasps) {
  s.seed = seed;
  s.grasps = 0;  // run() below gives the log's header (pose, gains) without grasps
  datasets::Simulator sim(mesh, name, Gripper(), s);
  TactileLog log = sim.run().log;
  if (!log.truth) throw Error("the simulator gave no ground truth", {}, name);
  std::vector<datasets::Simulator::Grasp> drawn(grasps.size());
  tbb::parallel_for(std::size_t{0}, grasps.size(),
                    [&](std::size_t i) { drawn[i] = sim.grasp(static_cast<std::size_t>(grasps[i])); });
  for (auto& g : drawn) {
    log.grasps.push_back(std::move(g.measured));
    log.truth->arm_poses.push_back(g.true_arm_pose);
    log.truth->joints.push_back(std::move(g.true_joints));
  }
  return log;
}

}  // namespace ts::experiments
