// The feature-free source's per-object point-pair tables (ObjectPairs, build_object_pairs).
//
// A table of 600 points holds 359 400 entries, three angles each, and its build was a quarter of
// a one-object localization's step (bunny: 16 of 63 ms). The pairs of one row are measured in a
// loop written for the compiler to vectorize (pair_row: each lane does the scalar formula
// operation for operation, so every value is the same bit for bit), and whatever the fast path
// cannot decide exactly (an angle within 1e-4 of a unit of a rounding boundary, an atan2 without
// arguments) is measured again the scalar way (`measure`).
// Compiled without errno from std::sqrt (never of a negative number here), with both sides of
// the selects computed and without contracted multiply-adds (engine/CMakeLists.txt).
#include "engine/recognition/sparse_hypotheses.hpp"

#include "engine/geometry/cloud.hpp"
#include "engine/target_clones.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>

namespace ts {
inline namespace recognition {

int pair_angle_units(double rad) {
  return static_cast<int>(std::lround(std::clamp(rad, 0.0, std::numbers::pi) * 255.0 / std::numbers::pi));
}

namespace {

/// atan(lo / hi) for 0 <= lo <= hi, hi > 0: Abramowitz and Stegun's 4.4.49 polynomial
/// (|error| <= 2e-8 rad, 1.6e-6 of a unit), evaluated by Estrin's scheme (short dependency
/// chains, so the angles of several pairs overlap).
[[gnu::always_inline]] inline double table_atan_ratio(double lo, double hi) {
  const double z = lo / hi, z2 = z * z, z4 = z2 * z2, z8 = z4 * z4;
  const double p01 = 1.0 + z2 * -0.3333314528, p23 = 0.1999355085 + z2 * -0.1420889944;
  const double p45 = 0.1065626393 + z2 * -0.0752896400, p67 = 0.0429096138 + z2 * -0.0161657367;
  const double p = (p01 + z4 * p23) + z8 * ((p45 + z4 * p67) + z8 * 0.0028662257);
  return z * p;
}

/// The angles atan2(y, x) and atan2(y, -x) for y >= 0 (a pair's angle from either end), scaled
/// to units before rounding (rad * 255 / pi), within 1.6e-6 of a unit. `odd` is set where the
/// polynomial has no argument (hi not in (0, max]: y = x = 0, or not finite). One definition for
/// the vectorized row loop and the scalar path, so both give the same bits.
[[gnu::always_inline]] inline void lane_angles(double y, double x, double& plus, double& minus, std::int32_t& odd) {
  const double ax = std::abs(x);
  const double hi = std::max(ax, y), lo = std::min(ax, y);
  odd |= !(hi > 0.0 && hi <= std::numeric_limits<double>::max());
  double a = table_atan_ratio(lo, hi);               // the angle of (y, |x|), in [0, pi/2]
  a = y > ax ? std::numbers::pi / 2 - a : a;
  const double obtuse = std::numbers::pi - a;
  plus = (x < 0.0 ? obtuse : a) * 255.0 / std::numbers::pi;
  minus = (x < 0.0 ? a : obtuse) * 255.0 / std::numbers::pi;
}

/// A scaled angle rounded to units, where it lies clear of a rounding boundary (farther than
/// 1e-4 of a unit, which the polynomial's error cannot cross).
[[gnu::always_inline]] inline bool clear_units(double v, std::uint8_t& out) {
  const int whole = static_cast<int>(v);
  const double part = v - whole;
  out = static_cast<std::uint8_t>(std::min(whole + (part > 0.5 ? 1 : 0), 255));
  return !(std::abs(part - 0.5) < 1e-4);
}

/// pair_angle_units(std::atan2(y, x)) and pair_angle_units(std::atan2(y, -x)) for y >= 0, bit for
/// bit: lane_angles rounded, and std::atan2 itself where the polynomial has no argument or its
/// error could change the rounding (about 2 angles in 10 000).
[[gnu::always_inline]] inline void table_angle_units_both(double y, double x, std::uint8_t& plus, std::uint8_t& minus) {
  double vp = 0.0, vm = 0.0;
  std::int32_t odd = 0;
  lane_angles(y, x, vp, vm, odd);
  if (odd || !clear_units(vp, plus)) plus = static_cast<std::uint8_t>(pair_angle_units(std::atan2(y, x)));
  if (odd || !clear_units(vm, minus)) minus = static_cast<std::uint8_t>(pair_angle_units(std::atan2(y, -x)));
}

/// One row's pairs (i, j) for j in [i + 1, n), measured for the compiler to vectorize: the
/// distance, and the angles before rounding (rad * 255 / pi) of row i (a_i, a_j, a_ij) and of
/// row j (angle(n_j, -d), angle(n_i, -d); its a_ij is row i's). `odd[j]` marks the pairs the
/// scalar path must measure: an atan2 without arguments (y = 0 and x = +-0: 0 or pi by the sign
/// of the zero, which the negation from j's end turns; a normal of zero). A dot product of 0
/// with y > 0 needs nothing: pi / 2 either way, exactly.
struct PairRow {
  std::vector<double> px, py, pz, nx, ny, nz;   // every point and normal (structure of arrays)
  std::vector<double> dist, ai, aj, ji, jj, aij;
  std::vector<std::int32_t> odd;
  explicit PairRow(std::size_t n)
      : px(n), py(n), pz(n), nx(n), ny(n), nz(n), dist(n), ai(n), aj(n), ji(n), jj(n), aij(n), odd(n) {}
};

/// Row i's pairs for j in [i + 1, n), into R. The arrays are the function's restrict
/// parameters: the loop vectorizes only knowing they do not overlap.
TS_TARGET_CLONES
void pair_row_lanes(std::size_t i, std::size_t n, const double* __restrict px, const double* __restrict py,
                    const double* __restrict pz, const double* __restrict nx, const double* __restrict ny,
                    const double* __restrict nz, double* __restrict dist, double* __restrict ai,
                    double* __restrict aj, double* __restrict ji, double* __restrict jj,
                    double* __restrict aij, std::int32_t* __restrict odd) {
  const double pix = px[i], piy = py[i], piz = pz[i];
  const double nix = nx[i], niy = ny[i], niz = nz[i];
  for (std::size_t j = i + 1; j < n; ++j) {
    const double dx = px[j] - pix, dy = py[j] - piy, dz = pz[j] - piz;
    const double njx = nx[j], njy = ny[j], njz = nz[j];
    dist[j] = std::sqrt((dx * dx + dy * dy) + dz * dz);
    // Eigen's 3-vector dot products and norms sum left to right, (x + y) + z; its cross product
    // is the textbook formula.
    const double si = (nix * dx + niy * dy) + niz * dz;
    const double sj = (njx * dx + njy * dy) + njz * dz;
    const double sij = (nix * njx + niy * njy) + niz * njz;
    const double cix = niy * dz - niz * dy, ciy = niz * dx - nix * dz, ciz = nix * dy - niy * dx;
    const double cjx = njy * dz - njz * dy, cjy = njz * dx - njx * dz, cjz = njx * dy - njy * dx;
    const double cnx = niy * njz - niz * njy, cny = niz * njx - nix * njz, cnz = nix * njy - niy * njx;
    const double ci = std::sqrt((cix * cix + ciy * ciy) + ciz * ciz);
    const double cj = std::sqrt((cjx * cjx + cjy * cjy) + cjz * cjz);
    const double cn = std::sqrt((cnx * cnx + cny * cny) + cnz * cnz);
    std::int32_t o = 0;
    double unused = 0.0;
    lane_angles(ci, si, ai[j], jj[j], o);    // angle(n_i, d); from j: angle(n_i, -d)
    lane_angles(cj, sj, aj[j], ji[j], o);    // angle(n_j, d); from j: angle(n_j, -d)
    lane_angles(cn, sij, aij[j], unused, o);
    odd[j] = o;
  }
}

void pair_row(std::size_t i, std::size_t n, PairRow& R) {
  pair_row_lanes(i, n, R.px.data(), R.py.data(), R.pz.data(), R.nx.data(), R.ny.data(), R.nz.data(),
                 R.dist.data(), R.ai.data(), R.aj.data(), R.ji.data(), R.jj.data(), R.aij.data(), R.odd.data());
}

/// The table's points: the keypoints thinned by a voxel filter, its voxel grown by 1.5 until at
/// most max_model_points remain; zero normals where the keypoints have none.
void thin_table_points(const ObjectKeypoints& keypoints, const SparseSettings& s, ObjectPairs& out) {
  const std::size_t cap = std::min<std::size_t>(s.max_model_points, 65535);
  PointCloud thin;
  for (double voxel = s.model_spacing; ; voxel *= 1.5) {
    thin = voxel_filter(keypoints.coarse, voxel);
    if (thin.size() <= cap) break;
  }
  out.points = thin.points;
  out.normals = thin.has_normals() ? thin.normals : std::vector<Vec3>(thin.size(), Vec3::Zero());
}

/// The rows into out.near: row i holds every j != i sorted by (distance, index): keys
/// (distance << 16 | j) taken in increasing j, then a stable radix sort on the distance's low
/// byte and on its high byte (both counts from one pass).
void append_sorted_rows(std::size_t n, const std::vector<std::uint16_t>& distance,
                        const std::vector<std::array<std::uint8_t, 3>>& angles, ObjectPairs& out) {
  out.near.resize(n * (n - 1));
  std::vector<std::uint32_t> keys(n - 1), sorted(n - 1);
  ObjectPairs::Near* to = out.near.data();
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint16_t* row = distance.data() + i * n;
    std::array<std::uint32_t, 256> low{}, high{};
    std::size_t k = 0;
    for (std::size_t j = 0; j < n; ++j) {
      if (j == i) continue;
      const std::uint32_t d = row[j];
      keys[k++] = d << 16 | static_cast<std::uint32_t>(j);
      ++low[d & 0xffu];
      ++high[d >> 8];
    }
    std::uint32_t at_low = 0, at_high = 0;
    for (std::size_t b = 0; b < 256; ++b) {
      const std::uint32_t l = low[b], h = high[b];
      low[b] = at_low, high[b] = at_high;
      at_low += l, at_high += h;
    }
    for (const std::uint32_t key : keys) sorted[low[(key >> 16) & 0xffu]++] = key;
    for (const std::uint32_t key : sorted) keys[high[key >> 24]++] = key;
    const std::array<std::uint8_t, 3>* row_angles = angles.data() + i * n;
    for (const std::uint32_t key : keys) {
      const std::uint32_t j = key & 0xffffu;
      const auto& a = row_angles[j];
      *to++ = {static_cast<std::uint16_t>(key >> 16), static_cast<std::uint16_t>(j), a[0], a[1], a[2], 0};
    }
  }
}

}  // namespace

ObjectPairs build_object_pairs(const ObjectKeypoints& keypoints, const SparseSettings& s) {
  ObjectPairs out;
  thin_table_points(keypoints, s, out);
  const std::size_t n = out.points.size();
  if (n < 2) return out;
  PairRow R(n);
  for (std::size_t i = 0; i < n; ++i) {
    R.px[i] = out.points[i].x(), R.py[i] = out.points[i].y(), R.pz[i] = out.points[i].z();
    R.nx[i] = out.normals[i].x(), R.ny[i] = out.normals[i].y(), R.nz[i] = out.normals[i].z();
  }
  // The largest distance (the unit's scale): sqrt is monotone and correctly rounded, so the
  // largest norm is the norm of the largest squared norm, bit for bit.
  double largest2 = 0.0;
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = i + 1; j < n; ++j) largest2 = std::max(largest2, (out.points[i] - out.points[j]).squaredNorm());
  out.unit = std::max(std::sqrt(largest2), 1e-9) / 65535.0;
  // Row i: every j != i sorted by (distance, index), each with angle(n_i, d), angle(n_j, d) and
  // angle(n_i, n_j) of d = p_j - p_i (in units, as pair_angle_units(std::atan2(|n x d|, n . d))
  // would give). Each unordered pair is measured once, for both rows: from j's end, d is exactly
  // -d (its norm and cross products' norms the same, its dot products negated), so angle(n_j,
  // -d) and angle(n_i, -d) are atan2 of the same numbers with x negated, and n_j x n_i is
  // exactly -(n_i x n_j).
  std::vector<std::uint16_t> distance(n * n);
  std::vector<std::array<std::uint8_t, 3>> angles(n * n);
  auto measure = [&](std::size_t i, std::size_t j) {   // row i's entry j, the scalar way
    const Vec3 d = out.points[j] - out.points[i];
    const Vec3& ni = out.normals[i];
    const Vec3& nj = out.normals[j];
    std::uint8_t ignored = 0;
    auto& e = angles[i * n + j];
    table_angle_units_both(ni.cross(d).norm(), ni.dot(d), e[0], ignored);
    table_angle_units_both(nj.cross(d).norm(), nj.dot(d), e[1], ignored);
    table_angle_units_both(ni.cross(nj).norm(), ni.dot(nj), e[2], ignored);
  };
  // One angle the scalar way without the fast path (never odd here): angle(a, b) in units, as
  // measure computes it.
  auto exact_units = [](const Vec3& a, const Vec3& b) {
    return static_cast<std::uint8_t>(pair_angle_units(std::atan2(a.cross(b).norm(), a.dot(b))));
  };
  for (std::size_t i = 0; i < n; ++i) {
    pair_row(i, n, R);
    for (std::size_t j = i + 1; j < n; ++j) {
      distance[i * n + j] = distance[j * n + i] =
          static_cast<std::uint16_t>(std::lround(std::min(R.dist[j] / out.unit, 65535.0)));
      auto& row_i = angles[i * n + j];
      auto& row_j = angles[j * n + i];
      if (R.odd[j]) {
        measure(i, j);
        measure(j, i);
        continue;
      }
      // Each angle the fast path leaves undecided (on a rounding boundary within the
      // polynomial's error: often pi / 2 between near-axis normals of CAD faces) from std::atan2
      // of the numbers `measure` computes, alone.
      if (!clear_units(R.ai[j], row_i[0])) row_i[0] = exact_units(out.normals[i], out.points[j] - out.points[i]);
      if (!clear_units(R.aj[j], row_i[1])) row_i[1] = exact_units(out.normals[j], out.points[j] - out.points[i]);
      if (!clear_units(R.aij[j], row_i[2])) row_i[2] = exact_units(out.normals[i], out.normals[j]);
      if (!clear_units(R.ji[j], row_j[0])) row_j[0] = exact_units(out.normals[j], out.points[i] - out.points[j]);
      if (!clear_units(R.jj[j], row_j[1])) row_j[1] = exact_units(out.normals[i], out.points[i] - out.points[j]);
      row_j[2] = row_i[2];
    }
  }
  append_sorted_rows(n, distance, angles, out);
  return out;
}

std::size_t ObjectPairs::memory_bytes() const {
  return points.size() * 2 * sizeof(Vec3) + near.size() * sizeof(Near);
}

}  // namespace recognition
}  // namespace ts
