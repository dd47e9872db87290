#include "io/gripper_io.hpp"

#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

namespace ts::io {

namespace {
using json = nlohmann::json;
using ojson = nlohmann::ordered_json;
constexpr double kDeg = std::numbers::pi / 180.0;

// Field access with the JSON path in every error.
class Reader {
 public:
  Reader(const json& j, std::string path, const std::string& file) : j_(j), path_(std::move(path)), file_(file) {}

  [[noreturn]] void fail(const std::string& what, const std::string& key = {}) const {
    throw Error(what, file_, key.empty() ? path_ : sub(key));
  }
  std::string sub(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }
  bool has(const std::string& key) const { return j_.is_object() && j_.contains(key) && !j_.at(key).is_null(); }
  Reader child(const std::string& key) const {
    if (!has(key)) fail("missing field", key);
    return Reader(j_.at(key), sub(key), file_);
  }
  Reader at(std::size_t i) const { return Reader(j_.at(i), path_ + "[" + std::to_string(i) + "]", file_); }
  std::size_t size() const {
    if (!j_.is_array()) fail("expected an array");
    return j_.size();
  }
  double number(const std::string& key) const {
    const Reader r = child(key);
    if (!r.j_.is_number()) fail("expected a number", key);
    const double v = r.j_.get<double>();
    if (!std::isfinite(v)) fail("expected a finite number", key);
    return v;
  }
  double number(const std::string& key, double fallback) const { return has(key) ? number(key) : fallback; }
  int integer(const std::string& key, int fallback) const {
    if (!has(key)) return fallback;
    const json& v = j_.at(key);
    if (!v.is_number_integer()) fail("expected an integer", key);
    return v.get<int>();
  }
  std::string text(const std::string& key) const {
    const Reader r = child(key);
    if (!r.j_.is_string()) fail("expected a string", key);
    return r.j_.get<std::string>();
  }
  std::string text(const std::string& key, const std::string& fallback) const {
    return has(key) ? text(key) : fallback;
  }
  std::vector<double> numbers(const std::string& key, std::size_t n) const {
    const Reader r = child(key);
    if (!r.j_.is_array() || r.j_.size() != n) fail("expected an array of " + std::to_string(n) + " numbers", key);
    std::vector<double> out;
    for (const auto& v : r.j_) {
      if (!v.is_number() || !std::isfinite(v.get<double>())) fail("expected an array of finite numbers", key);
      out.push_back(v.get<double>());
    }
    return out;
  }
  Vec3 vec3(const std::string& key) const {
    const auto v = numbers(key, 3);
    return {v[0], v[1], v[2]};
  }
  Pose pose() const {
    Pose T = Pose::Identity();
    T.translation() = vec3("t_m");
    if (has("q_wxyz")) {
      const auto q = numbers("q_wxyz", 4);
      Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
      if (quat.norm() < 1e-9) fail("quaternion must not be zero", "q_wxyz");
      T.linear() = quat.normalized().toRotationMatrix();
    } else {
      const Vec3 rpy = vec3("rpy_deg") * kDeg;
      T.linear() = (Eigen::AngleAxisd(rpy.z(), Vec3::UnitZ()) * Eigen::AngleAxisd(rpy.y(), Vec3::UnitY()) *
                    Eigen::AngleAxisd(rpy.x(), Vec3::UnitX()))
                       .toRotationMatrix();
    }
    return T;
  }
  const json& raw() const { return j_; }
  const std::string& path() const { return path_; }

 private:
  const json& j_;
  std::string path_;
  const std::string& file_;
};

double clean(double v) {
  const double r = std::round(v * 1e9) / 1e9;
  return r == 0.0 ? 0.0 : r;  // no "-0"
}

ojson vec_json(const Vec3& v) { return ojson::array({clean(v.x()), clean(v.y()), clean(v.z())}); }

ojson pose_json(const Pose& T) {
  const Mat3 R = T.linear();
  double roll = 0, pitch = std::asin(std::clamp(-R(2, 0), -1.0, 1.0)), yaw = 0;
  if (std::abs(std::cos(pitch)) > 1e-9) {
    roll = std::atan2(R(2, 1), R(2, 2));
    yaw = std::atan2(R(1, 0), R(0, 0));
  } else {
    yaw = std::atan2(-R(0, 1), R(1, 1));
  }
  ojson j;
  j["t_m"] = vec_json(T.translation());
  j["rpy_deg"] = vec_json(Vec3(roll, pitch, yaw) / kDeg);
  return j;
}
}  // namespace

Gripper parse_gripper(const std::string& text, const std::string& file) {
  json doc;
  try {
    doc = json::parse(text);
  } catch (const json::parse_error& e) {
    throw Error("gripper description does not parse as JSON: " + std::string(e.what()), file,
                "byte " + std::to_string(e.byte));
  } catch (const json::exception& e) {   // a number beyond double's range ("1E999"): out_of_range.406
    throw Error("gripper description does not parse as JSON: " + std::string(e.what()), file);
  }
  if (!doc.is_object()) throw Error("gripper description must be a JSON object", file);
  const Reader root(doc, "", file);
  if (root.has("format") && root.text("format") != "touchstone-gripper")
    root.fail("unknown format '" + root.text("format") + "'", "format");
  if (root.integer("version", 1) != 1) root.fail("unsupported version", "version");

  GripperSpec g;
  g.fingers.clear();
  g.name = root.text("name");
  g.single_pad = root.text("single_pad", g.single_pad);
  if (root.has("palm")) {
    const Reader p = root.child("palm");
    g.palm.radius = p.number("radius_m");
    g.palm.thickness = p.number("thickness_m");
  }
  if (root.has("sensor")) {
    const Reader s = root.child("sensor");
    SensorSettings& o = g.sensor;
    o.rows = s.integer("rows", o.rows);
    o.cols = s.integer("cols", o.cols);
    if (s.has("pitch_m")) {
      const auto v = s.numbers("pitch_m", 2);
      o.pitch_x = v[0], o.pitch_y = v[1];
    }
    if (s.has("size_m")) {
      const auto v = s.numbers("size_m", 2);
      o.size_x = v[0], o.size_y = v[1];
    }
    o.foam_thickness = s.number("foam_thickness_m", o.foam_thickness);
    if (s.has("response")) {
      const Reader r = s.child("response");
      o.knee_compression = r.number("knee", o.knee_compression);
      o.peak_compression = r.number("peak", o.peak_compression);
      o.end_response = r.number("end", o.end_response);
    }
    o.signal_peak = s.number("signal_peak", o.signal_peak);
    o.signal_full_scale = s.number("signal_full_scale", o.signal_full_scale);
    o.threshold = s.number("threshold", o.threshold);
  }
  const Reader fingers = root.child("fingers");
  for (std::size_t f = 0; f < fingers.size(); ++f) {
    const Reader fr = fingers.at(f);
    FingerSpec finger;
    finger.name = fr.text("name");
    finger.T_eef_base = fr.child("base").pose();
    const Reader links = fr.child("links");
    double parent_length = 0.0;
    for (std::size_t k = 0; k < links.size(); ++k) {
      const Reader lr = links.at(k);
      LinkSpec l;
      l.name = lr.text("name");
      l.length = lr.number("length_m");
      l.width = lr.number("width_m");
      l.thickness = lr.number("thickness_m");
      const Reader jr = lr.child("joint");
      l.joint_origin = jr.has("origin_m") ? jr.vec3("origin_m") : Vec3(0, 0, parent_length);
      l.joint_axis = jr.vec3("axis");
      if (l.joint_axis.norm() < 1e-9) jr.fail("joint axis must not be zero", "axis");
      l.joint_axis.normalize();
      l.open = jr.number("open_deg") * kDeg;
      l.min = jr.number("min_deg") * kDeg;
      l.max = jr.number("max_deg") * kDeg;
      l.has_pad = lr.has("pad");
      if (l.has_pad) l.T_link_pad = lr.child("pad").pose();
      parent_length = l.length;
      finger.links.push_back(l);
    }
    g.fingers.push_back(finger);
  }
  return Gripper(std::move(g), file);
}

Gripper read_gripper(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error("cannot open gripper description", path.string());
  std::ostringstream ss;
  ss << in.rdbuf();
  return parse_gripper(ss.str(), path.string());
}

std::string gripper_to_json(const GripperSpec& g) {
  ojson j;
  j["format"] = "touchstone-gripper";
  j["version"] = 1;
  j["name"] = g.name;
  j["palm"] = {{"radius_m", clean(g.palm.radius)}, {"thickness_m", clean(g.palm.thickness)}};
  j["single_pad"] = g.single_pad;
  const SensorSettings& s = g.sensor;
  ojson sensor;
  sensor["rows"] = s.rows;
  sensor["cols"] = s.cols;
  sensor["pitch_m"] = {clean(s.pitch_x), clean(s.pitch_y)};
  sensor["size_m"] = {clean(s.size_x), clean(s.size_y)};
  sensor["foam_thickness_m"] = clean(s.foam_thickness);
  sensor["response"] = {{"knee", clean(s.knee_compression)}, {"peak", clean(s.peak_compression)},
                        {"end", clean(s.end_response)}};
  sensor["signal_peak"] = clean(s.signal_peak);
  sensor["signal_full_scale"] = clean(s.signal_full_scale);
  sensor["threshold"] = clean(s.threshold);
  j["sensor"] = sensor;
  ojson fingers = ojson::array();
  for (const auto& f : g.fingers) {
    ojson fj;
    fj["name"] = f.name;
    fj["base"] = pose_json(f.T_eef_base);
    ojson links = ojson::array();
    for (const auto& l : f.links) {
      ojson lj;
      lj["name"] = l.name;
      lj["length_m"] = clean(l.length);
      lj["width_m"] = clean(l.width);
      lj["thickness_m"] = clean(l.thickness);
      lj["joint"] = {{"origin_m", vec_json(l.joint_origin)}, {"axis", vec_json(l.joint_axis)},
                     {"open_deg", clean(l.open / kDeg)}, {"min_deg", clean(l.min / kDeg)},
                     {"max_deg", clean(l.max / kDeg)}};
      lj["pad"] = l.has_pad ? pose_json(l.T_link_pad) : ojson(nullptr);
      links.push_back(lj);
    }
    fj["links"] = links;
    fingers.push_back(fj);
  }
  j["fingers"] = fingers;
  return j.dump(2) + "\n";
}

}  // namespace ts::io
