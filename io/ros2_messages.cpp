#include "io/ros2_messages.hpp"

#include <bit>
#include <cmath>
#include <cstring>

namespace ts::io::ros2 {

namespace {

/// Reads CDR primitives with their alignment; errors name the message and the field.
class CdrReader {
 public:
  CdrReader(std::span<const std::uint8_t> b, const std::string& file, const std::string& what)
      : b_(b), file_(file), what_(what) {
    if (b.size() < 4) fail("shorter than its 4-byte encapsulation header", "encapsulation");
    if (b[0] != 0 || (b[1] != 0 && b[1] != 1))
      fail("encapsulation " + std::to_string(b[0]) + " " + std::to_string(b[1]) +
               " is not plain CDR (0 0: big-endian, 0 1: little-endian)", "encapsulation");
    little_ = b[1] == 1;
    pos_ = 4;
  }

  [[noreturn]] void fail(const std::string& message, const std::string& field) const {
    throw Error(message, file_, what_ + (field.empty() ? "" : ": " + field));
  }

  template <class T>
  T get(const char* field) {
    align(sizeof(T), field);
    if (remaining() < sizeof(T)) fail("the message ends inside this field", field);
    std::uint8_t raw[sizeof(T)];
    std::memcpy(raw, b_.data() + pos_, sizeof(T));
    if (little_ != (std::endian::native == std::endian::little))
      for (std::size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(raw[i], raw[sizeof(T) - 1 - i]);
    T v;
    std::memcpy(&v, raw, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  double real(const char* field) {
    const double v = get<double>(field);
    if (!std::isfinite(v)) fail("not a finite number", field);
    return v;
  }
  std::string string(const char* field) {
    const std::uint32_t n = get<std::uint32_t>(field);
    if (n > remaining()) fail("declares a string of " + std::to_string(n) + " bytes, " + std::to_string(remaining()) + " left", field);
    if (n == 0) return {};   // some writers send an empty string as a zero length
    if (b_[pos_ + n - 1] != 0) fail("the string is not terminated by a NUL", field);
    std::string s(reinterpret_cast<const char*>(b_.data() + pos_), n - 1);
    pos_ += n;
    return s;
  }
  /// A sequence's count, checked against the bytes left for elements of at least `min_size`.
  std::size_t count(std::size_t min_size, const char* field) {
    const std::uint32_t n = get<std::uint32_t>(field);
    if (min_size > 0 && n > remaining() / min_size)
      fail("declares " + std::to_string(n) + " elements, more than the " + std::to_string(remaining()) +
               " bytes left can hold", field);
    return n;
  }
  Stamp stamp() {
    Stamp s;
    s.sec = get<std::int32_t>("stamp.sec");
    s.nanosec = get<std::uint32_t>("stamp.nanosec");
    if (s.nanosec >= 1000000000u) fail("nanosec " + std::to_string(s.nanosec) + " is not below 1e9", "stamp.nanosec");
    return s;
  }
  /// Vector3/Point then Quaternion (x, y, z, w) as a rigid transform.
  Pose pose(const char* field) {
    Vec3 t;
    for (int i = 0; i < 3; ++i) t(i) = real(field);
    double q[4];
    for (double& x : q) x = real(field);
    Eigen::Quaterniond r(q[3], q[0], q[1], q[2]);
    const double n = r.norm();
    if (!(std::abs(n - 1.0) <= 1e-3))
      fail("the orientation quaternion has norm " + std::to_string(n) + ", not 1", field);
    r.normalize();
    Pose T = Pose::Identity();
    T.linear() = r.toRotationMatrix();
    T.translation() = t;
    return T;
  }
  std::size_t remaining() const { return b_.size() - pos_; }

 private:
  void align(std::size_t n, const char* field) {
    const std::size_t off = (pos_ - 4) % n;
    if (off == 0) return;
    if (remaining() < n - off) fail("the message ends inside this field", field);
    pos_ += n - off;
  }

  std::span<const std::uint8_t> b_;
  const std::string& file_;
  const std::string& what_;
  std::size_t pos_ = 0;
  bool little_ = true;
};

class CdrWriter {
 public:
  CdrWriter() : b_{0, 1, 0, 0} {}
  template <class T>
  void put(T v) {
    while ((b_.size() - 4) % sizeof(T)) b_.push_back(0);
    std::uint8_t raw[sizeof(T)];
    std::memcpy(raw, &v, sizeof(T));
    if constexpr (std::endian::native != std::endian::little)
      for (std::size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(raw[i], raw[sizeof(T) - 1 - i]);
    b_.insert(b_.end(), raw, raw + sizeof(T));
  }
  void string(const std::string& s) {
    put(static_cast<std::uint32_t>(s.size() + 1));
    b_.insert(b_.end(), s.begin(), s.end());
    b_.push_back(0);
  }
  void stamp(const Stamp& s) {
    put(s.sec);
    put(s.nanosec);
  }
  void pose(const Pose& T) {
    const Eigen::Quaterniond q(T.linear());
    for (int i = 0; i < 3; ++i) put(T.translation()(i));
    put(q.x());
    put(q.y());
    put(q.z());
    put(q.w());
  }
  std::vector<std::uint8_t> take() { return std::move(b_); }

 private:
  std::vector<std::uint8_t> b_;
};

}  // namespace

PoseStamped decode_pose_stamped(std::span<const std::uint8_t> cdr, const std::string& file, const std::string& what) {
  CdrReader r(cdr, file, what);
  PoseStamped m;
  m.stamp = r.stamp();
  m.frame_id = r.string("header.frame_id");
  m.pose = r.pose("pose");
  return m;
}

std::vector<TransformStamped> decode_tf_message(std::span<const std::uint8_t> cdr, const std::string& file,
                                                const std::string& what) {
  CdrReader r(cdr, file, what);
  // A TransformStamped is at least 8 (stamp) + 4 + 4 (two strings) + 56 (the transform) bytes.
  const std::size_t n = r.count(72, "transforms");
  std::vector<TransformStamped> out(n);
  for (TransformStamped& t : out) {
    t.stamp = r.stamp();
    t.frame_id = r.string("transforms.header.frame_id");
    t.child_frame_id = r.string("transforms.child_frame_id");
    t.transform = r.pose("transforms.transform");
  }
  return out;
}

JointState decode_joint_state(std::span<const std::uint8_t> cdr, const std::string& file, const std::string& what) {
  CdrReader r(cdr, file, what);
  JointState m;
  m.stamp = r.stamp();
  (void)r.string("header.frame_id");
  m.name.resize(r.count(4, "name"));
  for (std::string& s : m.name) s = r.string("name");
  for (auto* v : {&m.position, &m.velocity, &m.effort}) {
    const char* field = v == &m.position ? "position" : v == &m.velocity ? "velocity" : "effort";
    v->resize(r.count(8, field));
    for (double& x : *v) x = r.get<double>(field);   // velocity and effort may be NaN (unknown)
  }
  for (double x : m.position)
    if (!std::isfinite(x)) r.fail("a joint position is not finite", "position");
  return m;
}

Float32MultiArray decode_float32_multi_array(std::span<const std::uint8_t> cdr, const std::string& file,
                                             const std::string& what) {
  CdrReader r(cdr, file, what);
  Float32MultiArray m;
  m.dim.resize(r.count(12, "layout.dim"));
  for (MultiArrayDimension& d : m.dim) {
    d.label = r.string("layout.dim.label");
    d.size = r.get<std::uint32_t>("layout.dim.size");
    d.stride = r.get<std::uint32_t>("layout.dim.stride");
  }
  m.data_offset = r.get<std::uint32_t>("layout.data_offset");
  m.data.resize(r.count(4, "data"));
  for (float& x : m.data) {
    x = r.get<float>("data");
    if (!std::isfinite(x)) r.fail("a value is not finite", "data");
  }
  return m;
}

std::vector<std::uint8_t> encode_pose_stamped(const PoseStamped& m) {
  CdrWriter w;
  w.stamp(m.stamp);
  w.string(m.frame_id);
  w.pose(m.pose);
  return w.take();
}

std::vector<std::uint8_t> encode_tf_message(const std::vector<TransformStamped>& m) {
  CdrWriter w;
  w.put(static_cast<std::uint32_t>(m.size()));
  for (const TransformStamped& t : m) {
    w.stamp(t.stamp);
    w.string(t.frame_id);
    w.string(t.child_frame_id);
    w.pose(t.transform);
  }
  return w.take();
}

std::vector<std::uint8_t> encode_joint_state(const JointState& m) {
  CdrWriter w;
  w.stamp(m.stamp);
  w.string("");
  w.put(static_cast<std::uint32_t>(m.name.size()));
  for (const std::string& s : m.name) w.string(s);
  for (const auto* v : {&m.position, &m.velocity, &m.effort}) {
    w.put(static_cast<std::uint32_t>(v->size()));
    for (double x : *v) w.put(x);
  }
  return w.take();
}

std::vector<std::uint8_t> encode_float32_multi_array(const Float32MultiArray& m) {
  CdrWriter w;
  w.put(static_cast<std::uint32_t>(m.dim.size()));
  for (const MultiArrayDimension& d : m.dim) {
    w.string(d.label);
    w.put(d.size);
    w.put(d.stride);
  }
  w.put(m.data_offset);
  w.put(static_cast<std::uint32_t>(m.data.size()));
  for (float x : m.data) w.put(x);
  return w.take();
}

}  // namespace ts::io::ros2
