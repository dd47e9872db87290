// Core types shared by every Touchstone module: points, poses, meshes, clouds, errors and the
// deterministic random streams. Units are metres and radians throughout the engine.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace ts {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Pose = Eigen::Isometry3d;  ///< rigid transform; named T_target_source where it matters

/// FPFH descriptor (Rusu et al. 2009): 3 x 11 bins.
constexpr int kFeatureDim = 33;
using Feature = std::array<float, kFeatureDim>;

/// Feature vectors of one length (a descriptor's: FPFH 33, PFH 125, SHOT 352, Spin Images 153),
/// row-major float. Every row has dim() values; rows added by resize() are zero.
class FeatureRows {
 public:
  FeatureRows() = default;
  explicit FeatureRows(int dim, std::size_t rows = 0)
      : dim_(dim), values_(static_cast<std::size_t>(dim > 0 ? dim : 0) * rows, 0.0f) {
    if (dim <= 0) throw std::invalid_argument("FeatureRows: the dimension must be positive");
  }
  /// FPFH rows (kFeatureDim values each).
  explicit FeatureRows(const std::vector<Feature>& fpfh) : dim_(kFeatureDim) {
    values_.reserve(fpfh.size() * kFeatureDim);
    for (const Feature& f : fpfh) values_.insert(values_.end(), f.begin(), f.end());
  }
  int dim() const { return dim_; }
  std::size_t size() const { return values_.size() / static_cast<std::size_t>(dim_); }
  bool empty() const { return values_.empty(); }
  const float* row(std::size_t i) const { return values_.data() + i * static_cast<std::size_t>(dim_); }
  float* row(std::size_t i) { return values_.data() + i * static_cast<std::size_t>(dim_); }
  void resize(std::size_t rows) { values_.resize(rows * static_cast<std::size_t>(dim_), 0.0f); }
  void reserve(std::size_t rows) { values_.reserve(rows * static_cast<std::size_t>(dim_)); }
  /// Append one row of dim() values.
  void push_back(const float* r) { values_.insert(values_.end(), r, r + dim_); }
  /// All values, row after row.
  const std::vector<float>& values() const { return values_; }
  std::vector<float>& values() { return values_; }
  bool operator==(const FeatureRows& o) const { return dim_ == o.dim_ && values_ == o.values_; }

  /// FPFH conveniences (dim() must be kFeatureDim; std::invalid_argument otherwise).
  void push_back(const Feature& f) { check_fpfh(), push_back(f.data()); }
  void assign(std::size_t rows, const Feature& f) {
    check_fpfh();
    values_.clear();
    for (std::size_t i = 0; i < rows; ++i) push_back(f.data());
  }
  Feature fpfh(std::size_t i) const {
    check_fpfh();
    Feature f;
    std::copy(row(i), row(i) + kFeatureDim, f.begin());
    return f;
  }

 private:
  void check_fpfh() const {
    if (dim_ != kFeatureDim) throw std::invalid_argument("FeatureRows: not FPFH rows");
  }
  int dim_ = kFeatureDim;
  std::vector<float> values_;
};

/// Triangle mesh in its own frame. Faces index `vertices` (counter-clockwise seen from outside).
struct Mesh {
  std::vector<Vec3> vertices;
  std::vector<Eigen::Vector3i> faces;
};

/// Point cloud with optional unit normals (`normals` is empty or the same size as `points`).
struct PointCloud {
  std::vector<Vec3> points;
  std::vector<Vec3> normals;

  std::size_t size() const { return points.size(); }
  bool empty() const { return points.empty(); }
  bool has_normals() const { return !normals.empty() && normals.size() == points.size(); }
};

/// Contacts grouped by the grasp that made them (each grasp's own contacts, in the order the
/// grasps came): the points of grasp g are points[first[g]] .. points[first[g + 1] - 1]. A
/// grasp's contacts share its arm pose error, which the evaluation can take out per grasp.
struct GraspGroups {
  std::vector<Vec3> points;
  std::vector<std::uint32_t> first{0};  ///< grasps() + 1 offsets into points
  /// Per grasp, points its hand held free at the end of the grasp (hand_surface_samples), in
  /// the frame of `points`: grasp g's are free[free_first[g]] .. free[free_first[g + 1] - 1]
  /// (none when unknown). They share the grasp's arm pose error with its contacts.
  std::vector<Vec3> free;
  std::vector<std::uint32_t> free_first{0};  ///< grasps() + 1 offsets into free
  /// Per grasp, the point its arm pose error turns about (the measured end effector's origin),
  /// or empty when unknown (then no grasp's error is modelled as a rotation).
  std::vector<Vec3> pivots;

  std::size_t grasps() const { return first.empty() ? 0 : first.size() - 1; }
  bool empty() const { return points.empty(); }
  /// Append one grasp's points (and the points its hand held free, if known).
  void add(const std::vector<Vec3>& grasp, const std::vector<Vec3>& grasp_free = {},
           const std::optional<Vec3>& pivot = std::nullopt) {
    if (first.empty()) first.push_back(0);
    if (free_first.empty()) free_first.push_back(0);
    points.insert(points.end(), grasp.begin(), grasp.end());
    first.push_back(static_cast<std::uint32_t>(points.size()));
    free.insert(free.end(), grasp_free.begin(), grasp_free.end());
    free_first.push_back(static_cast<std::uint32_t>(free.size()));
    // Pivots are all or nothing: a grasp without one drops them all.
    if (pivot && pivots.size() + 1 == grasps())
      pivots.push_back(*pivot);
    else
      pivots.clear();
  }
};

/// The one exception type of Touchstone. Thrown at I/O and configuration boundaries; the core
/// returns flagged results instead. what() reads "<message> (<file>, <field>)".
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message, const std::string& file = {},
                 const std::string& field = {});
  const std::string& message() const { return message_; }
  const std::string& file() const { return file_; }
  const std::string& field() const { return field_; }

 private:
  std::string message_, file_, field_;
};

/// Deterministic random stream (xoshiro256**), seeded from a tuple such as
/// (seed, step, task index) through splitmix64. Every random draw in Touchstone comes from a
/// stream built this way, so results never depend on thread scheduling. The distributions are
/// our own (not <random>'s), so draws are identical on every standard library.
class Rng {
 public:
  explicit Rng(std::uint64_t seed, std::uint64_t a = 0, std::uint64_t b = 0, std::uint64_t c = 0);
  std::uint64_t next();                       ///< 64 random bits
  double uniform();                           ///< in [0, 1)
  double uniform(double lo, double hi);       ///< in [lo, hi)
  std::size_t index(std::size_t n);           ///< in [0, n), unbiased; n > 0
  double normal();                            ///< standard normal (Box-Muller, no caching)
  Vec3 unit_vector();                         ///< uniform on the unit sphere
  Eigen::Quaterniond rotation();              ///< uniform on SO(3) (Shoemake)

 private:
  std::array<std::uint64_t, 4> s_;
};

/// True when every coordinate is finite.
inline bool finite(const Vec3& v) { return v.allFinite(); }

}  // namespace ts
