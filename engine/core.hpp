// Core types shared by every Touchstone module: points, poses, meshes, clouds, errors and the
// deterministic random streams. Units are metres and radians throughout the engine.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <cstdint>
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

  std::size_t grasps() const { return first.empty() ? 0 : first.size() - 1; }
  bool empty() const { return points.empty(); }
  /// Append one grasp's points.
  void add(const std::vector<Vec3>& grasp) {
    if (first.empty()) first.push_back(0);
    points.insert(points.end(), grasp.begin(), grasp.end());
    first.push_back(static_cast<std::uint32_t>(points.size()));
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
