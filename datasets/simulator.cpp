#include "datasets/simulator.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>
#include <tuple>
#include <utility>

namespace ts::datasets {

namespace {
constexpr double kDeg = std::numbers::pi / 180.0;

// Rng stream tags: (seed, tag, index).
constexpr std::uint64_t kStreamPose = 0, kStreamGeometry = 1, kStreamNoise = 2, kStreamGains = 3;
constexpr std::uint64_t kStreamOffTarget = 4;   // a scene's off-target choice and aims, per grasp

Vec3 perpendicular(const Vec3& a) {
  const Vec3 helper = std::abs(a.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
  return a.cross(helper).normalized();
}

Mat3 small_rotation(const Vec3& w) {
  const double angle = w.norm();
  if (angle < 1e-15) return Mat3::Identity();
  return Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
}

// Collision samples of one link, in the link frame, grouped into segments along the link for
// culling against the mesh.
struct Segment {
  Vec3 centre = Vec3::Zero();
  double radius = 0.0;
  std::vector<int> rigid, foam;
};

struct LinkGeometry {
  std::vector<Vec3> rigid;   // inner face (incl. under the pad) and tip face
  std::vector<Vec3> foam;    // sensel tops (foam surface)
  std::vector<Vec3> shell;   // the other faces (outer, sides, joint end): lead only on approach
  std::vector<Vec3> base;    // sensel bases (pad base plane)
  Vec3 pad_normal = Vec3::Zero();
  int pad = -1;              // index into gripper.pads(), -1: no pad
  std::vector<Segment> segments;
};

std::vector<double> grid_1d(double lo, double hi, double spacing) {
  const int n = std::max(1, static_cast<int>(std::ceil((hi - lo) / spacing)));
  std::vector<double> v;
  for (int i = 0; i <= n; ++i) v.push_back(lo + (hi - lo) * i / n);
  return v;
}

LinkGeometry link_geometry(const Gripper& g, int joint, const GraspSettings& s) {
  const LinkSpec& l = g.link(joint);
  const SensorSettings& sensor = g.sensor();
  LinkGeometry out;
  const double x_in = -0.5 * l.thickness;
  for (double y : grid_1d(-0.5 * l.width, 0.5 * l.width, s.inner_spacing))
    for (double z : grid_1d(0.0, l.length, s.inner_spacing)) out.rigid.emplace_back(x_in, y, z);
  for (double x : grid_1d(-0.5 * l.thickness, 0.5 * l.thickness, s.other_spacing))
    for (double y : grid_1d(-0.5 * l.width, 0.5 * l.width, s.other_spacing)) {
      if (x == x_in) continue;  // shared edge with the inner face
      out.rigid.emplace_back(x, y, l.length);
    }
  const double x_out = 0.5 * l.thickness;
  for (double y : grid_1d(-0.5 * l.width, 0.5 * l.width, s.other_spacing))
    for (double z : grid_1d(0.0, l.length, s.other_spacing)) out.shell.emplace_back(x_out, y, z);
  for (double x : grid_1d(-0.5 * l.thickness, 0.5 * l.thickness, s.other_spacing)) {
    for (double z : grid_1d(0.0, l.length, s.other_spacing)) {
      out.shell.emplace_back(x, -0.5 * l.width, z);
      out.shell.emplace_back(x, 0.5 * l.width, z);
    }
    for (double y : grid_1d(-0.5 * l.width, 0.5 * l.width, s.other_spacing)) out.shell.emplace_back(x, y, 0.0);
  }
  for (const auto& p : g.pads())
    if (g.joint_index(p.finger, p.link) == joint) out.pad = static_cast<int>(&p - g.pads().data());
  if (out.pad >= 0) {
    const Pose& T = l.T_link_pad;
    out.pad_normal = T.linear().col(2);
    for (int j = 0; j < sensor.sensels(); ++j) {
      const Vec3 b = sensor.sensel_position(j);
      out.base.push_back(T * b);
      out.foam.push_back(T * (b + Vec3(0, 0, sensor.foam_thickness)));
    }
  }
  // Three segments along the link.
  const int nseg = 3;
  out.segments.resize(nseg);
  auto seg_of = [&](const Vec3& p) {
    return std::clamp(static_cast<int>(p.z() / l.length * nseg), 0, nseg - 1);
  };
  for (int i = 0; i < static_cast<int>(out.rigid.size()); ++i) out.segments[seg_of(out.rigid[i])].rigid.push_back(i);
  for (int i = 0; i < static_cast<int>(out.foam.size()); ++i) out.segments[seg_of(out.foam[i])].foam.push_back(i);
  for (auto& sg : out.segments) {
    Eigen::AlignedBox3d box;
    for (int i : sg.rigid) box.extend(out.rigid[i]);
    for (int i : sg.foam) box.extend(out.foam[i]);
    if (box.isEmpty()) continue;
    sg.centre = box.center();
    for (int i : sg.rigid) sg.radius = std::max(sg.radius, (out.rigid[i] - sg.centre).norm());
    for (int i : sg.foam) sg.radius = std::max(sg.radius, (out.foam[i] - sg.centre).norm());
  }
  return out;
}

struct Hit {
  double angle = 0.0;
  bool rigid = false;
  int link = 0;          // finger-local link index of the hitting sample
  double radius = 0.0;   // distance of the hit sample from the joint origin
};

/// Cumulative face areas of a mesh (area-uniform sampling); back() is its area.
std::vector<double> area_cdf_of(const Mesh& M) {
  std::vector<double> cdf;
  double total = 0.0;
  for (const auto& f : M.faces) {
    total += 0.5 * (M.vertices[f[1]] - M.vertices[f[0]]).cross(M.vertices[f[2]] - M.vertices[f[0]]).norm();
    cdf.push_back(total);
  }
  return cdf;
}

/// An area-uniform point of M's surface and its face (draws the face, then two barycentrics).
std::pair<Vec3, int> area_sample(const Mesh& M, const std::vector<double>& cdf, Rng& rng) {
  const double u = rng.uniform() * cdf.back();
  const int face = static_cast<int>(
      std::min<std::size_t>(std::upper_bound(cdf.begin(), cdf.end(), u) - cdf.begin(), M.faces.size() - 1));
  const double r1 = std::sqrt(rng.uniform()), r2 = rng.uniform();
  const auto& tri = M.faces[face];
  return {(1 - r1) * M.vertices[tri[0]] + r1 * (1 - r2) * M.vertices[tri[1]] + r1 * r2 * M.vertices[tri[2]], face};
}

/// Face f's unit normal, its winding's times `sign` (+z for a degenerate face).
Vec3 face_normal_of(const Mesh& M, int f, double sign) {
  const auto& t = M.faces[f];
  const Vec3 n = (M.vertices[t[1]] - M.vertices[t[0]]).cross(M.vertices[t[2]] - M.vertices[t[0]]);
  const double len = n.norm();
  return len > 0 ? Vec3(sign * n / len) : Vec3::UnitZ();
}
}  // namespace

NoiseSettings noise_profile(const std::string& name) {
  NoiseSettings n;
  n.name = name;
  if (name == "ideal") return n;
  if (name == "underwater" || name == "deepsea") {
    n.arm_position_sigma = 0.003;
    n.arm_rotation_sigma_deg = 1.0;
    n.signal_noise = 0.05;
    if (name == "deepsea") {
      n.force_noise = 0.5;
      n.lateral_sigma = 0.002;
    }
    return n;
  }
  throw Error("unknown noise profile '" + name + "' (ideal, underwater, deepsea)", {}, "--noise");
}

struct Simulator::Impl {
  MeshIndex mesh;
  std::string name;
  Gripper gripper;
  SimulatorSettings settings;
  Pose T_world_object = Pose::Identity();
  std::vector<int> pads;
  std::vector<float> gains_all;          // every pad x sensels
  std::vector<LinkGeometry> links;       // per joint
  std::vector<Vec3> palm_samples;        // EEF frame
  std::vector<double> area_cdf;
  double normal_sign = 1.0;
  Vec3 centre = Vec3::Zero();
  double radius = 0.0;
  std::optional<Support> support;        // the scene's support (world frame), if any
  std::optional<MeshIndex> world;        // object and support (object frame): what the hand meets
  /// A cluttered scene's neighbours (world frame), their surface-area CDFs, centres, radii and
  /// the sign that turns their faces' winding into outward normals.
  struct Neighbour {
    PlacedObject placed;
    std::vector<double> area_cdf;
    Vec3 centre = Vec3::Zero();
    double radius = 0.0, normal_sign = 1.0;
  };
  std::vector<Neighbour> neighbours;

  const MeshIndex& collide() const { return world ? *world : mesh; }

  Impl(Mesh m, std::string n, Gripper g, SimulatorSettings s)
      : mesh(std::move(m)), name(std::move(n)), gripper(std::move(g)), settings(std::move(s)) {}

  // ---- geometry helpers -------------------------------------------------------------------
  Vec3 face_normal(int f) const { return face_normal_of(mesh.mesh(), f, normal_sign); }

  void finger_poses(const Pose& T_obj_eef, int f, const std::vector<double>& q, std::vector<Pose>& out) const {
    const int first = gripper.joint_index(f, 0);
    out.resize(gripper.spec().fingers[f].links.size());
    gripper.finger_link_poses(f, q.data() + first, out.data());
    for (auto& T : out) T = T_obj_eef * T;
  }

  // First hit of the samples of links k.. of finger f while joint k turns from a to b.
  std::optional<Hit> sweep(const Pose& T_obj_eef, int f, int k, std::vector<double> q, double a, double b,
                           bool rigid_only) const {
    const double step = settings.grasp.angle_step_deg * kDeg;
    const int n = std::max(1, static_cast<int>(std::ceil(std::abs(b - a) / step)));
    const int jk = gripper.joint_index(f, k);
    const int nlinks = static_cast<int>(gripper.spec().fingers[f].links.size());
    std::vector<Pose> P0, P1;
    q[jk] = a;
    finger_poses(T_obj_eef, f, q, P0);
    for (int s = 0; s < n; ++s) {
      const double t0 = a + (b - a) * s / n, t1 = a + (b - a) * (s + 1) / n;
      q[jk] = t1;
      finger_poses(T_obj_eef, f, q, P1);
      std::optional<Hit> best;
      double best_frac = 2.0;
      const Vec3 joint_origin = P0[k].translation();
      for (int m = k; m < nlinks; ++m) {
        const LinkGeometry& L = links[gripper.joint_index(f, m)];
        const double rot = 2.0 * std::sin(0.5 * std::abs(t1 - t0));
        for (const Segment& sg : L.segments) {
          if (sg.rigid.empty() && sg.foam.empty()) continue;
          const Vec3 c0 = P0[m] * sg.centre, c1 = P1[m] * sg.centre;
          const double reach = sg.radius + (c1 - c0).norm() + rot * sg.radius + 1e-4;
          if (!collide().closest_within(c0, reach)) continue;
          auto test = [&](const Vec3& x, bool rigid) {
            const Vec3 A = P0[m] * x, B = P1[m] * x;
            const Vec3 d = B - A;
            const double len = d.norm();
            if (!(len > 0)) return;
            const auto hit = collide().raycast(A, d, len);
            if (!hit) return;
            const double frac = hit->t / len;
            if (frac < best_frac) {
              best_frac = frac;
              best = Hit{t0 + (t1 - t0) * frac, rigid, m, (hit->point - joint_origin).norm()};
            }
          };
          for (int i : sg.rigid) test(L.rigid[i], true);
          if (!rigid_only)
            for (int i : sg.foam) test(L.foam[i], false);
        }
      }
      if (best) return best;
      P0.swap(P1);
    }
    return std::nullopt;
  }

  // Foam compression of each sensel of a pad on link pose T_obj_link (object frame), sampled at
  // the sensel (plus an optional lateral offset per sensel, pad frame).
  void compressions(const Pose& T_obj_link, const LinkGeometry& L, const Vec3* lateral, double* out) const {
    const SensorSettings& s = gripper.sensor();
    const Pose T_link_pad = gripper.link(gripper.pads()[L.pad].joint).T_link_pad;
    const Vec3 nrm = T_obj_link.linear() * L.pad_normal;
    for (std::size_t j = 0; j < L.base.size(); ++j) {
      Vec3 b = L.base[j];
      if (lateral) b = T_link_pad * (s.sensel_position(static_cast<int>(j)) + lateral[j]);
      const auto hit = collide().raycast(T_obj_link * b, nrm, s.foam_thickness);
      out[j] = hit ? s.foam_thickness - hit->t : 0.0;
    }
  }

  double max_compression(const Pose& T_obj_eef, int f, int k, const std::vector<double>& q) const {
    std::vector<Pose> P;
    finger_poses(T_obj_eef, f, q, P);
    double best = 0.0;
    std::vector<double> c(gripper.sensor().sensels());
    for (int m = k; m < static_cast<int>(P.size()); ++m) {
      const LinkGeometry& L = links[gripper.joint_index(f, m)];
      if (L.pad < 0) continue;
      compressions(P[m], L, nullptr, c.data());
      for (double v : c) best = std::max(best, v);
    }
    return best;
  }

  // Close finger f from the open hand (proximal joint first). Returns touching links; sets
  // *tip when the finger's distal link touched.
  int close_finger(const Pose& T_obj_eef, int f, std::vector<double>& q, Rng& rng, bool* tip = nullptr) const {
    const GraspSettings& gs = settings.grasp;
    const int nlinks = static_cast<int>(gripper.spec().fingers[f].links.size());
    int touching = 0;
    for (int k = 0; k < nlinks; ++k) {
      const int jk = gripper.joint_index(f, k);
      const LinkSpec& l = gripper.link(jk);
      const double press = rng.uniform(gs.press_min, gs.press_max);
      const auto hit = sweep(T_obj_eef, f, k, q, l.open, l.max, false);
      if (!hit) {
        q[jk] = l.max;
        continue;
      }
      ++touching;
      if (tip && hit->link == nlinks - 1) *tip = true;
      auto back_off = [&](const Hit& h) {
        return std::max(l.open, h.angle - gs.clearance / std::max(h.radius, 1e-3));
      };
      int touched_link = hit->link;
      if (hit->rigid) {
        q[jk] = back_off(*hit);
      } else {
        // Press: the foam gives until the deepest sensel reaches `press`, unless a rigid part
        // touches first.
        const auto rigid = sweep(T_obj_eef, f, k, q, hit->angle, l.max, true);
        double hi = rigid ? back_off(*rigid) : l.max;
        double lo = std::min(hit->angle, hi);
        std::vector<double> x = q;
        x[jk] = hi;
        if (max_compression(T_obj_eef, f, k, x) >= press) {
          for (int it = 0; it < 30 && hi - lo > 1e-7; ++it) {
            x[jk] = 0.5 * (lo + hi);
            (max_compression(T_obj_eef, f, k, x) >= press ? hi : lo) = x[jk];
          }
        }
        q[jk] = hi;
      }
      // A later link touched: the joints after k cannot close any further.
      if (touched_link > k) break;
    }
    return touching;
  }
};

Simulator::Simulator(Mesh object_mesh, std::string object_name, Gripper gripper, SimulatorSettings settings) {
  if (object_mesh.faces.empty()) throw Error("object mesh has no faces", {}, object_name);
  if (settings.sensors != 1 && settings.sensors != static_cast<int>(gripper.pads().size()) &&
      settings.sensors != 6)
    throw Error("--sensors must be 1 or " + std::to_string(gripper.pads().size()), {}, "--sensors");
  const auto& gs = settings.grasp;
  if (!(gs.aim_min_deg <= gs.aim_max_deg) || gs.max_attempts < 1 || !(gs.press_min <= gs.press_max) || !(gs.angle_step_deg > 0) ||
      !(gs.inner_spacing > 0) || !(gs.other_spacing > 0) || !(gs.clearance >= 0) ||
      gs.press_max >= gripper.sensor().foam_thickness)
    throw Error("inconsistent grasp settings", {}, "grasp");
  if (!(settings.gain_min > 0) || settings.gain_min > settings.gain_max)
    throw Error("calibration gains must satisfy 0 < min <= max", {}, "gain");
  const ProbeSettings& ps = settings.probe;
  if (!(ps.spec.ball_radius > 0 && ps.spec.ball_radius < 0.1) || !(ps.spec.shaft_radius >= 0) ||
      ps.spec.shaft_radius > ps.spec.ball_radius)
    throw Error("probe: need 0 < ball radius < 0.1 m and 0 <= shaft radius <= ball radius", {}, "probe");
  if (!(ps.max_tilt_deg >= 0 && ps.max_tilt_deg < 90) || !(ps.contact_sigma >= 0) || !(ps.quantization >= 0) ||
      !std::isfinite(ps.contact_sigma) || !std::isfinite(ps.quantization) || ps.max_attempts < 1)
    throw Error("probe: need a tilt in [0, 90) degrees, a finite noise and quantization >= 0", {}, "probe");
  const FingertipSettings& ft = settings.fingertips;
  if (!(ft.quantization >= 0) || !std::isfinite(ft.quantization) || !std::isfinite(ft.normal_sigma_deg) ||
      ft.normal_sigma_deg >= 90)
    throw Error("fingertips: need a finite quantization >= 0 and a normal noise below 90 degrees", {}, "fingertips");
  validate(settings.scene);
  if (settings.scene.kind == SceneKind::cluttered &&
      settings.neighbours.size() != static_cast<std::size_t>(settings.scene.neighbours))
    throw Error("scene.neighbours: " + std::to_string(settings.scene.neighbours) + " neighbours asked for, " +
                    std::to_string(settings.neighbours.size()) +
                    " meshes given (the caller loads them from the database: datasets::neighbour_choice)",
                {}, "scene.neighbours");
  if (settings.scene.kind != SceneKind::cluttered && !settings.neighbours.empty())
    throw Error("neighbours need scene = cluttered", {}, "scene.neighbours");
  if (settings.scene.kind != SceneKind::none && settings.sensing == Sensing::probe)
    throw Error("the probe does not touch scenes yet: scene needs sensing = pads or fingertips", {}, "scene");
  const auto& n = settings.noise;
  for (double v : {n.arm_position_sigma, n.arm_rotation_sigma_deg, n.joint_sigma_deg, n.signal_noise,
                   n.force_noise, n.lateral_sigma})
    if (!(v >= 0) || !std::isfinite(v)) throw Error("noise levels must be finite and >= 0", {}, "noise");
  impl_ = std::make_unique<Impl>(std::move(object_mesh), std::move(object_name), std::move(gripper),
                                 std::move(settings));
  Impl& m = *impl_;
  const Mesh& M = m.mesh.mesh();
  m.normal_sign = mesh_signed_volume(M) < 0 ? -1.0 : 1.0;
  m.area_cdf = area_cdf_of(M);
  if (!(m.area_cdf.back() > 0)) throw Error("object mesh has zero area", {}, m.name);
  const auto box = mesh_bounds(M);
  m.centre = box.center();
  for (const auto& v : M.vertices) m.radius = std::max(m.radius, (v - m.centre).norm());

  // Object pose and calibration gains.
  Rng pose_rng(m.settings.seed, kStreamPose);
  m.T_world_object.linear() = pose_rng.rotation().toRotationMatrix();
  const double h = m.settings.placement;
  m.T_world_object.translation() =
      m.settings.world_offset + Vec3(pose_rng.uniform(-h, h), pose_rng.uniform(-h, h), pose_rng.uniform(-h, h));
  if (m.settings.scene.kind != SceneKind::none) {
    // The support, and the surface the hand meets in the object frame: the object's faces, then
    // the support's, wound as the object's (face_normal's sign makes them point up).
    SceneSettings scene = m.settings.scene;
    if (scene.kind == SceneKind::cluttered && scene.extent_m == 0) {   // the patch under the neighbours too
      double r_neighbour = 0.0;
      for (const SceneObject& o : m.settings.neighbours) {
        const Vec3 c = mesh_bounds(o.mesh).center();
        for (const Vec3& v : o.mesh.vertices) r_neighbour = std::max(r_neighbour, (v - c).norm());
      }
      scene.extent_m = cluttered_extent(m.radius, r_neighbour, scene, m.gripper.reach());
    }
    m.support.emplace(M, m.T_world_object, scene, m.gripper.reach(), m.settings.seed);
    Mesh all = M;
    const Pose T_object_world = m.T_world_object.inverse();
    // A surface's faces after the object's, wound as the object's are when `outward` says how the
    // surface's own winding points (the support's faces point up).
    auto append = [&](const Mesh& world, double outward) {
      const int base = static_cast<int>(all.vertices.size());
      for (const Vec3& v : world.vertices) all.vertices.push_back(T_object_world * v);
      for (const auto& f : world.faces)
        all.faces.push_back(m.normal_sign * outward > 0 ? Eigen::Vector3i(f + Eigen::Vector3i::Constant(base))
                                                        : Eigen::Vector3i(f[0] + base, f[2] + base, f[1] + base));
    };
    append(m.support->mesh(), 1.0);
    if (scene.kind == SceneKind::cluttered) {
      Mesh object_world = M;
      for (Vec3& v : object_world.vertices) v = m.T_world_object * v;
      for (PlacedObject& p : place_neighbours(object_world, *m.support, m.settings.neighbours, scene, m.settings.seed)) {
        Impl::Neighbour n;
        n.area_cdf = area_cdf_of(p.world);
        if (!(n.area_cdf.back() > 0)) throw Error("neighbour '" + p.name + "' has zero area", {}, "scene.neighbours");
        n.centre = mesh_bounds(p.world).center();
        for (const Vec3& v : p.world.vertices) n.radius = std::max(n.radius, (v - n.centre).norm());
        n.normal_sign = mesh_signed_volume(p.world) < 0 ? -1.0 : 1.0;
        append(p.world, n.normal_sign);
        n.placed = std::move(p);
        m.neighbours.push_back(std::move(n));
      }
    }
    m.world.emplace(std::move(all));
  }
  Rng gain_rng(m.settings.seed, kStreamGains);
  const int S = m.gripper.sensor().sensels();
  for (std::size_t i = 0; i < m.gripper.pads().size() * S; ++i)
    m.gains_all.push_back(static_cast<float>(gain_rng.uniform(m.settings.gain_min, m.settings.gain_max)));
  if (m.settings.sensors == 1) {
    m.pads = {m.gripper.single_pad()};
  } else {
    for (std::size_t p = 0; p < m.gripper.pads().size(); ++p) m.pads.push_back(static_cast<int>(p));
  }
  for (int j = 0; j < m.gripper.joint_count(); ++j) m.links.push_back(link_geometry(m.gripper, j, gs));
  const auto& palm = m.gripper.spec().palm;
  // Palm: both discs and the rim (the hand approaches from any side).
  for (double x : grid_1d(-palm.radius, palm.radius, gs.other_spacing))
    for (double y : grid_1d(-palm.radius, palm.radius, gs.other_spacing))
      if (x * x + y * y <= palm.radius * palm.radius) {
        m.palm_samples.emplace_back(x, y, 0.0);
        m.palm_samples.emplace_back(x, y, -palm.thickness);
      }
  const int rim = std::max(8, static_cast<int>(std::ceil(2 * std::numbers::pi * palm.radius / gs.other_spacing)));
  for (int i = 0; i < rim; ++i)
    for (double z : grid_1d(-palm.thickness, 0.0, gs.other_spacing)) {
      const double phi = 2 * std::numbers::pi * i / rim;
      m.palm_samples.emplace_back(palm.radius * std::cos(phi), palm.radius * std::sin(phi), z);
    }
}

Simulator::~Simulator() = default;
Simulator::Simulator(Simulator&&) noexcept = default;
Simulator& Simulator::operator=(Simulator&&) noexcept = default;

const Pose& Simulator::object_pose() const { return impl_->T_world_object; }
const MeshIndex& Simulator::mesh() const { return impl_->mesh; }
const SimulatorSettings& Simulator::settings() const { return impl_->settings; }
const std::vector<int>& Simulator::logged_pads() const { return impl_->pads; }

namespace {
// One probe touch (ProbeSettings), object frame for the geometry.
Simulator::Grasp probe_touch(const MeshIndex& mesh, const std::vector<double>& area_cdf,
                             const SimulatorSettings& settings, const Pose& T_world_object,
                             const Vec3& centre, double radius, double normal_sign, std::size_t g) {
  const ProbeSettings& ps = settings.probe;
  const auto& M = mesh.mesh();
  const double r = ps.spec.ball_radius;
  Rng rng(settings.seed, kStreamGeometry, g);
  const double cos_max = std::cos(ps.max_tilt_deg * kDeg);
  Simulator::Grasp out;
  Vec3 start = Vec3::Zero(), d = Vec3::UnitZ();
  double L = 0.0;
  int attempts = 0;
  for (bool ok = false; !ok && attempts < ps.max_attempts; ++attempts) {
    const auto [p, face] = area_sample(M, area_cdf, rng);
    const Vec3 n = face_normal_of(M, face, normal_sign);
    const double cos_a = 1.0 - rng.uniform() * (1.0 - cos_max);
    const double sin_a = std::sqrt(std::max(0.0, 1.0 - cos_a * cos_a));
    const double beta = rng.uniform(0.0, 2.0 * std::numbers::pi);
    const Vec3 e1 = perpendicular(-n), e2 = (-n).cross(e1);
    d = (cos_a * -n + sin_a * (std::cos(beta) * e1 + std::sin(beta) * e2)).normalized();
    const Vec3 aim = p - d * r;                  // the ball centre touching p straight ahead
    L = (aim - centre).norm() + radius + r + 0.01;
    start = aim - d * L;
    ok = mesh.closest(start).distance > r && !mesh.inside(start);
  }
  // Sphere tracing: the ball centre advances by its clearance until it touches (1 um) or has
  // gone past the far side of the bounding sphere.
  const double t_max = L + 2.0 * radius + 2.0 * r;
  double t = 0.0;
  bool touched = false;
  for (int it = 0; it < 10000 && t <= t_max; ++it) {
    const double gap = mesh.closest(start + t * d).distance - r;
    if (gap < 1e-6) {
      touched = true;
      break;
    }
    t += gap;
  }
  t = std::min(t, t_max);
  Pose T_obj_tool = Pose::Identity();
  const Vec3 x = perpendicular(d);
  T_obj_tool.linear().col(0) = x;
  T_obj_tool.linear().col(1) = d.cross(x);
  T_obj_tool.linear().col(2) = d;
  T_obj_tool.translation() = start + t * d;
  out.true_arm_pose = T_world_object * T_obj_tool;
  out.diagnostics.approach_travel = t;
  out.diagnostics.attempts = attempts;
  out.diagnostics.touching_links = touched ? 1 : 0;
  out.diagnostics.contact_sensels = touched ? 1 : 0;

  // What the robot records: the arm's pose error, the probe's own noise, the quantization.
  Rng noise(settings.seed, kStreamNoise, g);
  const NoiseSettings& ns = settings.noise;
  GraspRecord& rec = out.measured;
  rec.time = settings.grasp_interval * static_cast<double>(g);
  rec.arm_pose = out.true_arm_pose;
  const Vec3 dp(noise.normal(), noise.normal(), noise.normal());
  const Vec3 dr(noise.normal(), noise.normal(), noise.normal());
  const Vec3 dc(noise.normal(), noise.normal(), noise.normal());
  rec.arm_pose.translation() += ns.arm_position_sigma * dp + ps.contact_sigma * dc;
  rec.arm_pose.linear() = (out.true_arm_pose.linear() * small_rotation(ns.arm_rotation_sigma_deg * kDeg * dr)).eval();
  if (ps.quantization > 0.0)
    for (int i = 0; i < 3; ++i)
      rec.arm_pose.translation()[i] = ps.quantization * std::round(rec.arm_pose.translation()[i] / ps.quantization);
  rec.probe_travel = t;
  rec.probe_touched = touched;
  return out;
}
}  // namespace

Simulator::Grasp Simulator::grasp(std::size_t g) const { return grasp_or_aim(g, nullptr); }

GraspCommand Simulator::aim(std::size_t g) const {
  if (impl_->settings.sensing == Sensing::probe) throw Error("a probe touch has no grasp aim", {}, "sensing");
  GraspCommand c;
  grasp_or_aim(g, &c);
  return c;
}

Simulator::Grasp Simulator::grasp_or_aim(std::size_t g, GraspCommand* aim_only) const {
  const Impl& m = *impl_;
  if (m.settings.sensing == Sensing::probe)
    return probe_touch(m.mesh, m.area_cdf, m.settings, m.T_world_object, m.centre, m.radius, m.normal_sign, g);
  const GraspSettings& gs = m.settings.grasp;
  const Gripper& G = m.gripper;
  const SensorSettings& sensor = G.sensor();
  Rng rng(m.settings.seed, kStreamGeometry, g);

  // The operator's aim: the single pad's finger at nominal joint angles puts that pad's foam on
  // a random surface point p, facing it (within max_tilt of -n), rolled at random; the open hand
  // then comes in from outside along -n until it would touch the object. An aim the hand cannot
  // reach (blocked more than approach_tolerance short of it) is redrawn (another point, other
  // angles), up to max_attempts; then the aim that came closest is used.
  const auto& M = m.mesh.mesh();
  const PadRef& aim_pad = G.pads()[G.single_pad()];
  const int aim_links = static_cast<int>(G.spec().fingers[aim_pad.finger].links.size());
  const double cos_max = std::cos(gs.max_tilt_deg * kDeg);
  Pose T_obj_eef = Pose::Identity();
  std::vector<double> q = G.open_angles();
  const auto open_links = G.link_poses(q);
  double travel = 0.0, best_shortfall = 1e300;
  Pose best_eef = Pose::Identity();
  std::vector<double> best_nominal;
  Vec3 best_p = Vec3::Zero(), best_d = Vec3::UnitZ();
  int attempts = 0;
  // In a scene, a share of the grasps aim at the support beside the object (their own stream:
  // the object's aims draw as without a scene).
  Rng off_rng(m.settings.seed, kStreamOffTarget, g);
  const bool off_target = m.support && off_rng.uniform() < m.settings.scene.off_target;
  const Pose T_object_world = m.T_world_object.inverse();
  bool aim_support = off_target;
  const int limit = m.support ? 2 * gs.max_attempts : gs.max_attempts;
  for (bool accepted = false; !accepted && attempts < limit; ++attempts) {
    // In a scene, an aim the hand could reach only from under the support is no aim (below);
    // when max_attempts draws gave none it could reach at all, the rest aim at the support.
    if (attempts == gs.max_attempts) {
      if (best_shortfall < 1e300) break;
      aim_support = true;
    }
    // A random surface point (area-uniform) and its outward normal, object frame; the approach
    // starts beyond the bounding sphere of what it aims at.
    Vec3 p, n, aim_centre = m.centre;
    double aim_radius = m.radius;
    if (aim_support && !m.neighbours.empty() && off_rng.uniform() < m.settings.scene.neighbour_share) {
      const Impl::Neighbour& nb = m.neighbours[off_rng.index(m.neighbours.size())];
      const auto [x, face] = area_sample(nb.placed.world, nb.area_cdf, off_rng);
      p = T_object_world * x;
      n = T_object_world.linear() * face_normal_of(nb.placed.world, face, nb.normal_sign);
      aim_centre = T_object_world * nb.centre;
      aim_radius = nb.radius;
    } else if (aim_support) {
      const auto [x, up] = m.support->aim(off_rng);
      p = T_object_world * x;
      n = T_object_world.linear() * up;
    } else {
      int face = 0;
      std::tie(p, face) = area_sample(M, m.area_cdf, rng);
      n = m.face_normal(face);
    }
    // Pad frame: z within the cone about -n, random roll, p on the foam at a random sensel spot.
    const double cos_a = 1.0 - rng.uniform() * (1.0 - cos_max);
    const double sin_a = std::sqrt(std::max(0.0, 1.0 - cos_a * cos_a));
    const double beta = rng.uniform(0.0, 2.0 * std::numbers::pi);
    const Vec3 e1 = perpendicular(-n), e2 = (-n).cross(e1);
    const Vec3 z = (cos_a * -n + sin_a * (std::cos(beta) * e1 + std::sin(beta) * e2)).normalized();
    const double roll = rng.uniform(0.0, 2.0 * std::numbers::pi);
    Pose T_obj_pad = rolled_frame(z, roll);
    const double ox = rng.uniform(-0.5, 0.5) * (sensor.rows - 1) * sensor.pitch_x;
    const double oy = rng.uniform(-0.5, 0.5) * (sensor.cols - 1) * sensor.pitch_y;
    T_obj_pad.translation() = p - T_obj_pad.linear() * Vec3(ox, oy, sensor.foam_thickness);
    std::vector<double> nominal = G.open_angles();
    for (int k = 0; k < aim_links; ++k)
      nominal[G.joint_index(aim_pad.finger, k)] = rng.uniform(gs.aim_min_deg, gs.aim_max_deg) * kDeg;
    const Pose target = T_obj_pad * G.pad_pose(nominal, G.single_pad()).inverse();
    // Come in along -n from outside the object's bounding sphere; stop where the open hand
    // would touch (ray casts of the palm, link and foam samples).
    const Vec3 d = -n;
    const double L = (target.translation() - aim_centre).norm() + aim_radius + G.reach() + 0.01;
    T_obj_eef = target;
    T_obj_eef.translation() -= d * L;
    travel = L;
    if (m.support && m.support->above(m.T_world_object * T_obj_eef.translation()) < G.reach()) continue;
    auto cast = [&](const Vec3& x_eef) {
      const auto hit = m.collide().raycast(T_obj_eef * x_eef, d, travel + gs.clearance);
      if (hit) travel = std::min(travel, hit->t - gs.clearance);
    };
    for (const Vec3& s_eef : m.palm_samples) cast(s_eef);
    for (int j = 0; j < G.joint_count(); ++j) {
      for (const Vec3& s_link : m.links[j].rigid) cast(open_links[j] * s_link);
      for (const Vec3& s_link : m.links[j].foam) cast(open_links[j] * s_link);
      for (const Vec3& s_link : m.links[j].shell) cast(open_links[j] * s_link);
    }
    travel = std::max(0.0, travel);
    accepted = travel >= L - gs.approach_tolerance;
    T_obj_eef.translation() += d * travel;
    if (L - travel < best_shortfall) {
      best_shortfall = L - travel;
      best_eef = T_obj_eef;
      best_nominal = nominal;
      best_p = p;
      best_d = d;
    }
  }
  T_obj_eef = best_eef;
  if (aim_only) {
    aim_only->T_world_eef = m.T_world_object * T_obj_eef;
    aim_only->approach = m.T_world_object.linear() * best_d;
    aim_only->joints = best_nominal;
    aim_only->target = m.T_world_object * best_p;
    return {};
  }
  return finish(T_obj_eef, travel, attempts, g, rng);
}

Simulator::Grasp Simulator::finish(const Pose& T_obj_eef, double travel, int attempts, std::size_t g, Rng& rng) const {
  const Impl& m = *impl_;
  const Gripper& G = m.gripper;
  const SensorSettings& sensor = G.sensor();
  std::vector<double> q = G.open_angles();
  // 4. Close every finger.
  Grasp out;
  out.diagnostics.approach_travel = travel;
  out.diagnostics.attempts = attempts;
  std::vector<char> tip(static_cast<std::size_t>(G.finger_count()), 0);
  for (int f = 0; f < G.finger_count(); ++f) {
    bool t = false;
    out.diagnostics.touching_links += m.close_finger(T_obj_eef, f, q, rng, &t);
    tip[static_cast<std::size_t>(f)] = t;
  }

  // 5. What the robot records.
  Rng noise(m.settings.seed, kStreamNoise, g);
  const NoiseSettings& ns = m.settings.noise;
  out.true_arm_pose = m.T_world_object * T_obj_eef;
  out.true_joints = q;
  GraspRecord& rec = out.measured;
  rec.time = m.settings.grasp_interval * static_cast<double>(g);
  rec.arm_pose = out.true_arm_pose;
  {
    const Vec3 dp(noise.normal(), noise.normal(), noise.normal());
    const Vec3 dr(noise.normal(), noise.normal(), noise.normal());
    rec.arm_pose.translation() += ns.arm_position_sigma * dp;
    rec.arm_pose.linear() = (out.true_arm_pose.linear() * small_rotation(ns.arm_rotation_sigma_deg * kDeg * dr)).eval();
  }
  rec.joints = q;
  for (double& v : rec.joints) v += ns.joint_sigma_deg * kDeg * noise.normal();
  if (m.settings.sensing == Sensing::fingertips) {
    record_fingertips(T_obj_eef, q, tip, noise, out);
    return out;
  }

  const int S = sensor.sensels();
  const double fold_detect = ns.fold_detect >= 0 ? ns.fold_detect : 2.0 * ns.signal_noise;
  std::vector<Pose> links = G.link_poses(q);
  std::vector<double> comp(S);
  std::vector<Vec3> lateral(S, Vec3::Zero());
  for (std::size_t slot = 0; slot < m.pads.size(); ++slot) {
    const int pad = m.pads[slot];
    const LinkGeometry& Lg = m.links[G.pads()[pad].joint];
    for (auto& d : lateral) d = Vec3(ns.lateral_sigma * noise.normal(), ns.lateral_sigma * noise.normal(), 0.0);
    m.compressions(T_obj_eef * links[G.pads()[pad].joint], Lg, ns.lateral_sigma > 0 ? lateral.data() : nullptr,
                   comp.data());
    for (int j = 0; j < S; ++j) {
      const double gain = m.gains_all[static_cast<std::size_t>(pad) * S + j];
      const double c = comp[j];
      double e = sensel_signal(sensor, gain, c);
      const double n_force = noise.normal(), n_signal = noise.normal();
      if (c > 0) e *= 1.0 + ns.force_noise * n_force;
      e *= 1.0 + ns.signal_noise * n_signal;
      e = std::clamp(e, 0.0, sensor.signal_full_scale);
      rec.tactile.push_back(static_cast<float>(e));
      const bool beyond = c > sensor.peak_compression * sensor.foam_thickness &&
                          1.0 - sensor_response(sensor, c / sensor.foam_thickness) >= fold_detect;
      rec.past_peak.push_back(static_cast<std::uint8_t>(beyond ? FoldHint::past_peak : FoldHint::rising));
      auto& d = out.diagnostics;
      d.contact_sensels += sensor_response(sensor, c / sensor.foam_thickness) > sensor.threshold;
      d.past_peak_sensels += c > sensor.peak_compression * sensor.foam_thickness;
      d.max_compression = std::max(d.max_compression, c);
    }
  }
  return out;
}

void Simulator::record_fingertips(const Pose& T_obj_eef, const std::vector<double>& q, const std::vector<char>& tip,
                                  Rng& noise, Grasp& out) const {
  const Impl& m = *impl_;
  const Gripper& G = m.gripper;
  const FingertipSettings& fs = m.settings.fingertips;
  GraspRecord& rec = out.measured;
  const std::vector<Pose> true_links = G.link_poses(q);
  const std::vector<Pose> measured_links = G.link_poses(rec.joints);
  const auto F = static_cast<std::size_t>(G.finger_count());
  rec.fingertip_touched.assign(F, 0);
  rec.fingertip_points.assign(F, Vec3::Zero());
  if (fs.normal_sigma_deg >= 0) rec.fingertip_normals.assign(F, Vec3::UnitZ());
  for (std::size_t f = 0; f < F; ++f) {
    const int fi = static_cast<int>(f);
    const int j = G.joint_index(fi, static_cast<int>(G.spec().fingers[f].links.size()) - 1);
    const Vec3 dn(noise.normal(), noise.normal(), noise.normal());   // drawn for every finger
    if (!tip[f]) continue;
    // The point of contact: the surface point nearest the fingertip's inner face, tip face and
    // foam at the final joint angles.
    const Pose T_obj_link = T_obj_eef * true_links[static_cast<std::size_t>(j)];
    const LinkGeometry& L = m.links[static_cast<std::size_t>(j)];
    ClosestPoint best = m.collide().closest(T_obj_link * L.rigid.front());   // a link always has rigid samples
    for (const auto* samples : {&L.rigid, &L.foam})
      for (const Vec3& x : *samples) {
        const ClosestPoint c = m.collide().closest(T_obj_link * x);
        if (c.distance < best.distance) best = c;
      }
    // As the robot reports it: the point fixed on its fingertip, placed by the measured arm pose
    // and joint readings, then rounded.
    const Vec3 on_link = T_obj_link.inverse() * best.point;
    const Pose T_world_link_measured = rec.arm_pose * measured_links[static_cast<std::size_t>(j)];
    Vec3 p = T_world_link_measured * on_link;
    if (fs.quantization > 0.0)
      for (int i = 0; i < 3; ++i) p[i] = fs.quantization * std::round(p[i] / fs.quantization);
    rec.fingertip_touched[f] = 1;
    rec.fingertip_points[f] = p;
    ++out.diagnostics.contact_sensels;
    if (fs.normal_sigma_deg >= 0) {
      const Vec3 n_link = T_obj_link.linear().transpose() * (m.normal_sign * best.normal);
      rec.fingertip_normals[f] =
          (small_rotation(fs.normal_sigma_deg * kDeg * dn) * (T_world_link_measured.linear() * n_link)).normalized();
    }
  }
}

SimulationResult Simulator::run() const {
  const Impl& m = *impl_;
  const std::size_t G = m.settings.grasps;
  std::vector<Grasp> slots(G);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, G, 1), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t g = r.begin(); g != r.end(); ++g) slots[g] = grasp(g);
  });
  SimulationResult out;
  TactileLog& log = out.log;
  log.object = m.name;
  log.noise = m.settings.noise.name;
  log.seed = m.settings.seed;
  log.gripper = m.gripper;
  const bool probe = m.settings.sensing == Sensing::probe;
  log.sensing = m.settings.sensing;
  log.probe = m.settings.probe.spec;
  log.fingertip_normals = m.settings.sensing == Sensing::fingertips && m.settings.fingertips.normal_sigma_deg >= 0;
  if (m.settings.sensing == Sensing::pads) {
    log.pads = m.pads;
    const std::size_t S = static_cast<std::size_t>(m.gripper.sensor().sensels());
    for (int pad : m.pads)
      log.gains.insert(log.gains.end(), m.gains_all.begin() + pad * S, m.gains_all.begin() + (pad + 1) * S);
  }
  log.truth = LogGroundTruth{};
  log.truth->object_pose = m.T_world_object;
  if (m.support) {
    log.truth->scene = to_string(m.settings.scene.kind);
    log.truth->support = m.support->mesh();
    for (const Impl::Neighbour& n : m.neighbours)
      log.truth->neighbours.push_back({n.placed.name, n.placed.T_world_object, n.placed.world});
  }
  for (auto& s : slots) {
    out.grasps_with_contact += s.diagnostics.contact_sensels > 0;
    log.truth->arm_poses.push_back(s.true_arm_pose);
    if (!probe) log.truth->joints.push_back(s.true_joints);
    out.diagnostics.push_back(s.diagnostics);
    log.grasps.push_back(std::move(s.measured));
  }
  return out;
}

}  // namespace ts::datasets
