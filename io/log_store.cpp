#include "io/log_store.hpp"

#include "io/pose_row.hpp"

#include "io/atomic_file.hpp"
#include "io/gripper_io.hpp"
#include "io/h5.hpp"

#include <cmath>
#include <cstring>

namespace ts::io {

namespace {
using h5::kAny;

std::string indexed(const std::string& path, std::size_t i) {
  std::string s = path;
  s += '[';
  s += std::to_string(i);
  s += ']';
  return s;
}

h5::Storage chunks(std::uint64_t rows, int deflate = 0) {
  h5::Storage s;
  s.chunk_rows = rows;
  s.deflate = deflate;
  return s;
}

std::uint64_t seed_from_attr(std::int64_t v) {
  std::uint64_t u;
  std::memcpy(&u, &v, sizeof u);
  return u;
}
std::int64_t seed_to_attr(std::uint64_t u) {
  std::int64_t v;
  std::memcpy(&v, &u, sizeof v);
  return v;
}

struct Dims {
  std::uint64_t pads, rows, cols, joints;
};
Dims dims_of(const LogHeader& h) {
  if (h.sensing == Sensing::probe) return {0, 0, 0, 0};
  if (h.sensing == Sensing::fingertips) return {0, 0, 0, static_cast<std::uint64_t>(h.gripper.joint_count())};
  return {h.pads.size(), static_cast<std::uint64_t>(h.gripper.sensor().rows),
          static_cast<std::uint64_t>(h.gripper.sensor().cols),
          static_cast<std::uint64_t>(h.gripper.joint_count())};
}

bool probe_log(const LogHeader& h) { return h.sensing == Sensing::probe; }
bool fingertip_log(const LogHeader& h) { return h.sensing == Sensing::fingertips; }

constexpr std::uint64_t kMaxSupportVertices = 10'000'000;

constexpr std::int64_t kMaxNeighbours = 64;

// A world-frame mesh of the ground truth (`path`: its group), sizes checked before reading.
Mesh read_truth_mesh(const h5::Group& g, const std::string& name, const std::string& path) {
  const h5::Shape vs = g.shape("vertices"), fs = g.shape("faces");
  if (vs.size() != 2 || vs[1] != 3 || vs[0] < 3 || vs[0] > kMaxSupportVertices)
    throw Error("must be [V, 3] with 3 <= V <= 10^7", name, path + "/vertices");
  if (fs.size() != 2 || fs[1] != 3 || fs[0] < 1 || fs[0] > 2 * kMaxSupportVertices)
    throw Error("must be [F, 3] with 1 <= F <= 2 x 10^7", name, path + "/faces");
  const auto v = g.read<double>("vertices", {kAny, 3});
  const auto f = g.read<std::int32_t>("faces", {kAny, 3});
  Mesh m;
  for (std::size_t i = 0; i < v.size(); i += 3) {
    m.vertices.emplace_back(v[i], v[i + 1], v[i + 2]);
    if (!m.vertices.back().allFinite()) throw Error("not finite", name, indexed(path + "/vertices", i / 3));
  }
  for (std::size_t i = 0; i < f.size(); i += 3) {
    for (std::size_t k = 0; k < 3; ++k)
      if (f[i + k] < 0 || static_cast<std::uint64_t>(f[i + k]) >= vs[0])
        throw Error("vertex index out of range", name, indexed(path + "/faces", i / 3));
    m.faces.emplace_back(f[i], f[i + 1], f[i + 2]);
  }
  return m;
}

void write_truth_mesh(h5::Group& g, const Mesh& m) {
  std::vector<double> v;
  for (const Vec3& x : m.vertices) v.insert(v.end(), {x[0], x[1], x[2]});
  std::vector<std::int32_t> f;
  for (const auto& t : m.faces) f.insert(f.end(), {t[0], t[1], t[2]});
  g.write("vertices", v.data(), {m.vertices.size(), 3});
  g.write("faces", f.data(), {m.faces.size(), 3});
}

// /ground_truth/support: the scene's name and its support mesh.
void read_support(const h5::Group& g, const std::string& name, LogHeader& h) {
  if (!g.has_attribute("scene")) throw Error("missing attribute", name, "/ground_truth/support/scene");
  h.true_scene = g.string_attribute("scene");
  if (h.true_scene.empty() || h.true_scene == "none" || h.true_scene.size() > 64)
    throw Error("must name the scene (not empty or \"none\", at most 64 characters)", name,
                "/ground_truth/support/scene");
  h.true_support = read_truth_mesh(g, name, "/ground_truth/support");
}

void write_support(h5::Group& truth, const LogHeader& h) {
  h5::Group g = truth.create_group("support");
  g.set_attribute("scene", h.true_scene);
  write_truth_mesh(g, h.true_support);
}

// /ground_truth/neighbours: attribute count, then groups 0 .. count - 1, each with its object's
// name (attribute), pose [7] and world-frame mesh.
void read_neighbours(const h5::Group& g, const std::string& name, LogHeader& h) {
  if (!g.has_attribute("count")) throw Error("missing attribute", name, "/ground_truth/neighbours/count");
  const std::int64_t count = g.int_attribute("count");
  if (count < 1 || count > kMaxNeighbours)
    throw Error("must lie in [1, 64]", name, "/ground_truth/neighbours/count");
  for (std::int64_t k = 0; k < count; ++k) {
    const std::string path = "/ground_truth/neighbours/" + std::to_string(k);
    if (!g.has_group(std::to_string(k))) throw Error("missing group", name, path);
    const h5::Group n = g.open_group(std::to_string(k));
    if (!n.has_attribute("object")) throw Error("missing attribute", name, path + "/object");
    LogGroundTruth::Neighbour x;
    x.name = n.string_attribute("object");
    if (x.name.empty() || x.name.size() > 256) throw Error("must name the object (1 to 256 characters)", name, path + "/object");
    const auto row = n.read<double>("pose", {7});
    x.pose = checked_pose_from_row(row.data(), name, path + "/pose");
    x.mesh = read_truth_mesh(n, name, path);
    h.true_neighbours.push_back(std::move(x));
  }
}

void write_neighbours(h5::Group& truth, const LogHeader& h) {
  h5::Group g = truth.create_group("neighbours");
  g.set_attribute("count", static_cast<std::int64_t>(h.true_neighbours.size()));
  for (std::size_t k = 0; k < h.true_neighbours.size(); ++k) {
    const LogGroundTruth::Neighbour& x = h.true_neighbours[k];
    h5::Group n = g.create_group(std::to_string(k));
    n.set_attribute("object", x.name);
    const auto row = pose_row(x.pose);
    n.write("pose", row.data(), {7});
    write_truth_mesh(n, x.mesh);
  }
}

// Header: root attributes, /gripper, /sensors and (structure of) /ground_truth.
LogHeader read_header(const h5::File& file) {
  const std::string name = file.name();
  const h5::Group root = file.root();
  if (!root.has_attribute("format") || root.string_attribute("format") != kLogFormat)
    throw Error("not a Touchstone tactile log (attribute format != \"" + std::string(kLogFormat) + "\")",
                name, "/format");
  const std::int64_t version = root.int_attribute("format_version");
  if (version < 1 || version > kLogFormatVersion)
    throw Error("unsupported log format_version " + std::to_string(version), name, "/format_version");
  LogHeader h;
  h.object = root.has_attribute("object") ? root.string_attribute("object") : "";
  h.noise = root.has_attribute("noise") ? root.string_attribute("noise") : "real";
  h.seed = root.has_attribute("seed") ? seed_from_attr(root.int_attribute("seed")) : 0;
  h.source = root.has_attribute("source") ? root.string_attribute("source") : "";

  const auto desc = file.group("gripper").read_strings("description");
  if (desc.size() != 1) throw Error("expected one gripper description string", name, "/gripper/description");
  try {
    h.gripper = parse_gripper(desc[0], name);
  } catch (const Error& e) {
    throw Error("gripper description: " + e.message(), name, "/gripper/description " + e.field());
  }
  if (root.has_attribute("sensing"))
    h.sensing = parse_sensing(root.string_attribute("sensing"), name, "/sensing");
  if (probe_log(h)) {
    if (version < 2) throw Error("a probe log needs format_version 2", name, "/format_version");
    const h5::Group probe = file.group("probe");
    for (const char* a : {"ball_radius", "shaft_radius"})
      if (!probe.has_attribute(a)) throw Error("missing attribute", name, std::string("/probe/") + a);
    h.probe.ball_radius = probe.double_attribute("ball_radius");
    h.probe.shaft_radius = probe.double_attribute("shaft_radius");
  } else if (fingertip_log(h)) {
    if (version < 3) throw Error("a fingertip log needs format_version 3", name, "/format_version");
    const h5::Group tips = file.group("fingertips");
    if (!tips.has_attribute("normals")) throw Error("missing attribute", name, "/fingertips/normals");
    const std::int64_t normals = tips.int_attribute("normals");
    if (normals != 0 && normals != 1) throw Error("must be 0 or 1", name, "/fingertips/normals");
    h.fingertip_normals = normals == 1;
  } else {
    const SensorSettings& s = h.gripper.sensor();
    const h5::Group sensors = file.group("sensors");
    const auto pads = sensors.read<std::int32_t>("pad_index", {kAny});
    h.pads.assign(pads.begin(), pads.end());
    const auto P = static_cast<std::int64_t>(h.pads.size());
    h.gains = sensors.read<float>("gain", {P, s.rows, s.cols});
  }
  if (root.has_group("ground_truth")) {
    const h5::Group truth = file.group("ground_truth");
    const auto row = truth.read<double>("object_pose", {7});
    h.true_object_pose = checked_pose_from_row(row.data(), name, "/ground_truth/object_pose");
    if (truth.has_group("support")) {
      if (version < 4) throw Error("a log with a scene's support needs format_version 4", name, "/format_version");
      read_support(truth.open_group("support"), name, h);
    }
    if (truth.has_group("neighbours")) {
      if (version < 5) throw Error("a log with a scene's neighbours needs format_version 5", name, "/format_version");
      if (!truth.has_group("support"))
        throw Error("neighbours lie on a scene's support: /ground_truth/support is missing", name,
                    "/ground_truth/neighbours");
      read_neighbours(truth.open_group("neighbours"), name, h);
    }
  }
  // The header must already be consistent (pads exist, gains positive).
  validate(log_of(h), name);
  return h;
}
}  // namespace

/// The fields a log's header and the log share.
template <class From, class To>
void copy_header(const From& from, To& to) {
  to.object = from.object;
  to.noise = from.noise;
  to.seed = from.seed;
  to.gripper = from.gripper;
  to.pads = from.pads;
  to.gains = from.gains;
  to.sensing = from.sensing;
  to.probe = from.probe;
  to.fingertip_normals = from.fingertip_normals;
}

TactileLog log_of(const LogHeader& h) {
  TactileLog log;
  copy_header(h, log);
  return log;
}

LogHeader header_of(const TactileLog& log) {
  LogHeader h;
  copy_header(log, h);
  if (log.truth) {
    h.true_object_pose = log.truth->object_pose;
    h.true_scene = log.truth->scene;
    h.true_support = log.truth->support;
    h.true_neighbours = log.truth->neighbours;
  }
  return h;
}

struct LogWriter::Impl {
  std::optional<AtomicOutput> atomic;
  h5::File file;
  LogHeader header;
  TactileLog shape;   // header as a log (for per-grasp validation)
  std::size_t grasps = 0;
  std::string display;
};

LogWriter::LogWriter() : impl_(std::make_unique<Impl>()) {}
LogWriter::LogWriter(LogWriter&&) noexcept = default;
LogWriter& LogWriter::operator=(LogWriter&&) noexcept = default;
LogWriter::~LogWriter() {
  if (!impl_ || !impl_->file.is_open()) return;
  try {
    // An atomic log that was not closed explicitly is abandoned (the temporary is removed).
    impl_->file.close();
  } catch (...) {
  }
}

LogWriter LogWriter::create(const std::filesystem::path& path, const LogHeader& header, bool atomic) {
  LogWriter w;
  Impl& m = *w.impl_;
  m.display = path.string();
  m.header = header;
  m.shape = log_of(header);
  validate(m.shape, m.display);
  const bool scene = header.true_object_pose && !header.true_support.faces.empty();
  if (!header.true_support.faces.empty() && !header.true_object_pose)
    throw Error("a scene's support is ground truth: the log needs the true object pose", m.display,
                "/ground_truth/support");
  if (!header.true_neighbours.empty() && !scene)
    throw Error("a scene's neighbours lie on its support: the log needs the support and the true object pose",
                m.display, "/ground_truth/neighbours");
  if (header.true_neighbours.size() > static_cast<std::size_t>(kMaxNeighbours))
    throw Error("at most 64 neighbours", m.display, "/ground_truth/neighbours");
  if (scene && (header.true_scene.empty() || header.true_scene == "none"))
    throw Error("a support needs its scene's name", m.display, "/ground_truth/support/scene");
  if (scene && probe_log(header))
    throw Error("a probe log cannot store a scene (scene needs sensing = pads or fingertips)", m.display, "scene");
  if (atomic) {
    m.atomic.emplace(path);
    m.file = h5::File::create(*m.atomic);
  } else {
    m.file = h5::File::create(path);
  }
  const Dims d = dims_of(header);
  std::lock_guard lock(h5::mutex());
  h5::Group root = m.file.root();
  root.set_attribute("format", kLogFormat);
  root.set_attribute("format_version",
                     static_cast<std::int64_t>(scene && !header.true_neighbours.empty() ? 5
                                               : scene                                  ? 4
                                               : fingertip_log(header)                  ? 3
                                               : probe_log(header)                      ? 2
                                                                                        : 1));
  root.set_attribute("object", header.object);
  root.set_attribute("noise", header.noise);
  root.set_attribute("seed", seed_to_attr(header.seed));
  root.set_attribute("source", header.source);
  root.create_group("gripper").write_strings("description", {gripper_to_json(header.gripper.spec())});
  if (probe_log(header)) {
    root.set_attribute("sensing", to_string(header.sensing));
    h5::Group probe = root.create_group("probe");
    probe.set_attribute("ball_radius", header.probe.ball_radius);
    probe.set_attribute("shaft_radius", header.probe.shaft_radius);
    h5::Group grasps = root.create_group("grasps");
    grasps.create_extendible<double>("time", {}, chunks(256));
    grasps.create_extendible<double>("arm_pose", {7}, chunks(256));
    grasps.create_extendible<double>("probe_travel", {}, chunks(256));
    grasps.create_extendible<std::uint8_t>("probe_touched", {}, chunks(256));
    if (header.true_object_pose) {
      h5::Group truth = root.create_group("ground_truth");
      const auto row = pose_row(*header.true_object_pose);
      truth.write("object_pose", row.data(), {7});
      truth.create_extendible<double>("arm_pose", {7}, chunks(256));
    }
    return w;
  }
  // Pads and fingertips: the hand's arm pose and joints per grasp, then what it sensed.
  const bool tips = fingertip_log(header);
  if (tips) {
    root.set_attribute("sensing", to_string(header.sensing));
    root.create_group("fingertips").set_attribute("normals", static_cast<std::int64_t>(header.fingertip_normals));
  } else {
    h5::Group sensors = root.create_group("sensors");
    std::vector<std::int32_t> pads(header.pads.begin(), header.pads.end());
    sensors.write("pad_index", pads);
    std::vector<std::string> names;
    for (int p : header.pads) names.push_back(header.gripper.pads()[p].name);
    sensors.write_strings("pad_name", names);
    sensors.write("gain", header.gains.data(), {d.pads, d.rows, d.cols});
  }
  h5::Group grasps = root.create_group("grasps");
  grasps.create_extendible<double>("time", {}, chunks(256));
  grasps.create_extendible<double>("arm_pose", {7}, chunks(256));
  grasps.create_extendible<double>("joints", {d.joints}, chunks(256));
  if (tips) {
    const auto F = static_cast<std::uint64_t>(header.gripper.finger_count());
    grasps.create_extendible<std::uint8_t>("fingertip_touched", {F}, chunks(256));
    grasps.create_extendible<double>("fingertip_point", {F, 3}, chunks(256));
    if (header.fingertip_normals) grasps.create_extendible<double>("fingertip_normal", {F, 3}, chunks(256));
  } else {
    grasps.create_extendible<float>("tactile", {d.pads, d.rows, d.cols}, chunks(32, 4));
    grasps.create_extendible<std::uint8_t>("past_peak", {d.pads, d.rows, d.cols}, chunks(32, 4));
  }
  if (header.true_object_pose) {
    h5::Group truth = root.create_group("ground_truth");
    const auto row = pose_row(*header.true_object_pose);
    truth.write("object_pose", row.data(), {7});
    truth.create_extendible<double>("arm_pose", {7}, chunks(256));
    truth.create_extendible<double>("joints", {d.joints}, chunks(256));
    if (scene) write_support(truth, header);
    if (scene && !header.true_neighbours.empty()) write_neighbours(truth, header);
  }
  return w;
}

LogWriter LogWriter::append_to(const std::filesystem::path& path) {
  LogWriter w;
  Impl& m = *w.impl_;
  m.display = path.string();
  m.file = h5::File::open(path, h5::File::Access::read_write);
  std::lock_guard lock(h5::mutex());
  m.header = read_header(m.file);
  m.shape = log_of(m.header);
  const h5::Group grasps = m.file.group("grasps");
  m.grasps = grasps.shape("time").at(0);
  std::vector<const char*> row_sets{"arm_pose", "joints", "tactile", "past_peak"};
  if (probe_log(m.header)) row_sets = {"arm_pose", "probe_travel", "probe_touched"};
  if (fingertip_log(m.header)) {
    row_sets = {"arm_pose", "joints", "fingertip_touched", "fingertip_point"};
    if (m.header.fingertip_normals) row_sets.push_back("fingertip_normal");
  }
  for (const char* name : row_sets)
    if (grasps.shape(name).at(0) != m.grasps)
      throw Error("dataset has " + std::to_string(grasps.shape(name).at(0)) + " rows but /grasps/time has " +
                      std::to_string(m.grasps) + " (interrupted append?)",
                  m.display, std::string("/grasps/") + name);
  return w;
}

const LogHeader& LogWriter::header() const { return impl_->header; }
std::size_t LogWriter::grasps() const { return impl_->grasps; }

void LogWriter::append(const GraspRecord& grasp, const Pose* truth_arm_pose,
                       const std::vector<double>* truth_joints) {
  Impl& m = *impl_;
  if (!m.file.is_open()) throw Error("log writer is closed", m.display);
  validate_grasp(m.shape, grasp, m.grasps, m.display);
  const bool has_truth = m.header.true_object_pose.has_value();
  if (has_truth != (truth_arm_pose != nullptr))
    throw Error(has_truth ? "this log has a ground-truth group: the true arm pose is required"
                          : "this log has no ground-truth group",
                m.display, "/ground_truth/arm_pose");
  const Dims d = dims_of(m.header);
  if (truth_arm_pose) {
    if (!truth_arm_pose->matrix().allFinite())
      throw Error("true arm pose is not finite", m.display, indexed("/ground_truth/arm_pose", m.grasps));
    if (!probe_log(m.header) && (!truth_joints || truth_joints->size() != d.joints))
      throw Error("true joint angles are required, one per joint", m.display,
                  indexed("/ground_truth/joints", m.grasps));
  }
  std::lock_guard lock(h5::mutex());
  h5::Group root = m.file.root();
  h5::Group g = root.open_group("grasps");
  g.append("time", &grasp.time, 1);
  const auto pose = pose_row(grasp.arm_pose);
  g.append("arm_pose", pose.data(), 1);
  if (probe_log(m.header)) {
    g.append("probe_travel", &grasp.probe_travel, 1);
    const std::uint8_t touched = grasp.probe_touched ? 1 : 0;
    g.append("probe_touched", &touched, 1);
    if (truth_arm_pose) {
      const auto row = pose_row(*truth_arm_pose);
      root.open_group("ground_truth").append("arm_pose", row.data(), 1);
    }
    ++m.grasps;
    return;
  }
  g.append("joints", grasp.joints.data(), 1);
  if (fingertip_log(m.header)) {
    g.append("fingertip_touched", grasp.fingertip_touched.data(), 1);
    auto flat = [](const std::vector<Vec3>& v) {
      std::vector<double> out;
      for (const Vec3& x : v) out.insert(out.end(), {x.x(), x.y(), x.z()});
      return out;
    };
    g.append("fingertip_point", flat(grasp.fingertip_points).data(), 1);
    if (m.header.fingertip_normals) g.append("fingertip_normal", flat(grasp.fingertip_normals).data(), 1);
  } else {
    g.append("tactile", grasp.tactile.data(), 1);
    std::vector<std::uint8_t> hints = grasp.past_peak;
    hints.resize(grasp.tactile.size(), 0);
    g.append("past_peak", hints.data(), 1);
  }
  if (truth_arm_pose) {
    h5::Group t = root.open_group("ground_truth");
    const auto row = pose_row(*truth_arm_pose);
    t.append("arm_pose", row.data(), 1);
    t.append("joints", truth_joints->data(), 1);
  }
  ++m.grasps;
}

void LogWriter::close() {
  Impl& m = *impl_;
  if (!m.file.is_open()) return;
  m.file.close();
  if (m.atomic) m.atomic->commit();
}

void write_log(const std::filesystem::path& path, const TactileLog& log) {
  validate(log, path.string());
  LogWriter w = LogWriter::create(path, header_of(log), true);
  for (std::size_t k = 0; k < log.grasps.size(); ++k) {
    if (log.truth) {
      const std::vector<double>& joints =
          log.truth->joints.empty() ? log.grasps[k].joints : log.truth->joints[k];
      w.append(log.grasps[k], &log.truth->arm_poses[k], &joints);
    } else {
      w.append(log.grasps[k]);
    }
  }
  w.close();
}

TactileLog read_log(const std::filesystem::path& path) {
  const h5::File file = h5::File::open(path, h5::File::Access::read);
  const std::string name = file.name();
  std::lock_guard lock(h5::mutex());
  const LogHeader h = read_header(file);
  TactileLog log = log_of(h);
  const Dims d = dims_of(h);
  const auto P = static_cast<std::int64_t>(d.pads), R = static_cast<std::int64_t>(d.rows),
             C = static_cast<std::int64_t>(d.cols), J = static_cast<std::int64_t>(d.joints);
  const h5::Group g = file.group("grasps");
  const auto time = g.read<double>("time", {kAny});
  const std::size_t G = time.size();
  auto rows_of = [&](const char* ds, const h5::Shape& s) {
    if (s.at(0) != G)
      throw Error("dataset has " + std::to_string(s.at(0)) + " rows but /grasps/time has " + std::to_string(G),
                  name, std::string("/grasps/") + ds);
  };
  h5::Shape s;
  const auto pose = g.read<double>("arm_pose", {kAny, 7}, &s);
  rows_of("arm_pose", s);
  if (probe_log(h)) {
    const auto travel = g.read<double>("probe_travel", {kAny}, &s);
    rows_of("probe_travel", s);
    const auto touched = g.read<std::uint8_t>("probe_touched", {kAny}, &s);
    rows_of("probe_touched", s);
    log.grasps.resize(G);
    for (std::size_t k = 0; k < G; ++k) {
      GraspRecord& r = log.grasps[k];
      r.time = time[k];
      r.arm_pose = checked_pose_from_row(&pose[7 * k], name, indexed("/grasps/arm_pose", k));
      r.probe_travel = travel[k];
      if (touched[k] > 1) throw Error("probe_touched must be 0 or 1", name, indexed("/grasps/probe_touched", k));
      r.probe_touched = touched[k] == 1;
    }
  } else {
    // Pads and fingertips: the hand's joints, then what it sensed.
    const auto joints = g.read<double>("joints", {kAny, J}, &s);
    rows_of("joints", s);
    const bool tips = fingertip_log(h);
    const auto F = static_cast<std::int64_t>(h.gripper.finger_count());
    std::vector<float> tactile;
    std::vector<std::uint8_t> hints, touched;
    std::vector<double> points, normals;
    auto rows = [&](const char* ds, auto& out, const h5::ShapeSpec& shape) {
      out = g.read<typename std::decay_t<decltype(out)>::value_type>(ds, shape, &s);
      rows_of(ds, s);
    };
    if (tips) {
      rows("fingertip_touched", touched, {kAny, F});
      rows("fingertip_point", points, {kAny, F, 3});
      if (h.fingertip_normals) rows("fingertip_normal", normals, {kAny, F, 3});
    } else {
      rows("tactile", tactile, {kAny, P, R, C});
      if (g.has_dataset("past_peak")) rows("past_peak", hints, {kAny, P, R, C});
    }
    const std::size_t image = d.pads * d.rows * d.cols, nf = static_cast<std::size_t>(F);
    log.grasps.resize(G);
    for (std::size_t k = 0; k < G; ++k) {
      GraspRecord& r = log.grasps[k];
      r.time = time[k];
      r.arm_pose = checked_pose_from_row(&pose[7 * k], name, indexed("/grasps/arm_pose", k));
      r.joints.assign(joints.begin() + k * d.joints, joints.begin() + (k + 1) * d.joints);
      if (!tips) {
        r.tactile.assign(tactile.begin() + k * image, tactile.begin() + (k + 1) * image);
        if (!hints.empty()) r.past_peak.assign(hints.begin() + k * image, hints.begin() + (k + 1) * image);
        continue;
      }
      r.fingertip_touched.assign(touched.begin() + k * nf, touched.begin() + (k + 1) * nf);
      for (std::size_t f = 0; f < nf; ++f) {
        const std::size_t i = 3 * (k * nf + f);
        r.fingertip_points.emplace_back(points[i], points[i + 1], points[i + 2]);
        if (!normals.empty()) r.fingertip_normals.emplace_back(normals[i], normals[i + 1], normals[i + 2]);
      }
    }
  }
  if (h.true_object_pose) {
    const h5::Group t = file.group("ground_truth");
    LogGroundTruth truth;
    truth.object_pose = *h.true_object_pose;
    truth.scene = h.true_scene;
    truth.support = h.true_support;
    truth.neighbours = h.true_neighbours;
    const auto tp = t.read<double>("arm_pose", {kAny, 7}, &s);
    if (s.at(0) != G)
      throw Error("ground truth has " + std::to_string(s.at(0)) + " arm poses for " + std::to_string(G) + " grasps",
                  name, "/ground_truth/arm_pose");
    for (std::size_t k = 0; k < G; ++k)
      truth.arm_poses.push_back(checked_pose_from_row(&tp[7 * k], name, indexed("/ground_truth/arm_pose", k)));
    if (t.has_dataset("joints")) {
      const auto tj = t.read<double>("joints", {kAny, J}, &s);
      if (s.at(0) != G) throw Error("ground-truth joint rows do not match the grasps", name, "/ground_truth/joints");
      for (std::size_t k = 0; k < G; ++k)
        truth.joints.emplace_back(tj.begin() + k * d.joints, tj.begin() + (k + 1) * d.joints);
    }
    log.truth = std::move(truth);
  }
  validate(log, name);
  return log;
}

}  // namespace ts::io
