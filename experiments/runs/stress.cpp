#include "experiments/runs/stress.hpp"

#include "datasets/shapes.hpp"
#include "engine/database/database.hpp"
#include "engine/geometry/mesh.hpp"
#include "engine/geometry/pose_error.hpp"
#include "engine/database/symmetry_cache.hpp"
#include "engine/recognition/icp.hpp"
#include "engine/recognition/recognizer.hpp"
#include "engine/recognition/scene.hpp"
#include "io/result_store.hpp"

#include <CLI/CLI.hpp>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <mutex>
#include <numbers>
#include <set>
#include <sstream>

namespace ts::experiments {

namespace {

using json = nlohmann::ordered_json;
constexpr double kReference = 0.15;  ///< m, the size the unscaled parameters are made for
constexpr double kPi = std::numbers::pi;
using datasets::slanted_prism;

// ---------------------------------------------------------------------------------------------
// Objects

/// Scale each axis so that the bounding box becomes `size`.
Mesh fit_box(Mesh m, const Vec3& size) {
  Eigen::AlignedBox3d box;
  for (const Vec3& v : m.vertices) box.extend(v);
  const Vec3 s = size.cwiseQuotient(box.sizes());
  for (Vec3& v : m.vertices) v = v.cwiseProduct(s);
  return m;
}

/// Scale uniformly so that the largest bounding-box side becomes `size`.
Mesh fit_largest(Mesh m, double size) {
  Eigen::AlignedBox3d box;
  for (const Vec3& v : m.vertices) box.extend(v);
  const double s = size / box.sizes().maxCoeff();
  for (Vec3& v : m.vertices) v *= s;
  return m;
}

/// The five asymmetric shapes (no rotation maps one onto itself or onto another).
std::vector<std::pair<std::string, Mesh>> shapes(double size) {
  std::vector<std::pair<std::string, Mesh>> out;
  out.emplace_back("wedge", fit_largest(slanted_prism({1.0, 0.55, 0.8}, 0.8, 0.45, 0.2), size));
  out.emplace_back("nut", fit_largest(slanted_prism({1.0, 0.7, 1.0, 0.6, 0.9}, 0.6, 0.3, -0.2), size));
  out.emplace_back("bar", fit_largest(slanted_prism({0.5, 0.35, 0.5, 0.42, 0.3, 0.5}, 3.0, 0.6, 0.3), size));
  out.emplace_back("block", fit_largest(slanted_prism({1.0, 0.6, 1.2, 0.8}, 0.9, 0.35, -0.25), size));
  out.emplace_back("plate", fit_largest(slanted_prism({1.0, 0.7, 0.95, 1.0, 0.6, 0.9, 0.8}, 0.3,
                                                      0.12, 0.2), size));
  return out;
}

DatabaseSettings database_settings(double f) {
  DatabaseSettings s;
  s.scale = ObjectScale::keep;
  s.max_extent *= f;
  s.scan.fine_spacing *= f;
  s.scan.coarse_voxel *= f;
  s.scan.coverage_radius *= f;
  s.fpfh.normal_radius *= f;
  s.fpfh.feature_radius *= f;
  s.field.fine_voxel *= f;
  s.field.coarse_voxel *= f;
  s.field.coarse_margin *= f;
  return s;
}

struct StressDatabase {
  std::vector<std::string> names;
  std::vector<Mesh> meshes;               ///< object frame
  std::vector<double> sizes;              ///< largest bounding-box side
  std::unique_ptr<Database> db;
};

/// Databases by (scale, rod), built once per process.
const StressDatabase& stress_database(double f, double rod_length, double rod_section,
                                      std::uint64_t seed) {
  static std::mutex mutex;
  static std::map<std::string, std::unique_ptr<StressDatabase>> cache;
  char key[160];
  std::snprintf(key, sizeof key, "%.17g/%.17g/%.17g/%llu", f, rod_length, rod_section,
                static_cast<unsigned long long>(seed));
  std::lock_guard<std::mutex> lock(mutex);
  auto& slot = cache[key];
  if (slot) return *slot;
  auto sd = std::make_unique<StressDatabase>();
  auto list = shapes(kReference * f);
  if (rod_length > 0.0)
    list.emplace_back("rod", fit_box(slanted_prism({1.0, 0.75, 0.9, 0.8}, 1.0, 0.3, 0.1),
                                     Vec3(rod_section, rod_section * 0.8, rod_length)));
  const DatabaseSettings settings = database_settings(f);
  std::vector<BuiltObject> built;
  for (std::size_t i = 0; i < list.size(); ++i) {
    ObjectInfo info;
    info.name = list[i].first;
    info.source = "stress";
    built.push_back(build_object(list[i].second, info, settings, Rng(seed, 0x5d, i).next()));
    Eigen::AlignedBox3d box;
    for (const Vec3& v : list[i].second.vertices) box.extend(v);
    sd->names.push_back(list[i].first);
    sd->sizes.push_back(box.sizes().maxCoeff());
    sd->meshes.push_back(std::move(list[i].second));
  }
  sd->db = std::make_unique<Database>(std::make_shared<MemorySource>(std::move(built), settings));
  slot = std::move(sd);
  return *slot;
}

// ---------------------------------------------------------------------------------------------
// Contacts

struct Touch {
  PointCloud contacts;                    ///< cumulative, world frame
  std::vector<Vec3> free;                 ///< cumulative, world frame
  GraspGroups grasps;
};

/// Faces of the largest planar region (faces sharing a normal and a plane), with their areas.
std::vector<int> largest_flat_region(const Mesh& m) {
  std::vector<std::vector<int>> groups;
  std::vector<Vec3> normals;
  std::vector<double> offsets, areas;
  for (int k = 0; k < static_cast<int>(m.faces.size()); ++k) {
    const auto& f = m.faces[k];
    const Vec3 &a = m.vertices[f[0]], &b = m.vertices[f[1]], &c = m.vertices[f[2]];
    const Vec3 cr = (b - a).cross(c - a);
    if (cr.norm() <= 0.0) continue;
    const Vec3 n = cr.normalized();
    std::size_t g = 0;
    for (; g < groups.size(); ++g)
      if (normals[g].dot(n) > 1.0 - 1e-9 && std::abs(normals[g].dot(a) - offsets[g]) < 1e-9 * (1 + a.norm()))
        break;
    if (g == groups.size()) {
      groups.emplace_back();
      normals.push_back(n);
      offsets.push_back(n.dot(a));
      areas.push_back(0.0);
    }
    groups[g].push_back(k);
    areas[g] += 0.5 * cr.norm();
  }
  const std::size_t best = static_cast<std::size_t>(std::max_element(areas.begin(), areas.end()) - areas.begin());
  return groups[best];
}

/// An area-uniform point of the given faces, with its face normal.
std::pair<Vec3, Vec3> surface_point(const Mesh& m, const std::vector<int>& faces, Rng& rng) {
  std::vector<double> cum;
  double total = 0.0;
  for (int k : faces) {
    const auto& f = m.faces[k];
    total += 0.5 * (m.vertices[f[1]] - m.vertices[f[0]]).cross(m.vertices[f[2]] - m.vertices[f[0]]).norm();
    cum.push_back(total);
  }
  const double u = rng.uniform() * total;
  const std::size_t i = std::min<std::size_t>(std::lower_bound(cum.begin(), cum.end(), u) - cum.begin(), faces.size() - 1);
  const auto& f = m.faces[faces[i]];
  const Vec3 &a = m.vertices[f[0]], &b = m.vertices[f[1]], &c = m.vertices[f[2]];
  double r1 = rng.uniform(), r2 = rng.uniform();
  if (r1 + r2 > 1.0) {
    r1 = 1.0 - r1;
    r2 = 1.0 - r2;
  }
  return {a + r1 * (b - a) + r2 * (c - a), (b - a).cross(c - a).normalized()};
}

Vec3 gaussian3(Rng& rng, double sigma) { return sigma * Vec3(rng.normal(), rng.normal(), rng.normal()); }

/// One grasp's patch on object `mesh` at T_world_object, appended to `touch`.
void add_grasp(const StressCase& c, double f, const MeshIndex& mesh, const std::vector<int>& faces,
               const Pose& T, Rng& rng, Touch& touch) {
  const double radius = 0.012 * f;
  const double noise_f = c.scale_noise ? f : 1.0;
  // Named, not a structured binding: the lambda below captures it (clang 14, the fuzz build).
  const std::pair<Vec3, Vec3> at = surface_point(mesh.mesh(), faces, rng);
  const Vec3 &centre = at.first, &n = at.second;
  const Vec3 t1 = n.unitOrthogonal(), t2 = n.cross(t1);
  const double phi = rng.uniform(0.0, 2 * kPi);
  const Vec3 dir = std::cos(phi) * t1 + std::sin(phi) * t2, side = n.cross(dir);
  // The arm's error of this grasp: a rotation about the patch centre and a translation.
  const Vec3 w = gaussian3(rng, c.arm_rotation_deg * kPi / 180.0);
  const Mat3 R = w.norm() > 0.0 ? Mat3(Eigen::AngleAxisd(w.norm(), w.normalized())) : Mat3::Identity();
  const Vec3 shift = gaussian3(rng, c.arm_noise_m * noise_f);
  const auto arm = [&](const Vec3& p) { return Vec3(T * (centre + R * (p - centre) + shift)); };
  std::vector<Vec3> grasp;
  const double min_dot = c.flat ? 1.0 - 1e-9 : 0.3;
  for (int attempt = 0; attempt < 40 * c.contacts && static_cast<int>(grasp.size()) < c.contacts * c.duplicates; ++attempt) {
    Vec3 q;
    if (c.collinear_m > 0.0) {
      q = centre + rng.uniform(-radius, radius) * dir + rng.uniform(-1.0, 1.0) * c.collinear_m * f * side;
    } else {
      const double r = radius * std::sqrt(rng.uniform()), a = rng.uniform(0.0, 2 * kPi);
      q = centre + r * (std::cos(a) * t1 + std::sin(a) * t2);
    }
    const ClosestPoint cp = mesh.closest(q);
    if (cp.normal.dot(n) < min_dot || (cp.point - centre).norm() > 1.5 * radius) continue;
    const Vec3 p = arm(cp.point) + gaussian3(rng, c.contact_noise_m * noise_f);
    for (int d = 0; d < c.duplicates; ++d) grasp.push_back(p);
  }
  for (const Vec3& p : grasp) touch.contacts.points.push_back(p);
  touch.grasps.add(grasp);
  // Free space: where the pad came from, along the normal and beside it.
  for (int k = 1; k <= 4; ++k)
    for (int s = 0; s < 5; ++s) {
      const Vec3 sides[5] = {Vec3::Zero(), t1, -t1, t2, -t2};
      const Vec3& lateral = sides[s];
      const Vec3 q = centre + n * (0.006 * k * f) + lateral * radius;
      if (mesh.closest(q).distance > 0.003 * f && !mesh.inside(q)) touch.free.push_back(arm(q));
    }
}

// ---------------------------------------------------------------------------------------------
// Checks

std::string fmt(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

/// First non-finite value of a step's outputs ("" when none).
std::string step_non_finite(const StepResult& r) {
  const auto pose = [](const Pose& T) { return T.matrix().allFinite(); };
  if (r.valid && !pose(r.best.pose)) return "best pose";
  if (!std::isfinite(r.posterior)) return "posterior";
  for (std::size_t i = 0; i < r.posteriors.size(); ++i)
    if (!std::isfinite(r.posteriors[i])) return "posteriors[" + std::to_string(i) + "]";
  for (std::size_t i = 0; i < r.hypotheses.size(); ++i) {
    const Hypothesis& h = r.hypotheses[i];
    if (!pose(h.pose)) return "hypotheses[" + std::to_string(i) + "].pose";
    if (!std::isfinite(h.log_weight) || !std::isfinite(h.weight))
      return "hypotheses[" + std::to_string(i) + "] weight " + fmt(h.log_weight);
  }
  return {};
}

/// First non-finite value of a result store as read back ("" when none).
std::string store_non_finite(const io::ResultData& d) {
  for (const auto& [name, v] : d.header.params)
    if (!std::isfinite(v)) return "/params/" + name;
  if (d.header.truth_pose && !d.header.truth_pose->matrix().allFinite()) return "/ground_truth";
  for (const io::ResultStep& s : d.steps) {
    const std::string at = "step " + std::to_string(s.step) + ": ";
    for (double v : {s.best_weight, s.best_log_weight, s.best_posterior})
      if (!std::isfinite(v)) return at + "best weight/log weight/posterior " + fmt(v);
    if (!s.best_pose.matrix().allFinite()) return at + "best pose";
    for (double v : s.posterior)
      if (!std::isfinite(v)) return at + "posterior";
    if (s.error)
      for (double v : {s.error->position_m, s.error->orientation_deg, s.error->symmetric_orientation_deg,
                       s.error->symmetric_position_m})
        if (!std::isfinite(v)) return at + "errors " + fmt(v);
    for (const Hypothesis& h : s.hypotheses)
      if (!h.pose.matrix().allFinite() || !std::isfinite(h.log_weight) || !std::isfinite(h.weight))
        return at + "hypothesis " + fmt(h.log_weight);
  }
  return {};
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double largest(const std::vector<double>& v) { return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()); }

/// The size a case's errors are judged against: its objects' largest side (the rod's length).
double judged_size(const StressCase& c) { return c.rod_length_m > 0.0 ? c.rod_length_m : c.size_m; }

/// A run whose answer is wrong or off by more than 5 % of the size or 10 degrees.
bool failed(const StressRun& r, double size) {
  return !r.valid || !r.correct || r.position_error_m > 0.05 * size || r.orientation_error_deg > 10.0;
}

}  // namespace

// -------------------------------------------------------------------------------------------------
// Configuration

namespace {

double number_in(const std::string& value, double lo, double hi, const std::string& file,
                 const std::string& key) {
  double v = 0.0;
  try {
    std::size_t used = 0;
    v = std::stod(value, &used);
    if (used != value.size()) throw std::invalid_argument(value);
  } catch (const std::exception&) {
    throw Error("'" + value + "' is not a number", file, key);
  }
  if (!(v >= lo && v <= hi)) throw Error(value + " is outside " + fmt(lo) + " .. " + fmt(hi), file, key);
  return v;
}

int whole_in(const std::string& value, int lo, int hi, const std::string& file, const std::string& key) {
  const double v = number_in(value, lo, hi, file, key);
  if (v != std::floor(v)) throw Error("'" + value + "' is not a whole number", file, key);
  return static_cast<int>(v);
}

}  // namespace

void set_stress_key(StressCase& c, const std::string& key, const std::string& value,
                    const std::string& file) {
  const auto number = [&](double lo, double hi) { return number_in(value, lo, hi, file, key); };
  const auto whole = [&](int lo, int hi) { return whole_in(value, lo, hi, file, key); };
  const auto flag = [&] {
    if (value == "true" || value == "1") return true;
    if (value == "false" || value == "0") return false;
    throw Error("'" + value + "' is not true or false", file, key);
  };
  if (key == "size_m") c.size_m = number(0.001, 10.0);
  else if (key == "distance_m") c.distance_m = number(0.0, 1e7);
  else if (key == "arm_noise_m") c.arm_noise_m = number(0.0, 0.1);
  else if (key == "arm_rotation_deg") c.arm_rotation_deg = number(0.0, 20.0);
  else if (key == "contact_noise_m") c.contact_noise_m = number(0.0, 0.1);
  else if (key == "scale_noise") c.scale_noise = flag();
  else if (key == "grasps") c.grasps = whole(1, 200);
  else if (key == "contacts") c.contacts = whole(1, 100000);
  else if (key == "duplicates") c.duplicates = whole(1, 100);
  else if (key == "collinear_m") c.collinear_m = number(0.0, 0.01);
  else if (key == "flat") c.flat = flag();
  else if (key == "rod_length_m") c.rod_length_m = number(0.0, 10.0);
  else if (key == "rod_section_m") c.rod_section_m = number(0.001, 1.0);
  else throw Error("unknown key (size_m, distance_m, arm_noise_m, arm_rotation_deg, contact_noise_m, "
                   "scale_noise, grasps, contacts, duplicates, collinear_m, flat, rod_length_m, "
                   "rod_section_m)", file, key);
  if (static_cast<double>(c.grasps) * c.contacts * c.duplicates > 1e6)
    throw Error("grasps x contacts x duplicates exceeds 1 000 000", file, key);
}

StressStudy load_stress_study(const std::filesystem::path& path) {
  const std::string file = path.string();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw Error("cannot read the study configuration", file);
  std::vector<CLI::ConfigItem> items;
  try {
    CLI::ConfigTOML parser;
    items = parser.from_file(file);
  } catch (const CLI::Error& e) {
    throw Error(std::string("cannot parse the study configuration: ") + e.what(), file);
  }
  StressStudy study;
  StressCase baseline;
  std::vector<std::pair<std::string, std::string>> cases;
  std::set<std::string> seen;
  for (const auto& item : items) {
    if (item.name == "++" || item.name == "--") continue;
    const std::string key = item.fullname();
    if (!seen.insert(key).second) throw Error("key given twice", file, key);
    if (item.inputs.size() != 1) throw Error("expected one value", file, key);
    const std::string& v = item.inputs.front();
    if (item.parents.size() == 1 && item.parents[0] == "baseline") {
      set_stress_key(baseline, item.name, v, file);
    } else if (item.parents.size() == 1 && item.parents[0] == "cases") {
      cases.emplace_back(item.name, v);
    } else if (!item.parents.empty()) {
      throw Error("unknown section (baseline, cases)", file, key);
    } else if (key == "name") {
      study.name = v;
    } else if (key == "description") {
      study.description = v;
    } else if (key == "preset") {
      if (v != "improved" && v != "paper") throw Error("'" + v + "' is not improved or paper", file, key);
      study.preset = v;
    } else if (key == "runs") {
      study.runs = whole_in(v, 1, 200, file, key);
    } else if (key == "seed") {
      try {
        std::size_t used = 0;
        study.seed = std::stoull(v, &used);
        if (used != v.size()) throw std::invalid_argument(v);
      } catch (const std::exception&) {
        throw Error("'" + v + "' is not an unsigned integer", file, key);
      }
    } else {
      throw Error("unknown key (name, description, preset, runs, seed, [baseline], [cases])", file, key);
    }
  }
  if (cases.empty()) throw Error("no cases: add a [cases] section, e.g. small = \"size_m=0.01\"", file, "cases");
  for (const auto& [name, text] : cases) {
    StressCase c = baseline;
    c.name = name;
    std::stringstream ss(text);
    std::string part;
    while (std::getline(ss, part, ',')) {
      const auto trim = [](std::string s) {
        const auto b = s.find_first_not_of(" \t"), e = s.find_last_not_of(" \t");
        return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
      };
      part = trim(part);
      if (part.empty()) continue;
      const auto eq = part.find('=');
      if (eq == std::string::npos) throw Error("'" + part + "' is not key=value", file, "cases." + name);
      set_stress_key(c, trim(part.substr(0, eq)), trim(part.substr(eq + 1)), file + ": cases." + name);
    }
    study.cases.push_back(c);
  }
  return study;
}

// -------------------------------------------------------------------------------------------------
// Running

StressCaseResult run_stress_case(const StressStudy& study, std::size_t index,
                                 const std::filesystem::path& out_dir) {
  const auto t0 = std::chrono::steady_clock::now();
  const StressCase& c = study.cases.at(index);
  const bool rod = c.rod_length_m > 0.0;
  const double f = rod ? 1.0 : c.size_m / kReference;
  const StressDatabase& sd = stress_database(f, c.rod_length_m, c.rod_section_m, study.seed);
  const Database& db = *sd.db;
  RecognizerSettings rs = study.preset == "paper" ? RecognizerSettings::paper() : RecognizerSettings::improved();
  rs = rs.scaled(f);
  rs.seed = Rng(study.seed, 0x57e5).next();

  StressCaseResult result;
  result.config = c;
  result.runs.resize(static_cast<std::size_t>(study.runs));
  const Vec3 direction = Vec3(0.48, -0.6, 0.64).normalized();
  SymmetryCache symmetries;
  tbb::parallel_for(0, study.runs, [&](int run) {
    StressRun& out = result.runs[run];
    Rng rng(study.seed, 0x57e6, static_cast<std::uint64_t>(run));
    const std::size_t object = rod ? sd.names.size() - 1 : static_cast<std::size_t>(run) % 5;
    out.object = sd.names[object];
    Pose T = Pose::Identity();
    T.linear() = rng.rotation().toRotationMatrix();
    T.translation() = c.distance_m * direction + 0.25 * f * Vec3(rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-1, 1));
    const MeshIndex mesh(sd.meshes[object]);
    std::vector<int> faces;
    if (c.flat) {
      faces = largest_flat_region(mesh.mesh());
    } else {
      faces.resize(mesh.mesh().faces.size());
      for (std::size_t k = 0; k < faces.size(); ++k) faces[k] = static_cast<int>(k);
    }
    Recognizer rec(db, rs);
    Touch touch;
    std::vector<io::ResultStep> steps;
    StepResult r;
    for (int g = 0; g < c.grasps; ++g) {
      Rng grng(study.seed, 0x57e7, static_cast<std::uint64_t>(run), static_cast<std::uint64_t>(g));
      add_grasp(c, f, mesh, faces, T, grng, touch);
      r = rec.step(touch.contacts, touch.free, touch.grasps);
      const std::string bad = step_non_finite(r);
      if (!bad.empty() && out.finite) {
        out.finite = false;
        out.non_finite = "step " + std::to_string(g + 1) + ": " + bad;
      }
      steps.push_back(io::to_result_step(r, object, T, nullptr));
    }
    out.valid = r.valid;
    out.contacts = r.contacts;
    out.ambiguous = r.pose_ambiguous;
    out.unobservable_dof = r.unobservable_dof;
    out.correct = r.valid && r.best.object == object;
    if (r.valid) {
      const PoseError e = pose_error(r.best.pose, T, out.correct ? &symmetries.get(db, object) : nullptr);
      out.position_error_m = e.position_m;
      out.orientation_error_deg = e.orientation_deg;
      out.symmetric_position_error_m = e.symmetric_position_m;
      out.symmetric_orientation_error_deg = e.symmetric_orientation_deg;
      SceneSettings ss = rs.scene;
      ss.descriptor = db.settings().descriptor;
      ss.free_clearance = 0.0;
      const Scene scene = prepare_scene(touch.contacts, touch.free, db.settings().fpfh, ss, rs.seed,
                                        static_cast<std::uint64_t>(c.grasps));
      Pose T_scene = r.best.pose;
      T_scene.translation() -= scene.origin;
      const GeometryRef geo = db.geometry(r.best.object);
      const IcpSystem sys = icp_system(scene, *geo, T_scene, rs.icp);
      out.condition = sys.condition;
      out.condition_raw = sys.condition_raw;
    } else {
      out.position_error_m = out.orientation_error_deg = 0.0;
      out.symmetric_position_error_m = out.symmetric_orientation_error_deg = 0.0;
      out.condition = out.condition_raw = kIcpSingular;
    }
    if (!out_dir.empty()) {
      io::ResultHeader h;
      h.method = std::string(method_name(rs.method));
      h.seed = rs.seed;
      h.database = "stress database (in memory)";
      h.input = "stress case " + c.name;
      h.input_kind = "cloud";
      h.objects = sd.names;
      h.truth_object = sd.names[object];
      h.truth_pose = T;
      h.params = {{"size_m", c.size_m}, {"distance_m", c.distance_m}, {"arm_noise_m", c.arm_noise_m},
                  {"contacts", double(c.contacts)}, {"duplicates", double(c.duplicates)},
                  {"collinear_m", c.collinear_m}, {"rod_length_m", c.rod_length_m}};
      const std::filesystem::path file = out_dir / (c.name + "-" + std::to_string(run) + ".h5");
      io::write_result(file, h, steps);
      const std::string bad = store_non_finite(io::read_result(file));
      if (!bad.empty() && out.finite) {
        out.finite = false;
        out.non_finite = file.filename().string() + ": " + bad;
      }
    }
  });
  result.time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return result;
}

// -------------------------------------------------------------------------------------------------
// Output

std::string first_non_finite(const nlohmann::ordered_json& j, const std::string& path) {
  if (j.is_number_float() && !std::isfinite(j.get<double>())) return path.empty() ? "/" : path;
  if (j.is_object()) {
    for (auto it = j.begin(); it != j.end(); ++it) {
      const std::string p = first_non_finite(it.value(), path + "/" + it.key());
      if (!p.empty()) return p;
    }
  } else if (j.is_array()) {
    for (std::size_t i = 0; i < j.size(); ++i) {
      const std::string p = first_non_finite(j[i], path + "/" + std::to_string(i));
      if (!p.empty()) return p;
    }
  }
  return {};
}

namespace {

struct Summary {
  std::size_t runs = 0, correct = 0, flagged = 0, silent = 0, finite = 0;
  double pos_median = 0, pos_max = 0, ori_median = 0, ori_max = 0;
  double cond_median = 0, cond_max = 0, cond_raw_median = 0;
  double contacts_median = 0;
};

Summary summarize(const StressCaseResult& r) {
  Summary s;
  s.runs = r.runs.size();
  std::vector<double> pos, ori, cond, raw, contacts;
  const double size = judged_size(r.config);
  for (const StressRun& run : r.runs) {
    s.correct += run.correct;
    s.flagged += run.ambiguous;
    s.silent += failed(run, size) && !run.ambiguous;
    s.finite += run.finite;
    if (run.valid) {
      pos.push_back(run.position_error_m);
      ori.push_back(run.orientation_error_deg);
    }
    cond.push_back(run.condition);
    raw.push_back(run.condition_raw);
    contacts.push_back(static_cast<double>(run.contacts));
  }
  s.pos_median = median(pos);
  s.pos_max = largest(pos);
  s.ori_median = median(ori);
  s.ori_max = largest(ori);
  s.cond_median = median(cond);
  s.cond_max = largest(cond);
  s.cond_raw_median = median(raw);
  s.contacts_median = median(contacts);
  return s;
}

std::string length(double m) {
  char b[32];
  if (m == 0.0) return "0";
  if (m >= 1000.0) std::snprintf(b, sizeof b, "%g km", m / 1000.0);
  else if (m >= 1.0) std::snprintf(b, sizeof b, "%g m", m);
  else if (m >= 0.01) std::snprintf(b, sizeof b, "%g cm", m * 100.0);
  else std::snprintf(b, sizeof b, "%g mm", m * 1000.0);
  return b;
}

std::string condition_text(double c) {
  if (c >= kIcpSingular) return "singular";
  char b[32];
  std::snprintf(b, sizeof b, "%.1e", c);
  return b;
}

}  // namespace

json stress_json(const StressStudy& study, const std::vector<StressCaseResult>& results) {
  json j;
  j["study"] = study.name;
  j["description"] = study.description;
  j["preset"] = study.preset;
  j["runs"] = study.runs;
  j["seed"] = study.seed;
  j["icp_singular_condition"] = kIcpSingular;
  json cases = json::array();
  for (const StressCaseResult& r : results) {
    const StressCase& c = r.config;
    const Summary s = summarize(r);
    json jc;
    jc["name"] = c.name;
    jc["config"] = {{"size_m", c.size_m}, {"distance_m", c.distance_m}, {"arm_noise_m", c.arm_noise_m},
                    {"arm_rotation_deg", c.arm_rotation_deg}, {"contact_noise_m", c.contact_noise_m},
                    {"scale_noise", c.scale_noise}, {"grasps", c.grasps}, {"contacts", c.contacts},
                    {"duplicates", c.duplicates}, {"collinear_m", c.collinear_m}, {"flat", c.flat},
                    {"rod_length_m", c.rod_length_m}, {"rod_section_m", c.rod_section_m}};
    jc["runs"] = s.runs;
    jc["correct"] = s.correct;
    jc["flagged_ambiguous"] = s.flagged;
    jc["failed_unflagged"] = s.silent;
    jc["position_error_m_median"] = s.pos_median;
    jc["position_error_m_max"] = s.pos_max;
    jc["orientation_error_deg_median"] = s.ori_median;
    jc["orientation_error_deg_max"] = s.ori_max;
    jc["icp_condition_median"] = s.cond_median;
    jc["icp_condition_max"] = s.cond_max;
    jc["icp_condition_raw_median"] = s.cond_raw_median;
    jc["all_finite"] = s.finite == s.runs;
    jc["time_s"] = r.time_s;
    json runs = json::array();
    for (const StressRun& run : r.runs)
      runs.push_back({{"object", run.object}, {"valid", run.valid}, {"correct", run.correct},
                      {"position_error_m", run.position_error_m},
                      {"orientation_error_deg", run.orientation_error_deg},
                      {"symmetric_position_error_m", run.symmetric_position_error_m},
                      {"symmetric_orientation_error_deg", run.symmetric_orientation_error_deg},
                      {"pose_ambiguous", run.ambiguous}, {"unobservable_dof", run.unobservable_dof},
                      {"icp_condition", run.condition}, {"icp_condition_raw", run.condition_raw},
                      {"contacts", run.contacts}, {"finite", run.finite},
                      {"non_finite", run.non_finite}});
    jc["per_run"] = runs;
    cases.push_back(jc);
  }
  j["cases"] = cases;
  return j;
}

std::string stress_table(const std::vector<StressCaseResult>& results) {
  std::ostringstream o;
  o << "| case | size | distance | arm | contacts | right | pos. err. median / max | "
       "orient. median / max | flagged | failed unflagged | ICP cond. median / max | finite |\n";
  o << "|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  char b[512];
  for (const StressCaseResult& r : results) {
    const StressCase& c = r.config;
    const Summary s = summarize(r);
    const double f = c.scale_noise && c.rod_length_m <= 0.0 ? c.size_m / kReference : 1.0;
    const std::string size = c.rod_length_m > 0.0 ? length(c.rod_length_m) + " x " + length(c.rod_section_m)
                                                  : length(c.size_m);
    std::snprintf(b, sizeof b,
                  "| %s | %s | %s | %s | %.0f | %zu/%zu | %s / %s | %.2f / %.2f deg | %zu/%zu | %zu | "
                  "%s / %s | %s |\n",
                  c.name.c_str(), size.c_str(), length(c.distance_m).c_str(),
                  length(c.arm_noise_m * f).c_str(), s.contacts_median, s.correct, s.runs,
                  length(s.pos_median).c_str(), length(s.pos_max).c_str(), s.ori_median, s.ori_max,
                  s.flagged, s.runs, s.silent, condition_text(s.cond_median).c_str(),
                  condition_text(s.cond_max).c_str(), s.finite == s.runs ? "yes" : "NO");
    o << b;
  }
  return o.str();
}

}  // namespace ts::experiments
