// The `touchstone` Python module (pybind11): the library, not the command line. A database,
// tactile logs (simulate, read, write, the fused clouds of an exploration), a Recognizer stepped
// with NumPy arrays, experiments and their run stores. Errors are touchstone.Error (the C++
// ts::Error's message, file and field); the GIL is released during every long call. The pure
// Python part (touchstone/__init__.py) wraps this extension, `touchstone._touchstone`; the type
// stubs are touchstone/__init__.pyi.
#include "experiments/allocator.hpp"
#include "experiments/analysis/calibration.hpp"
#include "experiments/analysis/report.hpp"
#include "experiments/params/config.hpp"
#include "experiments/params/parameters.hpp"
#include "experiments/resources.hpp"
#include "experiments/runs/driver.hpp"
#include "experiments/runs/engine_database.hpp"
#include "experiments/runs/grasp_pools.hpp"
#include "experiments/runs/log_steps.hpp"
#include "experiments/runs/recognition_engine.hpp"

#include "datasets/db_builder.hpp"
#include "datasets/simulator.hpp"
#include "engine/database/symmetry_cache.hpp"
#include "engine/geometry/symmetry.hpp"
#include "engine/recognition/answer_set.hpp"
#include "engine/recognition/recognizer.hpp"
#include "io/db_store.hpp"
#include "io/log_store.hpp"
#include "io/result_store.hpp"
#include "io/run_store.hpp"

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <tbb/global_control.h>

#include <cmath>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

namespace py = pybind11;

namespace ts::python {
namespace {

using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;

// ---- conversions ----------------------------------------------------------------------------

/// An N x 3 array as points; `what` names the argument in the error.
std::vector<Vec3> points_of(const py::object& obj, const char* what) {
  if (obj.is_none()) return {};
  const Array a = Array::ensure(obj);
  if (!a) throw py::value_error(std::string(what) + ": expected an N x 3 array of numbers");
  if (a.ndim() != 2 || a.shape(1) != 3)
    throw py::value_error(std::string(what) + ": expected an N x 3 array, got shape " +
                          py::str(py::object(a.attr("shape"))).cast<std::string>());
  const auto r = a.unchecked<2>();
  std::vector<Vec3> p(static_cast<std::size_t>(a.shape(0)));
  for (py::ssize_t i = 0; i < a.shape(0); ++i) {
    p[static_cast<std::size_t>(i)] = Vec3(r(i, 0), r(i, 1), r(i, 2));
    if (!p[static_cast<std::size_t>(i)].allFinite())
      throw py::value_error(std::string(what) + ": row " + std::to_string(i) + " is not finite");
  }
  return p;
}

py::array_t<double> array_of(const std::vector<Vec3>& p) {
  py::array_t<double> a({static_cast<py::ssize_t>(p.size()), py::ssize_t{3}});
  auto w = a.mutable_unchecked<2>();
  for (std::size_t i = 0; i < p.size(); ++i)
    for (int c = 0; c < 3; ++c) w(static_cast<py::ssize_t>(i), c) = p[i](c);
  return a;
}

/// Contacts by grasp from Python: `grasps` a sequence of N_g x 3 arrays, `hand_free` (None, or
/// one M_g x 3 array per grasp: the points its hand held free) and `pivots` (None, or a G x 3
/// array: the point each grasp's arm error turns about), as Exploration's grasps(), hand_free()
/// and pivots() give them.
GraspGroups grasp_groups(const py::object& grasps, const py::object& hand_free, const py::object& pivots) {
  GraspGroups g;
  if (grasps.is_none()) {
    if (!hand_free.is_none() || !pivots.is_none())
      throw py::value_error("hand_free and pivots describe grasps: give grasps too");
    return g;
  }
  std::vector<py::object> items, frees;
  for (const auto& item : grasps) items.push_back(py::reinterpret_borrow<py::object>(item));
  if (!hand_free.is_none()) {
    for (const auto& item : hand_free) frees.push_back(py::reinterpret_borrow<py::object>(item));
    if (frees.size() != items.size())
      throw py::value_error("hand_free: " + std::to_string(frees.size()) + " entries for " +
                            std::to_string(items.size()) + " grasps (one array per grasp)");
  }
  const std::vector<Vec3> pv = points_of(pivots, "pivots");
  if (!pivots.is_none() && pv.size() != items.size())
    throw py::value_error("pivots: " + std::to_string(pv.size()) + " rows for " + std::to_string(items.size()) +
                          " grasps (one per grasp)");
  for (std::size_t k = 0; k < items.size(); ++k)
    g.add(points_of(items[k], "grasps[]"), frees.empty() ? std::vector<Vec3>{} : points_of(frees[k], "hand_free[]"),
          pv.empty() ? std::nullopt : std::optional<Vec3>(pv[k]));
  return g;
}

py::array_t<double> matrix_of(const Pose& T) {
  py::array_t<double> a({py::ssize_t{4}, py::ssize_t{4}});
  auto w = a.mutable_unchecked<2>();
  const Eigen::Matrix4d M = T.matrix();
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) w(r, c) = M(r, c);
  return a;
}

py::array_t<double> vector_of(const std::vector<double>& v) {
  py::array_t<double> a(static_cast<py::ssize_t>(v.size()));
  std::copy(v.begin(), v.end(), a.mutable_data());
  return a;
}

/// A parameter value given in Python as the text the flags and configuration files take.
std::string value_text(const py::handle& v) {
  if (py::isinstance<py::bool_>(v)) return v.cast<bool>() ? "true" : "false";
  if (py::isinstance<py::str>(v)) return v.cast<std::string>();
  if (py::isinstance<py::int_>(v) || py::isinstance<py::float_>(v)) return py::str(py::repr(v)).cast<std::string>();
  if (py::isinstance<py::list>(v) || py::isinstance<py::tuple>(v)) {
    std::string s;
    for (const auto& x : v) s += (s.empty() ? "" : ",") + value_text(x);
    return s;
  }
  throw py::type_error("a parameter value must be a number, a bool, a string or a list of them");
}

/// The method settings of a preset with `params` (key -> value) applied in the declaration's
/// order, as `touchstone recognize` applies its flags. An unknown key or a parameter that is not
/// a method parameter is an error naming it.
experiments::MethodSettings method_settings(const std::string& preset, const py::dict& params) {
  experiments::MethodSettings m = experiments::MethodSettings::preset(preset);
  std::map<std::string, std::string> given;
  for (const auto& [k, v] : params) {
    const std::string key = py::str(k).cast<std::string>();
    const experiments::Parameter* p = experiments::find_parameter(key);
    if (!p) throw Error("unknown parameter '" + key + "' (touchstone.parameters() lists them)", {}, key);
    if (p->kind != experiments::Parameter::Kind::method)
      throw Error("'" + key + "' is a " + experiments::kind_name(p->kind) + " parameter, not a method parameter", {}, key);
    given[p->key] = value_text(v);
  }
  for (const experiments::Parameter& p : experiments::method_parameters()) {
    const auto it = given.find(p.key);
    if (it != given.end()) experiments::apply(m, p, experiments::parse_value(p, it->second, {}, p.key));
  }
  return m;
}

// ---- the database ---------------------------------------------------------------------------

/// An open database file: the reader and the engine's lazy cache over it.
struct PyDatabase {
  std::string path;
  std::shared_ptr<io::DbReader> reader;
  std::shared_ptr<Database> db;

  std::size_t index(const py::object& key) const {
    if (py::isinstance<py::int_>(key)) {
      const auto i = key.cast<long long>();
      if (i < 0 || static_cast<std::size_t>(i) >= db->size())
        throw py::index_error("object index " + std::to_string(i) + " out of range (" + std::to_string(db->size()) +
                              " objects)");
      return static_cast<std::size_t>(i);
    }
    const std::string name = key.cast<std::string>();
    const std::size_t i = db->find(name);
    if (i == db->size()) throw Error("no object '" + name + "' in the database", path, "object");
    return i;
  }
};

std::shared_ptr<PyDatabase> open_database(const std::string& path, std::optional<double> memory_budget_mb) {
  auto d = std::make_shared<PyDatabase>();
  d->path = path;
  {
    py::gil_scoped_release release;
    d->reader = std::make_shared<io::DbReader>(path);
    d->db = std::make_shared<Database>(d->reader);
    if (d->db->size() == 0) throw Error("the database has no objects", path, "/objects");
    experiments::set_memory_budget(*d->db, memory_budget_mb, path, "memory_budget_mb");
  }
  return d;
}

// ---- the database's geometry as arrays (object frame, metres) ---------------------------------

/// An object's stored cloud: "fine" (the scanner's, exact face normals) or "coarse" (the feature
/// points, PCA normals).
PointCloud object_cloud(const PyDatabase& d, std::size_t i, const std::string& cloud) {
  if (cloud != "fine" && cloud != "coarse")
    throw py::value_error("cloud: expected \"fine\" or \"coarse\", got \"" + cloud + "\"");
  py::gil_scoped_release release;
  return cloud == "fine" ? d.db->load_fine(i) : d.reader->load_coarse(i);
}

py::array_t<double> object_points(const PyDatabase& d, const py::object& key, const std::string& cloud) {
  return array_of(object_cloud(d, d.index(key), cloud).points);
}

py::array_t<double> object_normals(const PyDatabase& d, const py::object& key, const std::string& cloud) {
  const std::size_t i = d.index(key);
  const PointCloud c = object_cloud(d, i, cloud);
  if (!c.has_normals())
    throw Error("the " + cloud + " cloud of '" + d.db->info(i).name + "' has no normals", d.path, "/objects");
  return array_of(c.normals);
}

/// (vertices V x 3 float64, faces F x 3 int64), the object-frame mesh the simulator touches.
py::tuple object_mesh(const PyDatabase& d, const py::object& key) {
  const std::size_t i = d.index(key);
  Mesh mesh;
  {
    py::gil_scoped_release release;
    mesh = d.reader->load_mesh(i);
  }
  py::array_t<std::int64_t> faces({static_cast<py::ssize_t>(mesh.faces.size()), py::ssize_t{3}});
  auto w = faces.mutable_unchecked<2>();
  for (std::size_t f = 0; f < mesh.faces.size(); ++f)
    for (int c = 0; c < 3; ++c) w(static_cast<py::ssize_t>(f), c) = mesh.faces[f](c);
  return py::make_tuple(array_of(mesh.vertices), faces);
}

/// The object's distance field at N x 3 object-frame points: the signed distance to its surface
/// (m, negative inside a closed mesh), exact to the field's interpolation near the surface and a
/// lower bound (>= the field's coarse margin) far from it.
py::array_t<double> object_distance(const PyDatabase& d, const py::object& key, const py::object& points) {
  const std::size_t i = d.index(key);
  const std::vector<Vec3> p = points_of(points, "points");
  std::vector<double> out(p.size());
  {
    py::gil_scoped_release release;
    const GeometryRef g = d.db->geometry(i);
    g->field.distances(p.data(), p.size(), Pose::Identity(), out.data());
  }
  return vector_of(out);
}

py::dict object_info(const PyDatabase& d, std::size_t i) {
  const ObjectInfo& info = d.db->info(i);
  py::dict o;
  o["name"] = info.name;
  o["index"] = i;
  o["source"] = info.source;
  o["mesh_sha256"] = info.mesh_sha256;
  o["scale"] = info.scale;
  o["extent_m"] = array_of({info.extent}).attr("reshape")(3);
  o["fine_points"] = info.fine_points;
  o["coarse_points"] = info.coarse_points;
  o["closed"] = info.closed;
  o["coverage"] = info.coverage;
  return o;
}

// ---- tactile logs ---------------------------------------------------------------------------

struct PyLog {
  std::shared_ptr<TactileLog> log;   // shared: an Exploration holds a reference to it
};

py::object truth_pose(const PyLog& l) {
  if (!l.log->truth) return py::none();
  return matrix_of(l.log->truth->object_pose);
}

py::array_t<double> arm_poses(const PyLog& l) {
  const auto& g = l.log->grasps;
  py::array_t<double> a({static_cast<py::ssize_t>(g.size()), py::ssize_t{4}, py::ssize_t{4}});
  auto w = a.mutable_unchecked<3>();
  for (std::size_t k = 0; k < g.size(); ++k) {
    const Eigen::Matrix4d M = g[k].arm_pose.matrix();
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) w(static_cast<py::ssize_t>(k), r, c) = M(r, c);
  }
  return a;
}

PyLog simulate(const PyDatabase& d, const py::object& object, std::size_t grasps, const std::string& noise,
               int sensors, std::uint64_t seed, const py::dict& params) {
  const std::size_t i = d.index(object);
  experiments::ExperimentConfig c;
  experiments::set_key(c, "noise", {noise});
  experiments::set_key(c, "sensors", {std::to_string(sensors)});
  for (const auto& [k, v] : params) {
    const std::string key = py::str(k).cast<std::string>();
    const experiments::Parameter* p = experiments::find_parameter(key);
    if (!p || !p->simulate)
      throw Error("'" + key + "' is not a simulator parameter (touchstone.parameters(kind=\"simulator\"))", {}, key);
    experiments::set_key(c, p->key, {value_text(v)});
  }
  datasets::SimulatorSettings s = experiments::simulation_settings(c);
  s.grasps = grasps;
  s.seed = seed;
  PyLog l;
  {
    py::gil_scoped_release release;
    s.neighbours = datasets::scene_neighbours(s.scene, d.db->size(), i, s.seed, [&](std::size_t k) {
      return datasets::SceneObject{d.db->info(k).name, d.reader->load_mesh(k)};
    });
    const datasets::Simulator sim(d.reader->load_mesh(i), d.db->info(i).name, Gripper(), s);
    l.log = std::make_shared<TactileLog>(sim.run().log);
  }
  return l;
}

// ---- recognition ----------------------------------------------------------------------------

/// One step as Python sees it: names resolved, poses as 4 x 4 arrays.
py::dict hypothesis_dict(const Database& db, const Hypothesis& h) {
  py::dict o;
  o["object"] = db.info(h.object).name;
  o["object_index"] = h.object;
  o["pose"] = matrix_of(h.pose);
  o["log_weight"] = h.log_weight;
  o["weight"] = h.weight;
  o["born"] = h.born;
  return o;
}

py::dict step_dict(const Database& db, const StepResult& r, const std::optional<io::ResultStep>& scored) {
  py::dict o;
  o["step"] = r.step;
  o["valid"] = r.valid;
  o["object"] = r.valid ? py::object(py::str(db.info(r.best.object).name)) : py::none();
  o["object_index"] = r.valid ? py::object(py::int_(r.best.object)) : py::none();
  o["pose"] = r.valid ? py::object(matrix_of(r.best.pose)) : py::none();
  o["log_weight"] = r.valid ? py::object(py::float_(r.best.log_weight)) : py::none();
  o["weight"] = r.valid ? py::object(py::float_(r.best.weight)) : py::none();
  o["posterior"] = r.valid ? py::object(py::float_(r.posterior)) : py::none();
  o["posteriors"] = vector_of(r.posteriors);
  py::list hs;
  for (const Hypothesis& h : r.hypotheses) hs.append(hypothesis_dict(db, h));
  o["hypotheses"] = hs;
  o["contacts"] = r.contacts;
  o["free_points"] = r.free_points;
  if (r.support.found) {
    py::dict sp;
    const SupportSurface& u = r.support;
    if (u.shape == SupportSurface::Shape::plane) {
      sp["shape"] = "plane";
      sp["normal"] = vector_of(std::vector<double>{u.normal.x(), u.normal.y(), u.normal.z()});
      sp["offset_m"] = u.offset;
    } else {
      sp["shape"] = "cylinder";
      sp["axis"] = vector_of(std::vector<double>{u.axis.x(), u.axis.y(), u.axis.z()});
      sp["point"] = vector_of(std::vector<double>{u.point.x(), u.point.y(), u.point.z()});
      sp["radius_m"] = u.radius;
    }
    sp["contacts"] = r.support.contacts_on;
    sp["grasps"] = r.support.grasps_on;
    o["support"] = sp;
  } else {
    o["support"] = py::none();
  }
  o["support_verdict"] = r.support.verdict == SupportVerdict::not_looked ? py::object(py::none())
                                                                        : py::object(py::str(to_string(r.support.verdict)));
  if (!r.attribution.empty()) {   // per contact: 0 the object's, 1 the support's, 2 unexplained
    py::array_t<std::uint8_t> a(static_cast<py::ssize_t>(r.attribution.size()));
    auto w = a.mutable_unchecked<1>();
    for (std::size_t i = 0; i < r.attribution.size(); ++i) w(static_cast<py::ssize_t>(i)) = static_cast<std::uint8_t>(r.attribution[i]);
    o["attribution"] = a;
  } else {
    o["attribution"] = py::none();
  }
  o["unobservable_dof"] = r.unobservable_dof;
  o["pose_ambiguous"] = r.pose_ambiguous;
  o["observability"] = r.observability_from_model ? "answer_surface" : "contact_normals";
  o["candidates"] = r.candidates;
  py::dict t;
  t["prepare"] = r.times.prepare_s;
  t["shortlist"] = r.times.shortlist_s;
  t["prune"] = r.times.prune_s;
  t["register"] = r.times.register_s;
  t["icp"] = r.times.icp_s;
  t["evaluate"] = r.times.evaluate_s;
  t["total"] = r.times.total_s;
  o["times_s"] = t;
  py::list ran, skipped;   // the step's pipeline: stages run (times in times_s) and left out (why)
  for (const StageRun& g : r.stages) {
    if (g.ran) {
      ran.append(g.name);
      t[py::str("stage." + g.name)] = g.seconds;
    } else {
      py::dict d;
      d["stage"] = g.name;
      d["reason"] = g.reason;
      skipped.append(d);
    }
  }
  o["stages_ran"] = ran;
  o["stages_skipped"] = skipped;
  // Recognizer(explain=True): why the answer won over its best rival (as recognize --explain).
  if (r.explanation.empty()) {
    o["explanation"] = py::none();
  } else {
    py::dict x;
    x["decided_by"] = r.decided_by.empty() ? py::object(py::none()) : py::object(py::str(r.decided_by));
    py::list hs;
    for (const Evidence& e : r.explanation) {
      py::dict h;
      h["role"] = &e == &r.explanation.front() ? "answer" : "rival";
      h["object"] = db.info(e.object).name;
      h["rank"] = e.rank;
      h["pose"] = matrix_of(e.pose);
      h["log_weight"] = e.log_weight;
      h["contact_log_weight"] = e.contact_log_weight;
      h["free_log_weight"] = e.free_log_weight;
      h["floor_log_weight"] = e.floor_log_weight;
      h["free_points_checked"] = e.free_points_checked;
      h["offset_rms_m"] = e.offset_rms_m;
      h["contact_rms_sigma"] = e.fit.valid ? py::object(py::float_(e.fit.rms_sigma)) : py::none();
      h["contacts_beyond_3_sigma"] = e.fit.valid ? py::object(py::float_(e.fit.far_share)) : py::none();
      h["twin_score"] = std::isfinite(e.twin_score) ? py::object(py::float_(e.twin_score)) : py::none();
      h["posterior"] = e.posterior;
      hs.append(h);
    }
    x["hypotheses"] = hs;
    o["explanation"] = x;
  }
  // Against the truth, when known (a simulated log): as the result files store them.
  const bool known = scored && scored->correct.has_value();
  o["correct"] = known ? py::object(py::bool_(*scored->correct)) : py::none();
  const auto e = scored ? scored->error : std::nullopt;
  o["position_error_m"] = e ? py::object(py::float_(e->position_m)) : py::none();
  o["orientation_error_deg"] = e ? py::object(py::float_(e->orientation_deg)) : py::none();
  o["symmetric_orientation_error_deg"] = e ? py::object(py::float_(e->symmetric_orientation_deg)) : py::none();
  return o;
}

class PyRecognizer {
 public:
  PyRecognizer(std::shared_ptr<PyDatabase> d, const std::string& preset, const std::string& method,
               std::uint64_t seed, const py::dict& params, const std::optional<std::vector<std::string>>& only,
               const std::optional<std::string>& calibration, const std::optional<double>& alpha, bool explain)
      : d_(std::move(d)), m_(method_settings(preset, params)), explain_(explain) {
    // Set answers (as `recognize --calibration FILE --alpha A`): the calibration's answer sets.
    if (calibration) {
      calibration_ = experiments::read_calibration(*calibration, experiments::file_fingerprint(*d_->reader));
      if (calibration_->answer_sets.empty())
        throw Error("the calibration has no answer sets: fit it with `touchstone calibrate` on run stores of this "
                    "version", *calibration, "answer_sets");
      calibration_->single_answer_sets(*calibration);   // a sweep's calibration: which level is for these contacts?
    } else if (alpha) {
      throw Error("set answers need a calibration", {}, "alpha");
    }
    if (alpha && !(*alpha > 0.0 && *alpha < 1.0)) throw Error("alpha must lie in (0, 1)", {}, "alpha");
    alpha_ = alpha;
    const io::CongruenceRecord* congruence = d_->reader->congruence();
    class_of_ = class_indices(d_->db->size(), congruence ? congruence->classes() : std::vector<std::vector<std::size_t>>{},
                              classes_);
    const auto parsed = parse_method(method);
    if (!parsed) throw Error("unknown method '" + method + "' (bricpsf, batch-ransac, ransac-icp, ransac-icp-fs)", {}, "method");
    m_.recognizer.method = *parsed;
    m_.recognizer.seed = seed;
    inside_margin_given_ = params.contains("evaluate.free_inside_margin_m");
    if (only) {
      m_.recognizer.objects.assign(d_->db->size(), 0);
      for (const std::string& name : *only) m_.recognizer.objects[d_->index(py::str(name))] = 1;
    }
    d_->db->set_surface(needs_surface(m_.recognizer, d_->db->settings()));
    py::gil_scoped_release release;
    rec_ = std::make_unique<Recognizer>(*d_->db, m_.recognizer);
    rec_->explain(explain_);
  }

  py::dict step(const py::object& contacts, const py::object& free, const py::object& grasps,
               const py::object& hand_free, const py::object& pivots) {
    PointCloud c;
    c.points = points_of(contacts, "contacts");
    const std::vector<Vec3> f = points_of(free, "free");
    const GraspGroups g = grasp_groups(grasps, hand_free, pivots);
    StepResult r;
    {
      py::gil_scoped_release release;
      r = rec_->step(c, f, g);
    }
    py::dict o = step_dict(*d_->db, r, std::nullopt);
    o["answer_set"] = answer_set(r);
    return o;
  }

  /// The step's set answer (None without a calibration), as `recognize --json` gives it.
  py::object answer_set(const StepResult& r) const {
    if (!calibration_) return py::none();
    const experiments::AnswerSetCalibration& a = calibration_->answer_sets.front();   // one: checked on reading
    const double alpha = alpha_.value_or(a.alpha);
    const AnswerSet set = conformal_set(class_log_weight_gaps(r, class_of_, classes_), a.at(r.step), alpha);
    py::dict o;
    o["alpha"] = alpha;
    o["informative"] = set.informative;
    o["size"] = set.size;
    o["calibrated_step"] = a.calibrated_step(r.step);
    py::list members;
    for (const AnswerSetMember& m : set.members) {
      py::list names;
      for (std::size_t i = 0; i < class_of_.size(); ++i)
        if (class_of_[i] == m.cls) names.append(d_->db->info(i).name);
      py::dict x;
      x["objects"] = names;
      x["p_value"] = m.p_value;
      if (outside_state(m.gap)) {   // no hypothesis in the state: there by the shape prior
        x["log_weight_gap"] = py::none();
        x["prior_gap"] = m.gap - kOutsideState;
      } else {
        x["log_weight_gap"] = m.gap;
      }
      members.append(x);
    }
    o["members"] = members;
    return o;
  }

  /// Every step of a log, as `touchstone recognize --log` takes them (the same settings, fusion
  /// and seed: the same answers); `steps` 0: all grasps. Resets the recognizer first.
  py::list recognize_log(const PyLog& l, int steps) {
    const TactileLog& log = *l.log;
    const int n = static_cast<int>(log.grasps.size());
    if (n == 0) throw Error("the log has no grasps", {}, "/grasps");
    if (steps < 0 || steps > n)
      throw Error("steps " + std::to_string(steps) + " outside 0.." + std::to_string(n) + " (the log's grasps)", {}, "steps");
    const int K = steps > 0 ? steps : n;
    std::vector<StepResult> results;
    std::vector<io::ResultStep> scored;
    {
      py::gil_scoped_release release;
      const Database& db = *d_->db;
      const RecognizerSettings rs = experiments::log_settings(m_.recognizer, log, inside_margin_given_);
      Recognizer rec(db, rs);
      rec.explain(explain_);
      Exploration ex(log, experiments::log_exploration(db, m_.recognizer, m_.contact_voxel));
      std::optional<std::size_t> truth;
      if (!log.object.empty() && db.find(log.object) < db.size()) truth = db.find(log.object);
      const std::optional<Pose> truth_pose = log.truth ? std::optional(log.truth->object_pose) : std::nullopt;
      const SymmetryGroup* sym = truth && truth_pose ? &symmetries_.get(db, *truth) : nullptr;
      for (int k = 1; k <= K; ++k) {
        experiments::StepInput in = experiments::step_input(ex, static_cast<std::size_t>(k), m_.recognizer.method);
        results.push_back(rec.step(in.contacts, in.free, in.grasps));
        scored.push_back(io::to_result_step(results.back(), truth, truth_pose, sym));
      }
    }
    py::list out;
    for (std::size_t k = 0; k < results.size(); ++k) {
      py::dict o = step_dict(*d_->db, results[k], scored[k]);
      o["answer_set"] = answer_set(results[k]);
      out.append(o);
    }
    return out;
  }

  void reset() { rec_->reset(); }

  py::dict settings() const {
    py::dict o;
    for (const auto& [key, value] : experiments::stored_parameters(m_)) o[py::str(key)] = value;
    return o;
  }

  py::list hypotheses() const {
    py::list hs;
    for (const Hypothesis& h : rec_->hypotheses()) hs.append(hypothesis_dict(*d_->db, h));
    return hs;
  }

 private:
  std::shared_ptr<PyDatabase> d_;
  experiments::MethodSettings m_;
  bool explain_ = false;   ///< each step says why its answer won (StepResult::explanation)
  bool inside_margin_given_ = false;
  std::unique_ptr<Recognizer> rec_;
  SymmetryCache symmetries_;
  std::optional<experiments::Calibration> calibration_;   ///< with answer sets (null: none)
  std::optional<double> alpha_;
  std::vector<std::uint32_t> class_of_;
  std::size_t classes_ = 0;
};

/// `grasps` arrays, the k-th of points[first[k]] .. points[first[k + 1] - 1] (0 x 3 for a grasp
/// `first` has no offsets for).
py::list per_grasp(const std::vector<Vec3>& points, const std::vector<std::uint32_t>& first, std::size_t grasps) {
  py::list out;
  for (std::size_t k = 0; k < grasps; ++k)
    out.append(array_of(k + 1 < first.size() ? std::vector<Vec3>(points.begin() + first[k], points.begin() + first[k + 1])
                                              : std::vector<Vec3>{}));
  return out;
}

/// The fused clouds of a log, step by step (the recognizer's inputs), on a database's box.
class PyExploration {
 public:
  PyExploration(PyLog l, const PyDatabase& d, double contact_voxel, std::optional<double> res_free)
      : log_(std::move(l.log)) {
    RecognizerSettings rs = experiments::MethodSettings::preset("improved").recognizer;
    if (res_free) rs.evaluate.res_free = *res_free;
    ex_ = std::make_unique<Exploration>(*log_, experiments::log_exploration(*d.db, rs, contact_voxel));
  }
  void advance_to(std::size_t k) {
    py::gil_scoped_release release;
    ex_->advance_to(k);
  }
  std::size_t steps() const { return ex_->steps(); }
  py::array_t<double> contacts() const { return array_of(ex_->contact_cloud().points); }
  py::array_t<double> free() const {
    std::vector<Vec3> f;
    {
      py::gil_scoped_release release;
      f = ex_->free_cloud().points;
    }
    return array_of(f);
  }
  /// Per grasp, its contacts.
  py::list grasps() const {
    const GraspGroups& g = ex_->grasp_groups();
    return per_grasp(g.points, g.first, g.grasps());
  }
  /// Per grasp, the points its hand held free at the end of the grasp (GraspGroups::free).
  py::list hand_free() const {
    const GraspGroups& g = ex_->grasp_groups();
    return per_grasp(g.free, g.free_first, g.grasps());
  }
  /// Per grasp, the point its arm pose error turns about (GraspGroups::pivots; 0 x 3 when unknown).
  py::array_t<double> pivots() const { return array_of(ex_->grasp_groups().pivots); }

 private:
  std::shared_ptr<TactileLog> log_;
  std::unique_ptr<Exploration> ex_;
};

// ---- progress callbacks ----------------------------------------------------------------------

/// A Python progress(done, total, seconds_left) called from the C++ workers (one call at a time):
/// it takes the GIL for the call and keeps what the callback raises, for the caller to stop its
/// work and raise it again. None: no callback.
class PyProgress {
 public:
  explicit PyProgress(py::object f) : f_(std::move(f)) {
    if (!f_.is_none() && !PyCallable_Check(f_.ptr()))
      throw py::type_error("progress: expected a callable progress(done, total, seconds_left) or None");
  }
  bool active() const { return !f_.is_none(); }
  /// False once the callback has raised (it is not called again).
  bool operator()(std::size_t done, std::size_t total, std::optional<double> seconds_left) {
    if (raised_) return false;
    py::gil_scoped_acquire gil;
    try {
      f_(done, total, seconds_left ? py::object(py::float_(*seconds_left)) : py::object(py::none()));
      return true;
    } catch (...) {
      raised_ = std::current_exception();
      return false;
    }
  }
  /// Raises what the callback raised, if it did.
  void raise_if_raised() const {
    if (raised_) std::rethrow_exception(raised_);
  }

 private:
  py::object f_;
  std::exception_ptr raised_;
};

// ---- building a database ---------------------------------------------------------------------

/// `touchstone db build` without the command line. `inputs`: (name, path, source) per mesh, or
/// `manifest`, or `folder` (one of the three, as the Python wrapper gives them); `params`: build
/// parameters by their names in Database.settings. Returns what was built, as a dict.
py::dict build_database(const std::string& out, const py::list& inputs, const std::string& manifest,
                        const std::string& folder, const py::dict& params, const std::string& scale,
                        const std::string& units, std::uint64_t seed, double congruence_tolerance, int threads,
                        const py::object& progress_f) {
  PyProgress progress(progress_f);
  std::vector<datasets::MeshInput> meshes;
  if (!manifest.empty()) {
    meshes = datasets::inputs_from_manifest(manifest);
  } else if (!folder.empty()) {
    meshes = datasets::inputs_from_folder(folder);
  } else {
    for (std::size_t k = 0; k < inputs.size(); ++k) {
      const auto t = inputs[k].cast<py::tuple>();
      const std::string field = "meshes[" + std::to_string(k) + "]";
      datasets::MeshInput in;
      try {
        in = datasets::input_from_path(t[1].cast<std::string>(), t[0].cast<std::string>());
      } catch (const Error& e) {   // e.g. an object name a database cannot hold
        throw Error(e.message(), out, field);
      }
      const auto source = t[2].cast<std::string>();
      if (!source.empty()) in.source = source;
      in.origin = "build_database";
      in.origin_field = field;
      meshes.push_back(std::move(in));
    }
  }
  datasets::BuildSettings bs;
  if (scale == "keep") bs.database.scale = ObjectScale::keep;
  else if (scale != "fit") throw Error("expected \"fit\" or \"keep\", got \"" + scale + "\"", out, "scale");
  const auto per_unit = io::metres_per_unit(units);
  if (!per_unit) throw Error("expected a unit of m, cm, mm or in, got \"" + units + "\"", out, "units");
  bs.units = *per_unit;
  for (const auto& [k, v] : params) {
    const std::string key = py::str(k).cast<std::string>();
    if (key == "descriptor") {
      const std::string d = py::str(v).cast<std::string>();
      try {
        bs.database.descriptor = ts::parse_descriptor(d);
      } catch (const Error& e) {
        throw Error(e.message(), out, "descriptor");
      }
      continue;
    }
    // A number: Python's or NumPy's (anything with __float__ but a bool or a string).
    if (py::isinstance<py::bool_>(v) || py::isinstance<py::str>(v) || !py::hasattr(v, "__float__"))
      throw Error("expected a number, got " + py::repr(v).cast<std::string>(), out, key);
    io::set_setting_value(bs.database, key, py::float_(py::reinterpret_borrow<py::object>(v)).cast<double>(), out);   // errors name the key
  }
  bs.seed = seed;
  if (!(congruence_tolerance > 0.0) || !std::isfinite(congruence_tolerance))
    throw Error("expected a positive fraction of the object size (e.g. 0.01)", out, "congruence_tolerance");
  bs.congruence.tolerance = congruence_tolerance;
  // The callback after each object (on the worker that built it, one at a time): what it raises
  // stops the build (the objects finished stay in OUT.parts, so the same call resumes) and is
  // raised again here.
  struct ProgressRaised {};
  if (progress.active())
    bs.progress = [&](const datasets::BuildProgress& p) {
      const std::size_t built = p.done - p.resumed;
      if (!progress(p.done, p.total, built ? std::optional<double>(p.remaining_s()) : std::nullopt))
        throw ProgressRaised{};
    };
  datasets::BuildReport report;
  try {
    py::gil_scoped_release release;
    std::optional<tbb::global_control> limit;
    if (threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
    report = datasets::build_database(meshes, out, bs);
  } catch (...) {
    // What the callback raised comes first, also when another object's error reached here
    // before it (the build rethrows the error of the smallest failing object).
    progress.raise_if_raised();
    throw;
  }
  py::dict d;
  d["out"] = out;
  d["objects"] = report.names;
  d["resumed"] = report.resumed;
  py::list warnings;
  for (std::size_t i = 0; i < report.names.size(); ++i)
    for (const auto& w : report.warnings[i]) warnings.append(py::make_tuple(report.names[i], w));
  d["warnings"] = warnings;
  py::list classes;
  for (const auto& members : report.congruence.record.classes()) {
    py::list names;
    for (std::size_t i : members) names.append(report.names.at(i));
    classes.append(names);
  }
  d["congruent_classes"] = classes;
  const auto& t = report.times;
  d["times_s"] = py::dict(py::arg("import") = t.import_s, py::arg("scan") = t.scan_s, py::arg("features") = t.features_s,
                          py::arg("field") = t.field_s, py::arg("write") = t.write_s, py::arg("wall") = t.wall_s);
  return d;
}

// ---- experiments and run stores -------------------------------------------------------------

/// `touchstone experiment` without the command line: the configuration file (optional) with
/// `set` on top, the runs into `out` (resumed with `resume`), the report as JSON text.
std::string run_experiment(const std::string& db, const std::string& out, const std::string& config_file,
                           const py::dict& set, int threads, bool resume, const py::object& progress_f) {
  PyProgress progress(progress_f);
  experiments::ExperimentConfig c;
  if (!config_file.empty()) experiments::load_config_file(c, config_file);
  for (const auto& [k, v] : set) {
    const std::string key = py::str(k).cast<std::string>();
    std::vector<std::string> inputs;
    if ((py::isinstance<py::list>(v) || py::isinstance<py::tuple>(v)))
      for (const auto& x : v) inputs.push_back(value_text(x));
    else
      inputs.push_back(value_text(v));
    experiments::set_key(c, key, inputs);
  }
  experiments::validate(c, config_file);
  py::gil_scoped_release release;
  std::optional<tbb::global_control> limit;
  if (threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(threads));
  const int used = threads > 0 ? threads : static_cast<int>(tbb::global_control::active_value(
                                               tbb::global_control::max_allowed_parallelism));
  auto engine = experiments::make_recognition_engine(c, experiments::open_database(db), used);
  const io::RunStoreHeader header = engine->header();
  std::error_code ec;
  if (std::filesystem::exists(out, ec)) {
    if (!resume) throw Error("the run store already exists: continue it with resume=True, or remove it", out, "out");
    experiments::check_resumable(io::RunStore::read_header(out), header, out);
  } else {
    io::RunStore::create(out, header);
  }
  experiments::DriveSettings ds;
  ds.parallel_runs = c.schedule == "runs";
  // The progress callback, after each stored run (on a worker thread, one call at a time): what
  // it raises stops the experiment as Ctrl-C stops the command (the runs finished are stored,
  // resume=True continues) and is raised again here.
  std::atomic<bool> stop{false};
  if (progress.active()) {
    ds.stop = &stop;
    ds.on_progress = [&](const experiments::Progress& p) {
      if (!stop && !progress(p.done, p.total, p.remaining_s())) stop = true;
    };
  }
  const experiments::DriveOutcome outcome = experiments::drive(*engine, experiments::all_tasks(header, c.runs), out, ds);
  progress.raise_if_raised();
  if (outcome.interrupted) throw Error("the experiment stopped before its last run; resume=True continues it", out, "out");
  io::RunStore::compact(out, true);
  experiments::ReportSettings rs;
  rs.threads = used;
  rs.machine = experiments::machine_description();
  return experiments::report_json(io::RunStore::read(out), rs, out).dump();
}

std::string report(const std::string& store) {
  py::gil_scoped_release release;
  experiments::ReportSettings rs;
  rs.machine = experiments::machine_description();
  return experiments::report_json(io::RunStore::read(store), rs, store).dump();
}

/// A run store as arrays: runs x steps for every per-step column.
py::dict read_runs(const std::string& path) {
  io::RunStoreContents s;
  {
    py::gil_scoped_release release;
    s = io::RunStore::read(path);
  }
  const auto& h = s.header;
  const py::ssize_t R = static_cast<py::ssize_t>(s.runs.size()), S = h.steps;
  py::dict header;
  header["config"] = h.config_json;
  header["database"] = h.database_json;
  header["versions"] = h.versions_json;
  header["machine"] = h.machine;
  header["steps"] = h.steps;
  header["variants"] = h.variant_labels;
  header["objects"] = h.objects;
  header["database_objects"] = h.database_objects;
  header["stages"] = h.stages;
  header["step_values"] = h.step_values;
  header["complete"] = s.complete;

  auto ints = [&](auto get) {
    py::array_t<std::int32_t> a({R, S});
    auto w = a.mutable_unchecked<2>();
    for (py::ssize_t r = 0; r < R; ++r)
      for (py::ssize_t k = 0; k < S; ++k) w(r, k) = get(s.runs[static_cast<std::size_t>(r)].steps[static_cast<std::size_t>(k)]);
    return a;
  };
  auto reals = [&](auto get) {
    py::array_t<double> a({R, S});
    auto w = a.mutable_unchecked<2>();
    for (py::ssize_t r = 0; r < R; ++r)
      for (py::ssize_t k = 0; k < S; ++k) w(r, k) = get(s.runs[static_cast<std::size_t>(r)].steps[static_cast<std::size_t>(k)]);
    return a;
  };
  auto columns = [&](std::size_t n, auto get) {
    py::array_t<double> a({R, S, static_cast<py::ssize_t>(n)});
    auto w = a.mutable_unchecked<3>();
    for (py::ssize_t r = 0; r < R; ++r)
      for (py::ssize_t k = 0; k < S; ++k) {
        const auto& v = get(s.runs[static_cast<std::size_t>(r)].steps[static_cast<std::size_t>(k)]);
        for (std::size_t j = 0; j < n; ++j) w(r, k, static_cast<py::ssize_t>(j)) = j < v.size() ? v[j] : NAN;
      }
    return a;
  };
  using Step = io::RunStepRecord;
  py::dict steps;
  steps["best_object"] = ints([](const Step& x) { return x.best_object; });
  steps["correct"] = ints([](const Step& x) { return std::int32_t{x.correct}; }).attr("astype")("bool");
  steps["weight"] = reals([](const Step& x) { return x.weight; });
  steps["posterior_true"] = reals([](const Step& x) { return x.posterior_true; });
  steps["posterior_best"] = reals([](const Step& x) { return x.posterior_best; });
  steps["posterior_entropy"] = reals([](const Step& x) { return x.posterior_entropy; });
  steps["true_rank"] = ints([](const Step& x) { return x.true_rank; });
  steps["hypotheses"] = ints([](const Step& x) { return x.hypotheses; });
  steps["contacts"] = ints([](const Step& x) { return x.contacts; });
  steps["free_points"] = ints([](const Step& x) { return x.free_points; });
  steps["position_error_m"] = reals([](const Step& x) { return x.position_error_m; });
  steps["orientation_error_rad"] = reals([](const Step& x) { return x.orientation_error_rad; });
  steps["symmetric_orientation_error_rad"] = reals([](const Step& x) { return x.symmetric_orientation_error_rad; });
  steps["mssd_m"] = reals([](const Step& x) { return x.mssd_m; });
  steps["time_s"] = reals([](const Step& x) { return x.time_s; });
  steps["stage_times_s"] = columns(h.stages.size(), [](const Step& x) -> const std::vector<double>& { return x.stage_times_s; });
  steps["values"] = columns(h.step_values.size(), [](const Step& x) -> const std::vector<double>& { return x.values; });
  py::array_t<double> poses({R, S, py::ssize_t{4}, py::ssize_t{4}});
  auto pw = poses.mutable_unchecked<4>();
  py::array_t<double> truth({R, py::ssize_t{4}, py::ssize_t{4}});
  auto tw = truth.mutable_unchecked<3>();
  py::array_t<std::int32_t> variant(R), object(R), run(R);
  py::array_t<double> wall(R);
  for (py::ssize_t r = 0; r < R; ++r) {
    const io::RunRecord& rec = s.runs[static_cast<std::size_t>(r)];
    variant.mutable_at(r) = rec.variant;
    object.mutable_at(r) = rec.object;
    run.mutable_at(r) = rec.run;
    wall.mutable_at(r) = rec.wall_time_s;
    const Eigen::Matrix4d T = rec.truth.matrix();
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) tw(r, i, j) = T(i, j);
    for (py::ssize_t k = 0; k < S; ++k) {
      const Eigen::Matrix4d P = rec.steps[static_cast<std::size_t>(k)].pose.matrix();
      for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) pw(r, k, i, j) = P(i, j);
    }
  }
  steps["pose"] = poses;
  py::dict runs;
  runs["variant"] = variant;
  runs["object"] = object;
  runs["run"] = run;
  runs["truth"] = truth;
  runs["wall_time_s"] = wall;
  py::dict o;
  o["header"] = header;
  o["runs"] = runs;
  o["steps"] = steps;
  return o;
}

std::string parameters_json() { return experiments::parameters_json().dump(); }

std::unique_ptr<tbb::global_control> g_threads;

void set_threads(int n) {
  if (n < 0) throw py::value_error("threads must be >= 0 (0: every core)");
  g_threads.reset();
  if (n > 0) g_threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                               static_cast<std::size_t>(n));
}

}  // namespace
}  // namespace ts::python

PYBIND11_MODULE(_touchstone, m) {
  using namespace ts::python;
  m.doc() = "Touchstone's C++ library (the touchstone package wraps it)";
#ifdef TS_VERSION
  m.attr("__version__") = TS_VERSION;
#endif

  static py::exception<ts::Error> error(m, "Error", PyExc_RuntimeError);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const ts::Error& e) {
      // The message, file and field as attributes of the instance beside its text.
      py::object instance = py::reinterpret_borrow<py::object>(error.ptr())(py::str(e.what()));
      instance.attr("message") = e.message();
      instance.attr("file") = e.file();
      instance.attr("field") = e.field();
      PyErr_SetObject(error.ptr(), instance.ptr());
    }
  });

  m.def("set_threads", &set_threads, py::arg("threads"));
  m.def("parameters_json", &parameters_json);

  py::class_<PyDatabase, std::shared_ptr<PyDatabase>>(m, "Database", py::dynamic_attr(),
      "An object database (HDF5, `touchstone db build`). Geometry is loaded on demand within "
      "memory_budget_mb (None: the default, 256 MB; 0: no limit), evicted least-recently-used.")
      .def(py::init(&open_database), py::arg("path"), py::arg("memory_budget_mb") = py::none())
      .def_readonly("path", &PyDatabase::path)
      .def("__len__", [](const PyDatabase& d) { return d.db->size(); })
      .def_property_readonly("objects",
                             [](const PyDatabase& d) {
                               std::vector<std::string> names;
                               for (std::size_t i = 0; i < d.db->size(); ++i) names.push_back(d.db->info(i).name);
                               return names;
                             })
      .def("index", [](const PyDatabase& d, const std::string& name) { return d.index(py::str(name)); }, py::arg("name"))
      .def("object_info", [](const PyDatabase& d, const py::object& key) { return object_info(d, d.index(key)); },
           py::arg("object"))
      .def("points", &object_points, py::arg("object"), py::arg("cloud") = "fine",
           "An object's stored points, N x 3, object frame, m: cloud \"fine\" (the scanner's) or \"coarse\" "
           "(the feature points)")
      .def("normals", &object_normals, py::arg("object"), py::arg("cloud") = "fine",
           "The unit outward normals of points(object, cloud), row for row")
      .def("mesh", &object_mesh, py::arg("object"),
           "(vertices V x 3 float64, faces F x 3 int64): the object-frame mesh, m")
      .def("distance", &object_distance, py::arg("object"), py::arg("points"),
           "The object's distance field at N x 3 object-frame points (m; negative inside a closed "
           "mesh; far from the surface a lower bound)")
      .def_property_readonly("settings", [](const PyDatabase& d) {
        py::dict o;
        for (const auto& v : ts::io::settings_values(d.db->settings()))
          o[py::str(v.group.empty() ? v.name : v.group + "." + v.name)] = v.value;
        o["descriptor"] = ts::descriptor_name(d.db->settings().descriptor);
        return o;
      });

  py::class_<PyLog>(m, "TactileLog",
      "A tactile log (io/FORMAT_LOG.md): per grasp the measured arm pose, finger joints and tactile "
      "images; a simulated log also holds its ground truth (truth_pose).")
      .def_property_readonly("object", [](const PyLog& l) { return l.log->object; })
      .def_property_readonly("noise", [](const PyLog& l) { return l.log->noise; })
      .def_property_readonly("seed", [](const PyLog& l) { return l.log->seed; })
      .def_property_readonly("sensing", [](const PyLog& l) { return std::string(ts::to_string(l.log->sensing)); })
      .def_property_readonly("pads", [](const PyLog& l) { return l.log->pads.size(); })
      .def("__len__", [](const PyLog& l) { return l.log->grasps.size(); })
      .def_property_readonly("truth_pose", &truth_pose)
      .def("arm_poses", &arm_poses)
      .def("write", [](const PyLog& l, const std::string& path) {
        py::gil_scoped_release release;
        ts::io::write_log(path, *l.log);
      }, py::arg("path"));
  m.def("read_log", [](const std::string& path) {
    PyLog l;
    py::gil_scoped_release release;
    l.log = std::make_shared<ts::TactileLog>(ts::io::read_log(path));
    return l;
  }, py::arg("path"));
  m.def("simulate", &simulate, py::arg("db"), py::arg("object"), py::arg("grasps") = 20,
        py::arg("noise") = "underwater", py::arg("sensors") = 1, py::arg("seed") = 1, py::arg("params") = py::dict());

  py::class_<PyExploration>(m, "Exploration",
      "The fused clouds of a log step by step (the recognizer's inputs, as `touchstone recognize` "
      "fuses them): contacts() N x 3, free() M x 3, grasps() the contacts by grasp, hand_free() the points each grasp's hand held free, pivots() G x 3; world frame, metres.")
      .def(py::init<PyLog, const PyDatabase&, double, std::optional<double>>(), py::arg("log"), py::arg("db"),
           py::arg("contact_voxel_m") = 0.002, py::arg("res_free_m") = py::none())
      .def("advance_to", &PyExploration::advance_to, py::arg("steps"))
      .def_property_readonly("steps", &PyExploration::steps)
      .def("contacts", &PyExploration::contacts)
      .def("free", &PyExploration::free)
      .def("grasps", &PyExploration::grasps)
      .def("hand_free", &PyExploration::hand_free)
      .def("pivots", &PyExploration::pivots);

  py::class_<PyRecognizer>(m, "Recognizer", "The C++ recognizer (touchstone.Recognizer wraps it).")
      .def(py::init<std::shared_ptr<PyDatabase>, const std::string&, const std::string&, std::uint64_t,
                    const py::dict&, const std::optional<std::vector<std::string>>&, const std::optional<std::string>&,
                    const std::optional<double>&, bool>(),
           py::arg("db"), py::arg("preset") = "improved", py::arg("method") = "bricpsf", py::arg("seed") = 1,
           py::arg("params") = py::dict(), py::arg("only") = py::none(), py::arg("calibration") = py::none(),
           py::arg("alpha") = py::none(), py::arg("explain") = false)
      .def("step", &PyRecognizer::step, py::arg("contacts"), py::arg("free") = py::none(),
           py::arg("grasps") = py::none(), py::arg("hand_free") = py::none(), py::arg("pivots") = py::none())
      .def("recognize_log", &PyRecognizer::recognize_log, py::arg("log"), py::arg("steps") = 0)
      .def("reset", &PyRecognizer::reset)
      .def_property_readonly("settings", &PyRecognizer::settings)
      .def_property_readonly("hypotheses", &PyRecognizer::hypotheses);

  m.def("run_experiment_json", &run_experiment, py::arg("db"), py::arg("out"), py::arg("config") = "",
        py::arg("set") = py::dict(), py::arg("threads") = 0, py::arg("resume") = false,
        py::arg("progress") = py::none());
  m.def("build_database_impl", &build_database, py::arg("out"), py::arg("inputs"), py::arg("manifest"),
        py::arg("folder"), py::arg("params"), py::arg("scale"), py::arg("units"), py::arg("seed"),
        py::arg("congruence_tolerance"), py::arg("threads"), py::arg("progress"));
  m.def("report_json", &report, py::arg("store"));
  m.def("read_runs", &read_runs, py::arg("path"));
}
