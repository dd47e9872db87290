#include "engine/touch/active_touch.hpp"
#include "engine/detail.hpp"

#include "engine/database/database.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <numbers>

namespace ts {
inline namespace touch {

namespace {
using detail::kRadPerDeg;

std::vector<double> grid_1d(double lo, double hi, double spacing) {
  const int n = std::max(1, static_cast<int>(std::ceil((hi - lo) / spacing)));
  std::vector<double> v;
  for (int i = 0; i <= n; ++i) v.push_back(lo + (hi - lo) * i / n);
  return v;
}

void require(bool ok, const std::string& message, const std::string& field) {
  if (!ok) throw Error(message, {}, field);
}
}  // namespace

struct GraspPlanner::Selected {
  std::vector<const Hypothesis*> h;
  std::vector<double> w;            ///< normalized tempered weights
  std::vector<double> object_w;     ///< per hypothesis, the summed w of its object's hypotheses
  std::vector<PlanObject> obj;
  std::vector<Pose> T_obj_world;
  std::vector<Vec3> centre_world;   ///< object-frame origin in the world
};

GraspPlanner::GraspPlanner(Gripper gripper, ActiveSettings s) : gripper_(std::move(gripper)), s_(s) {
  require(s_.candidates >= 1, "the planner needs at least one candidate grasp", "active.candidates");
  require(s_.hypotheses >= 1, "the planner needs at least one hypothesis to predict under", "active.hypotheses");
  require(s_.leaders >= 1, "the planner needs at least one hypothesis to aim at", "active.leaders");
  require(s_.sigma > 0 && std::isfinite(s_.sigma), "the outcome noise must be positive", "active.sigma_m");
  require(s_.cap > 0 && std::isfinite(s_.cap), "the distance cap must be positive", "active.cap_m");
  require(s_.offset_sigma >= 0 && std::isfinite(s_.offset_sigma), "the arm offset sigma must be >= 0",
          "active.offset_sigma_m");
  require(s_.collision_weight >= 0 && std::isfinite(s_.collision_weight), "the collision weight must be >= 0",
          "active.collision_weight");
  require(s_.temperature > 0 && std::isfinite(s_.temperature), "the temperature must be positive",
          "active.temperature");
  require(s_.pose_weight >= 0 && std::isfinite(s_.pose_weight), "the pose weight must be >= 0",
          "active.pose_weight");
  require(s_.coverage_weight >= 0 && std::isfinite(s_.coverage_weight), "the coverage weight must be >= 0",
          "active.coverage_weight");
  require(s_.coverage_radius > 0 && std::isfinite(s_.coverage_radius), "the coverage radius must be positive",
          "active.coverage_radius_m");
  require(s_.clearance >= 0 && s_.clearance < 0.1, "the clearance must lie in [0, 0.1) m", "active.clearance_m");
  require(s_.aim_min_deg <= s_.aim_max_deg, "aim angles: need min <= max", "active.aim_deg");
  require(s_.hand_spacing > 0.001, "hand sample spacing must exceed 1 mm", "active.hand_spacing_m");
  require(s_.aim_radius >= 0 && std::isfinite(s_.aim_radius), "the aim radius must be >= 0", "active.aim_radius_m");
  require(s_.attempts >= 1, "the planner needs at least one aim per candidate", "active.attempts");
  pad_ = gripper_.single_pad();
  require(pad_ >= 0, "the gripper has no aimed pad (single_pad)", "single_pad");
  const PadRef& pad = gripper_.pads()[static_cast<std::size_t>(pad_)];
  require(!gripper_.spec().fingers[static_cast<std::size_t>(pad.finger)].links.empty(),
          "the aimed pad's finger has no joints", "fingers");

  // Hand samples of the open hand: palm front face and rim, each link's inner and outer faces
  // and tip, at hand_spacing.
  const double sp = s_.hand_spacing;
  const PalmSpec& palm = gripper_.spec().palm;
  for (double x : grid_1d(-palm.radius, palm.radius, sp))
    for (double y : grid_1d(-palm.radius, palm.radius, sp))
      if (x * x + y * y <= palm.radius * palm.radius) hand_.emplace_back(x, y, 0.0);
  const int rim = std::max(8, static_cast<int>(std::ceil(2 * std::numbers::pi * palm.radius / sp)));
  for (int i = 0; i < rim; ++i) {
    const double phi = 2 * std::numbers::pi * i / rim;
    hand_.emplace_back(palm.radius * std::cos(phi), palm.radius * std::sin(phi), -0.5 * palm.thickness);
  }
  const std::vector<Pose> open = gripper_.link_poses(gripper_.open_angles());
  for (int j = 0; j < gripper_.joint_count(); ++j) {
    const LinkSpec& l = gripper_.link(j);
    for (double x : {-0.5 * l.thickness, 0.5 * l.thickness})
      for (double y : grid_1d(-0.5 * l.width, 0.5 * l.width, sp))
        for (double z : grid_1d(0.0, l.length, sp)) hand_.push_back(open[j] * Vec3(x, y, z));
    for (double y : grid_1d(-0.5 * l.width, 0.5 * l.width, sp)) hand_.push_back(open[j] * Vec3(0.0, y, l.length));
  }
  const SensorSettings& sensor = gripper_.sensor();
  const double a = 0.5 * (sensor.rows - 1) * sensor.pitch_x, b = 0.5 * (sensor.cols - 1) * sensor.pitch_y;
  for (double x : {-a, 0.0, a})
    for (double y : {-b, 0.0, b}) pad_points_.emplace_back(x, y, sensor.foam_thickness);
}

std::vector<Hypothesis> with_leader(const std::vector<Hypothesis>& hypotheses, std::uint32_t object,
                                    const Pose& pose, double share, double temperature) {
  if (!(share > 0.0 && share < 1.0)) throw Error("a leader's share must lie in (0, 1)", {}, "share");
  if (!(temperature > 0.0) || !std::isfinite(temperature)) throw Error("temperature must be > 0", {}, "temperature");
  double top = -std::numeric_limits<double>::infinity();
  for (const Hypothesis& h : hypotheses) top = std::max(top, h.log_weight);
  double others = 0.0;   // the others' tempered weights, relative to the top
  for (const Hypothesis& h : hypotheses)
    if (std::isfinite(h.log_weight)) others += std::exp((h.log_weight - top) / temperature);
  Hypothesis leader;
  leader.object = object;
  leader.pose = pose;
  leader.log_weight = others > 0.0 ? top + temperature * std::log(share / (1.0 - share) * others) : 0.0;
  leader.weight = std::exp(leader.log_weight);
  std::vector<Hypothesis> out;
  out.reserve(hypotheses.size() + 1);
  out.push_back(leader);
  out.insert(out.end(), hypotheses.begin(), hypotheses.end());
  return out;
}

GraspPlanner::Selected GraspPlanner::select(const std::vector<Hypothesis>& hyps, const PlanObjects& objects) const {
  Selected sel;
  std::vector<char> taken(hyps.size(), 0);
  std::vector<std::uint32_t> seen;
  const std::size_t K = std::min(s_.hypotheses, hyps.size());
  const std::size_t per_object = std::max<std::size_t>(1, K / 2);
  for (std::size_t i = 0; i < hyps.size() && sel.h.size() < per_object; ++i) {
    if (!std::isfinite(hyps[i].log_weight)) continue;
    if (std::find(seen.begin(), seen.end(), hyps[i].object) != seen.end()) continue;
    seen.push_back(hyps[i].object);
    taken[i] = 1;
    sel.h.push_back(&hyps[i]);
  }
  for (std::size_t i = 0; i < hyps.size() && sel.h.size() < K; ++i)
    if (!taken[i] && std::isfinite(hyps[i].log_weight)) sel.h.push_back(&hyps[i]);
  if (sel.h.empty()) throw Error("no hypothesis to plan the next grasp from (no contact yet?)", {}, "hypotheses");
  // Order by (ln wt, original order) so the leaders are the heaviest.
  std::stable_sort(sel.h.begin(), sel.h.end(),
                   [](const Hypothesis* a, const Hypothesis* b) { return a->log_weight > b->log_weight; });
  double top = -std::numeric_limits<double>::infinity();
  for (const Hypothesis* h : sel.h) top = std::max(top, h->log_weight);
  double sum = 0.0;
  for (const Hypothesis* h : sel.h) {
    sel.w.push_back(std::exp((h->log_weight - top) / s_.temperature));
    sum += sel.w.back();
  }
  for (double& w : sel.w) w /= sum;
  sel.object_w.assign(sel.h.size(), 0.0);
  for (std::size_t i = 0; i < sel.h.size(); ++i)
    for (std::size_t j = 0; j < sel.h.size(); ++j)
      if (sel.h[j]->object == sel.h[i]->object) sel.object_w[i] += sel.w[j];
  for (const Hypothesis* h : sel.h) {
    PlanObject o = objects(h->object);
    if (!o.field || o.field->empty())
      throw Error("object " + std::to_string(h->object) + " has no distance field to plan with", {}, "field");
    if (!o.surface || o.surface->points.empty())
      throw Error("object " + std::to_string(h->object) + " has no surface points to aim at", {}, "surface");
    sel.obj.push_back(o);
    sel.T_obj_world.push_back(h->pose.inverse());
    sel.centre_world.push_back(h->pose.translation());
  }
  return sel;
}

bool GraspPlanner::hand_blocked(const std::vector<Vec3>& hand_world, const Vec3& d, std::size_t k,
                                const Selected& sel) const {
  // Swept open hand: each sample moves along d and ends at its aim position; only the part of
  // its path inside the object's bounding sphere can meet the object.
  const PlanObject& o = sel.obj[k];
  const Pose& T = sel.T_obj_world[k];
  const Vec3 centre = sel.centre_world[k];
  const double R = o.radius + s_.clearance;
  for (const Vec3& end : hand_world) {
    // Path end - d * t, t >= 0 (t = 0 at the aim): the interval of t within the sphere.
    const Vec3 m = end - centre;
    const double bq = m.dot(d);            // |end - d t - centre|^2 = t^2 - 2 bq t + |m|^2
    const double disc = bq * bq - (m.squaredNorm() - R * R);
    if (disc < 0) continue;
    const double root = std::sqrt(disc);
    const double t_hi = bq + root;         // farthest from the aim, where the path enters
    const double t_lo = std::max(0.0, bq - root);
    if (t_hi < 0) continue;
    // Sphere tracing from t_hi toward the aim (t decreasing).
    double t = t_hi;
    for (int it = 0; it < 48 && t >= t_lo; ++it) {
      const double g = o.field->distance(T * (end - d * t));
      if (g < s_.clearance) return true;
      t -= std::max(g - 0.5 * s_.clearance, 0.5 * s_.clearance);
    }
  }
  return false;
}

PlannedGrasp GraspPlanner::score(const GraspCommand& c, const Selected& sel, const std::vector<Vec3>& contacts) const {
  const std::size_t K = sel.h.size();
  const std::size_t P = pad_points_.size();
  const Pose T_world_pad = c.T_world_eef * gripper_.pad_pose(c.joints, pad_);
  std::vector<Vec3> pad_world(P);
  for (std::size_t i = 0; i < P; ++i) pad_world[i] = T_world_pad * pad_points_[i];
  std::vector<Vec3> hand_world(hand_.size());
  for (std::size_t i = 0; i < hand_.size(); ++i) hand_world[i] = c.T_world_eef * hand_[i];
  const Vec3 d = c.approach.normalized();

  // Outcome per hypothesis: P clamped pad distances and the blocked flag.
  const std::size_t D = P + 1;
  std::vector<double> y(K * D, 0.0);
  std::vector<double> dist(P);
  PlannedGrasp out;
  out.command = c;
  for (std::size_t k = 0; k < K; ++k) {
    const PlanObject& o = sel.obj[k];
    const Pose& T = sel.T_obj_world[k];
    o.field->distances(pad_world.data(), P, T, dist.data());
    for (std::size_t i = 0; i < P; ++i) y[k * D + i] = std::clamp(dist[i], -s_.cap, s_.cap);
    const bool blocked = hand_blocked(hand_world, d, k, sel);
    y[k * D + P] = blocked ? 3.0 * s_.cap : 0.0;
    if (blocked) out.blocked_weight += sel.w[k];
  }
  // Pairwise Bhattacharyya lower bound on I(H; Y), and its part about the object.
  const double inv = 1.0 / (8.0 * s_.sigma * s_.sigma);
  // The common offset's share of the squared pad-distance sum (0: off, the plain distance).
  const double s2 = s_.offset_sigma * s_.offset_sigma;
  const double common = s2 > 0.0 ? s2 / (s_.sigma * s_.sigma + static_cast<double>(P) * s2) : 0.0;
  double info = 0.0, object_info = 0.0;
  for (std::size_t i = 0; i < K; ++i) {
    double inner = 0.0, same = 0.0;
    for (std::size_t j = 0; j < K; ++j) {
      double d2 = 0.0, sum = 0.0;
      for (std::size_t e = 0; e < D; ++e) {
        const double diff = y[i * D + e] - y[j * D + e];
        d2 += diff * diff;
        if (e < P) sum += diff;
      }
      if (common > 0.0) d2 = std::max(0.0, d2 - common * sum * sum);
      const double term = sel.w[j] * std::exp(-d2 * inv);
      inner += term;
      if (sel.h[j]->object == sel.h[i]->object) same += term;
    }
    if (sel.w[i] == 0.0) continue;   // underflowed (a low temperature): no term, and no 0 / 0
    info -= sel.w[i] * std::log(inner);
    // same >= w_i > 0 (k_ii = 1) and object_w >= w_i: every logarithm is finite
    object_info += sel.w[i] * (std::log(same) - std::log(sel.object_w[i]) - std::log(inner));
  }
  out.information = std::max(0.0, info);
  out.object_information = std::clamp(object_info, 0.0, out.information);
  double d2 = s_.coverage_radius * s_.coverage_radius;
  for (const Vec3& p : contacts) d2 = std::min(d2, (p - c.target).squaredNorm());
  out.coverage = std::sqrt(d2) / s_.coverage_radius;
  // Written so that pose_weight 1 and coverage_weight 0 give the information term bit for bit.
  out.score = out.information - (1.0 - s_.pose_weight) * (out.information - out.object_information) -
              s_.collision_weight * out.blocked_weight;
  if (s_.coverage_weight > 0.0) out.score += s_.coverage_weight * out.coverage;
  return out;
}

std::vector<PlannedGrasp> GraspPlanner::evaluate(const std::vector<GraspCommand>& commands,
                                                 const std::vector<Hypothesis>& hypotheses,
                                                 const PlanObjects& objects,
                                                 const std::vector<Vec3>& contacts) const {
  const Selected sel = select(hypotheses, objects);
  std::vector<PlannedGrasp> out(commands.size());
  tbb::parallel_for(std::size_t{0}, commands.size(), [&](std::size_t i) {
    out[i] = score(commands[i], sel, contacts);
    out[i].candidate = i;
  });
  return out;
}

std::vector<PlannedGrasp> GraspPlanner::plan(const std::vector<Hypothesis>& hypotheses, const PlanObjects& objects,
                                             std::uint64_t seed, std::size_t n_best,
                                             const std::vector<Vec3>& contacts) const {
  const Selected sel = select(hypotheses, objects);
  const std::size_t leaders = std::min(s_.leaders, sel.h.size());
  // Per leader, the model points near the contacts (at most 256 contacts, evenly picked).
  std::vector<Vec3> near;
  const std::size_t stride = std::max<std::size_t>(1, contacts.size() / 256);
  for (std::size_t i = 0; i < contacts.size(); i += stride) near.push_back(contacts[i]);
  std::vector<std::vector<std::size_t>> eligible(leaders);
  if (s_.aim_radius > 0 && !near.empty()) {
    const double r2 = s_.aim_radius * s_.aim_radius;
    tbb::parallel_for(std::size_t{0}, leaders, [&](std::size_t k) {
      const PointCloud& S = *sel.obj[k].surface;
      for (std::size_t i = 0; i < S.points.size(); ++i) {
        const Vec3 p = sel.h[k]->pose * S.points[i];
        for (const Vec3& c : near)
          if ((p - c).squaredNorm() <= r2) {
            eligible[k].push_back(i);
            break;
          }
      }
    });
  }
  const PadRef& pad = gripper_.pads()[static_cast<std::size_t>(pad_)];
  const int aim_links = static_cast<int>(gripper_.spec().fingers[static_cast<std::size_t>(pad.finger)].links.size());
  std::vector<PlannedGrasp> out(s_.candidates);
  tbb::parallel_for(std::size_t{0}, s_.candidates, [&](std::size_t c) {
    Rng rng(seed, c);
    const std::size_t k = c % leaders;
    const PlanObject& o = sel.obj[k];
    const PointCloud& S = *o.surface;
    const Pose& T_world_obj = sel.h[k]->pose;
    GraspCommand cmd;
    std::vector<Vec3> hand_world(hand_.size());
    // As the simulator's operator: an aim the open hand cannot reach on the aimed hypothesis'
    // own model is redrawn, up to `attempts` times (the last one is kept).
    for (std::size_t attempt = 0; attempt < s_.attempts; ++attempt) {
      const std::size_t idx = eligible[k].empty() ? rng.index(S.points.size())
                                                  : eligible[k][rng.index(eligible[k].size())];
      const Vec3 p_obj = S.points[idx];
      // Outward normal: the stored one, turned away from the object's origin (centroid rule).
      Vec3 n_obj = S.has_normals() ? S.normals[idx] : Vec3(p_obj);
      if (!(n_obj.norm() > 0)) n_obj = Vec3::UnitZ();
      n_obj.normalize();
      if (n_obj.dot(p_obj) < 0) n_obj = -n_obj;
      const Vec3 p = T_world_obj * p_obj;
      const Vec3 n = T_world_obj.linear() * n_obj;
      // Pad frame: z = -n, seeded roll, the foam's centre on p.
      const Vec3 z = -n;
      const double roll = rng.uniform(0.0, 2.0 * std::numbers::pi);
      Pose T_world_pad = rolled_frame(z, roll);
      T_world_pad.translation() = p - z * gripper_.sensor().foam_thickness;
      std::vector<double> joints = gripper_.open_angles();
      for (int l = 0; l < aim_links; ++l) {
        const int j = gripper_.joint_index(pad.finger, l);
        const LinkSpec& spec = gripper_.link(j);
        joints[static_cast<std::size_t>(j)] =
            std::clamp(rng.uniform(s_.aim_min_deg, s_.aim_max_deg) * kRadPerDeg, spec.min, spec.max);
      }
      cmd.T_world_eef = T_world_pad * gripper_.pad_pose(joints, pad_).inverse();
      cmd.approach = z;
      cmd.joints = std::move(joints);
      cmd.target = p;
      for (std::size_t i = 0; i < hand_.size(); ++i) hand_world[i] = cmd.T_world_eef * hand_[i];
      if (!hand_blocked(hand_world, z, k, sel)) break;
    }
    out[c] = score(cmd, sel, contacts);
    out[c].candidate = c;
    out[c].aimed_object = sel.h[k]->object;
  });
  std::stable_sort(out.begin(), out.end(), [](const PlannedGrasp& a, const PlannedGrasp& b) {
    if (a.score != b.score) return a.score > b.score;
    return a.candidate < b.candidate;
  });
  out.resize(std::min(out.size(), n_best));
  return out;
}

PlanObjects database_plan_objects(const Database& db) {
  struct Held {
    std::mutex mutex;
    std::map<std::uint32_t, GeometryRef> geometry;
  };
  auto held = std::make_shared<Held>();
  return [&db, held](std::uint32_t object) {
    GeometryRef g;
    {
      std::lock_guard<std::mutex> lock(held->mutex);
      auto it = held->geometry.find(object);
      if (it == held->geometry.end()) it = held->geometry.emplace(object, db.geometry(object)).first;
      g = it->second;
    }
    PlanObject o;
    o.field = &g->field;
    o.surface = &db.keypoints(object).coarse;
    o.radius = 0.5 * db.info(object).extent.norm();
    return o;
  };
}

}  // namespace touch
}  // namespace ts
