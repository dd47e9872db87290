// Two-level distance field (see distance_field.hpp). Index ijk stands for the object-frame point
// ijk * voxel (voxel centres).
//
// Fine level: the voxels whose centres are within fine_band_voxels voxels of the surface.
// MeshIndex::shell finds the voxel centres within half a voxel diagonal of a face, with exact
// distances (each face tests the lattice points of its own box); OpenVDB's dilation grows that
// shell to reach the band (kShellRadius), every grown voxel gets its exact distance from the
// mesh's BVH, and voxels farther than the band are dropped. The band is whole: every voxel
// within the half-width is there. (OpenVDB's meshToVolume made the shell until 2026-11-28, and
// its band until ff668bb: its voxelization took a sixth of a database build, and it removed
// shell voxels next to internal faces and in gaps narrower than about 1.7 voxels.)
//
// Coarse level: dense over the box B = bbox(mesh) grown by coarse_margin and rounded out to
// whole voxels (each point of bbox + margin has its 8 interpolation corners inside), exact BVH
// distances up to coarse_margin + 2 voxels and that cap (a lower bound) beyond. A coarse
// meshToVolume run was tried first: its propagated values were off by up to 24 mm in thin
// regions.
//
// Signs (closed meshes): from the closest point's angle-weighted pseudonormal (MeshIndex::side)
// when the faces are wound consistently (MeshIndex::oriented); else, and for coarse voxels
// farther from the surface than the search reached, by ray parity (MeshIndex::inside).
//
// Both levels are held as CompactGrids (4^3 bricks of int16 behind a dense brick index); the
// OpenVDB tree of the dilation is dropped after the build.
//
// Queries interpolate trilinearly from the fine level when its 8 corners are all active, else
// from the coarse level. Outside B nothing is stored; there the distance to the surface is at
// least dist(p, B) + coarse_margin (B shrunk by the margin still contains the mesh's bounding
// box), and that lower bound is returned.
//
// Determinism: every value is computed for its own voxel; the shell is sorted by voxel, then
// distance, then face; the dilation is a union. Same mesh and settings => same grids and bytes
// for any thread count.
#include "engine/geometry/distance_field.hpp"
#include "engine/detail.hpp"

#include <openvdb/openvdb.h>
#include <openvdb/tools/Morphology.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <optional>

namespace ts {
inline namespace geometry {

namespace {

using detail::init_openvdb;

/// Smallest power of two q with max|v| / q <= 32000 (int16 with room to spare). Dequantized
/// values k*q are exact in float and double, so quantizing them again gives them back.
double quantum_for(double max_abs) {
  double q = std::ldexp(1.0, -40);
  while (max_abs / q > 32000.0) q *= 2.0;
  return q;
}

std::int16_t quantize(double v, double q) {
  const double k = std::nearbyint(v / q);
  return static_cast<std::int16_t>(std::clamp(k, -32767.0, 32767.0));
}

inline int brick_of(int i) { return i >> 2; }           // floor division by CompactGrid::kBrick
inline int in_brick(int a, int b, int c) { return ((a & 3) << 4) | ((b & 3) << 2) | (c & 3); }

/// Sparse voxels (any order; a repeated voxel keeps its last value) -> compact grid with a
/// quantum chosen for their values. Linear time: bricks are numbered in the order of a dense
/// index over their box, which is the order of their coordinates.
CompactGrid compact_from_cells(double voxel, const std::vector<std::pair<std::array<std::int32_t, 3>, double>>& cells) {
  CompactGrid g;
  g.voxel = voxel;
  double max_abs = 0.0;
  std::array<int, 3> lo{0, 0, 0}, hi{-1, -1, -1};
  for (std::size_t n = 0; n < cells.size(); ++n) {
    max_abs = std::max(max_abs, std::abs(cells[n].second));
    for (int a = 0; a < 3; ++a) {
      const int b = brick_of(cells[n].first[a]);
      lo[a] = n == 0 ? b : std::min(lo[a], b);
      hi[a] = n == 0 ? b : std::max(hi[a], b);
    }
  }
  g.quantum = quantum_for(max_abs);
  if (cells.empty()) return g;
  const std::size_t dy = static_cast<std::size_t>(hi[1] - lo[1] + 1), dz = static_cast<std::size_t>(hi[2] - lo[2] + 1);
  const double span = double(hi[0] - lo[0] + 1) * double(dy) * double(dz);
  if (span > 1e8) throw Error("distance field: voxels span more than 1e8 bricks", {}, "ijk");
  auto cell = [&](const std::array<std::int32_t, 3>& ijk) {
    return (static_cast<std::size_t>(brick_of(ijk[0]) - lo[0]) * dy + static_cast<std::size_t>(brick_of(ijk[1]) - lo[1])) * dz +
           static_cast<std::size_t>(brick_of(ijk[2]) - lo[2]);
  };
  std::vector<std::int32_t> number(static_cast<std::size_t>(span), -1);
  for (const auto& c : cells) number[cell(c.first)] = 0;
  std::int32_t count = 0;
  for (std::size_t n = 0; n < number.size(); ++n)
    if (number[n] == 0) {
      number[n] = count++;
      const std::size_t a = n / (dy * dz), b = (n / dz) % dy, c = n % dz;
      g.bricks.push_back({lo[0] + static_cast<int>(a), lo[1] + static_cast<int>(b), lo[2] + static_cast<int>(c)});
    }
  g.values.assign(g.bricks.size() * CompactGrid::kBrickVoxels, CompactGrid::kInactive);
  for (const auto& [ijk, v] : cells)
    g.values[static_cast<std::size_t>(number[cell(ijk)]) * CompactGrid::kBrickVoxels + in_brick(ijk[0], ijk[1], ijk[2])] =
        quantize(v, g.quantum);
  return g;
}

CompactGrid compact_from_sparse(const SparseGrid& s) {
  std::vector<std::pair<std::array<std::int32_t, 3>, double>> cells(s.ijk.size());
  for (std::size_t n = 0; n < s.ijk.size(); ++n) cells[n] = {s.ijk[n], s.value[n]};
  return compact_from_cells(s.voxel, cells);
}

/// A CompactGrid with its dense brick index, ready for lookups.
struct Level {
  CompactGrid grid;
  double inv_voxel = 0.0;
  std::array<int, 3> origin{0, 0, 0};   // brick coordinates of index cell 0
  std::array<int, 3> dims{0, 0, 0};     // index extent in bricks
  std::vector<std::int32_t> index;      // brick number, or -1

  static Level make(CompactGrid g, const std::string& name) {
    auto bad = [&](const std::string& why, const std::string& what) {
      throw Error("distance field: " + why, {}, name + "/" + what);
    };
    if (!(g.voxel > 0.0) || !std::isfinite(g.voxel)) bad("voxel size must be positive", "voxel");
    if (!(g.quantum > 0.0) || !std::isfinite(g.quantum)) bad("quantum must be positive", "quantum");
    if (g.values.size() != g.bricks.size() * CompactGrid::kBrickVoxels)
      bad(std::to_string(g.values.size()) + " values for " + std::to_string(g.bricks.size()) +
              " bricks (expected 64 a brick)", "values");
    constexpr std::int32_t kReach = 1 << 26;   // |brick coordinate|: keeps voxel ijk in int range
    std::array<std::int64_t, 3> lo{0, 0, 0}, hi{-1, -1, -1};
    for (std::size_t b = 0; b < g.bricks.size(); ++b) {
      for (int a = 0; a < 3; ++a) {
        if (std::abs(g.bricks[b][a]) >= kReach) bad("brick coordinate out of range", "bricks");
        if (b == 0 || g.bricks[b][a] < lo[a]) lo[a] = g.bricks[b][a];
        if (b == 0 || g.bricks[b][a] > hi[a]) hi[a] = g.bricks[b][a];
      }
      if (b > 0 && !(g.bricks[b - 1] < g.bricks[b])) bad("bricks not in increasing order", "bricks");
    }
    Level L;
    L.inv_voxel = 1.0 / g.voxel;
    if (!g.bricks.empty()) {
      double cells = 1.0;
      for (int a = 0; a < 3; ++a) cells *= double(hi[a] - lo[a] + 1);
      if (cells > 1e8) bad("bricks span more than 1e8 index cells", "bricks");
      for (int a = 0; a < 3; ++a) {
        L.origin[a] = static_cast<int>(lo[a]);
        L.dims[a] = static_cast<int>(hi[a] - lo[a] + 1);
      }
      L.index.assign(static_cast<std::size_t>(cells), -1);
      for (std::size_t b = 0; b < g.bricks.size(); ++b)
        L.index[L.cell(g.bricks[b][0] - L.origin[0], g.bricks[b][1] - L.origin[1], g.bricks[b][2] - L.origin[2])] =
            static_cast<std::int32_t>(b);
    }
    L.grid = std::move(g);
    return L;
  }

  std::size_t cell(int a, int b, int c) const {
    return (static_cast<std::size_t>(a) * static_cast<std::size_t>(dims[1]) + static_cast<std::size_t>(b)) *
               static_cast<std::size_t>(dims[2]) + static_cast<std::size_t>(c);
  }

  /// The values of the brick holding voxel (i, j, k), or nullptr.
  const std::int16_t* brick(int i, int j, int k) const {
    const int a = brick_of(i) - origin[0], b = brick_of(j) - origin[1], c = brick_of(k) - origin[2];
    if (static_cast<unsigned>(a) >= static_cast<unsigned>(dims[0]) ||
        static_cast<unsigned>(b) >= static_cast<unsigned>(dims[1]) ||
        static_cast<unsigned>(c) >= static_cast<unsigned>(dims[2]))
      return nullptr;
    const std::int32_t n = index[cell(a, b, c)];
    return n < 0 ? nullptr : grid.values.data() + static_cast<std::size_t>(n) * CompactGrid::kBrickVoxels;
  }

  bool empty() const { return grid.bricks.empty(); }

  std::size_t bytes() const {
    return grid.bricks.capacity() * sizeof(grid.bricks[0]) + grid.values.capacity() * sizeof(std::int16_t) +
           index.capacity() * sizeof(std::int32_t) + sizeof(Level);
  }

  /// Active voxels with dequantized values, sorted by (i, j, k).
  SparseGrid sparse() const {
    SparseGrid s;
    s.voxel = grid.voxel;
    std::vector<std::pair<std::array<std::int32_t, 3>, float>> cells;
    for (std::size_t b = 0; b < grid.bricks.size(); ++b)
      for (int n = 0; n < CompactGrid::kBrickVoxels; ++n) {
        const std::int16_t v = grid.values[b * CompactGrid::kBrickVoxels + static_cast<std::size_t>(n)];
        if (v == CompactGrid::kInactive) continue;
        cells.push_back({{grid.bricks[b][0] * 4 + (n >> 4), grid.bricks[b][1] * 4 + ((n >> 2) & 3),
                          grid.bricks[b][2] * 4 + (n & 3)},
                         static_cast<float>(v * grid.quantum)});
      }
    std::sort(cells.begin(), cells.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const auto& [ijk, v] : cells) {
      s.ijk.push_back(ijk);
      s.value.push_back(v);
    }
    return s;
  }
};

/// The 8 corner values of index cell (i, j, k) (corner n at offset (n & 1, n >> 1 & 1, n >> 2
/// & 1)), or false when some corner is missing or inactive.
inline bool corners(const Level& L, int i, int j, int k, int raw[8]) {
  if ((i & 3) != 3 && (j & 3) != 3 && (k & 3) != 3) {
    // All 8 corners in one brick (27 of 64 cells): offsets a*16 + b*4 + c.
    const std::int16_t* b = L.brick(i, j, k);
    if (!b) return false;
    const int o0 = in_brick(i, j, k);
    for (int n = 0; n < 8; ++n) {
      raw[n] = b[o0 + ((n & 1) << 4) + (((n >> 1) & 1) << 2) + ((n >> 2) & 1)];
      if (raw[n] == CompactGrid::kInactive) return false;
    }
  } else {
    // Corners in 2, 4 or 8 bricks: each brick looked up once (an axis crosses into the next
    // brick where the cell sits on its last voxel).
    const int ax = (i & 3) == 3, ay = (j & 3) == 3, az = (k & 3) == 3;
    const std::int16_t* bp[2][2][2];
    for (int a = 0; a <= ax; ++a)
      for (int bb = 0; bb <= ay; ++bb)
        for (int c = 0; c <= az; ++c)
          if (!(bp[a][bb][c] = L.brick(i + a, j + bb, k + c))) return false;
    for (int n = 0; n < 8; ++n) {
      const int dx = n & 1, dy = (n >> 1) & 1, dz = (n >> 2) & 1;
      raw[n] = bp[dx & ax][dy & ay][dz & az][in_brick(i + dx, j + dy, k + dz)];
      if (raw[n] == CompactGrid::kInactive) return false;
    }
  }
  return true;
}

/// The trilinear interpolant of a cell's corner values at fractions (tx, ty, tz), and its
/// analytic gradient (per index unit) when asked.
inline double interpolate(const Level& L, const int raw[8], double tx, double ty, double tz, Vec3* grad) {
  double v[8];
  for (int n = 0; n < 8; ++n) v[n] = raw[n] * L.grid.quantum;
  const double x00 = v[0] + tx * (v[1] - v[0]);
  const double x10 = v[2] + tx * (v[3] - v[2]);
  const double x01 = v[4] + tx * (v[5] - v[4]);
  const double x11 = v[6] + tx * (v[7] - v[6]);
  const double y0 = x00 + ty * (x10 - x00);
  const double y1 = x01 + ty * (x11 - x01);
  if (grad) {
    const double dx00 = v[1] - v[0], dx10 = v[3] - v[2], dx01 = v[5] - v[4], dx11 = v[7] - v[6];
    const double dx0 = dx00 + ty * (dx10 - dx00), dx1 = dx01 + ty * (dx11 - dx01);
    (*grad)[0] = dx0 + tz * (dx1 - dx0);
    (*grad)[1] = (x10 - x00) + tz * ((x11 - x01) - (x10 - x00));
    (*grad)[2] = y1 - y0;
  }
  return y0 + tz * (y1 - y0);
}

/// The last fine cell read by a batch of queries and its corners: consecutive queries of a batch
/// (the contacts of one hypothesis, in the scene's order) often fall in one cell.
struct CellCache {
  bool valid = false, ok = false;
  int i = 0, j = 0, k = 0;
  int raw[8];
};

/// Trilinear interpolation at index-space point x when all 8 corners are active.
inline bool trilinear(const Level& L, const Vec3& x, double& out, Vec3* grad = nullptr,
                      CellCache* cache = nullptr) {
  const double fx = std::floor(x.x()), fy = std::floor(x.y()), fz = std::floor(x.z());
  constexpr double kLimit = 1e9;   // keep far points out of int32 index range
  if (!(std::abs(fx) < kLimit && std::abs(fy) < kLimit && std::abs(fz) < kLimit)) return false;
  const int i = static_cast<int>(fx), j = static_cast<int>(fy), k = static_cast<int>(fz);
  const double tx = x.x() - fx, ty = x.y() - fy, tz = x.z() - fz;
  int own[8];
  const int* raw = own;
  if (cache) {
    if (!(cache->valid && cache->i == i && cache->j == j && cache->k == k)) {
      cache->ok = corners(L, i, j, k, cache->raw);
      cache->valid = true, cache->i = i, cache->j = j, cache->k = k;
    }
    if (!cache->ok) return false;
    raw = cache->raw;
  } else if (!corners(L, i, j, k, own)) {
    return false;
  }
  out = interpolate(L, raw, tx, ty, tz, grad);
  return true;
}

}  // namespace

struct DistanceField::Impl {
  Level fine, coarse;
  bool built = false;               // a coarse level exists (possibly without voxels)
  bool is_signed = false;
  double coarse_margin = 0.0;
  Eigen::AlignedBox3d coarse_box;   // object frame, spanned by the coarse voxel centres

  double query(const Vec3& p, CellCache* cache = nullptr) const {
    double d;
    if (trilinear(fine, p * fine.inv_voxel, d, nullptr, cache)) return d;
    if (coarse_box.contains(p) && trilinear(coarse, p * coarse.inv_voxel, d)) return d;
    if (!finite(p)) return std::numeric_limits<double>::infinity();
    return std::sqrt(coarse_box.squaredExteriorDistance(p)) + coarse_margin;
  }

  /// As query(), with the gradient of the interpolant (zero where only a bound is known).
  double query_gradient(const Vec3& p, Vec3& g) const {
    double d;
    if (trilinear(fine, p * fine.inv_voxel, d, &g)) {
      g *= fine.inv_voxel;
      return d;
    }
    if (coarse_box.contains(p) && trilinear(coarse, p * coarse.inv_voxel, d, &g)) {
      g *= coarse.inv_voxel;
      return d;
    }
    g.setZero();
    if (!finite(p)) return std::numeric_limits<double>::infinity();
    return std::sqrt(coarse_box.squaredExteriorDistance(p)) + coarse_margin;
  }

  /// The box spanned by the active coarse voxels (the coarse level is a dense box).
  /// Only bricks that reach beyond the bounds so far are scanned voxel by voxel (a load reads
  /// a few of the thousands).
  void set_box() {
    coarse_box.setEmpty();
    const CompactGrid& g = coarse.grid;
    std::array<int, 3> lo{0, 0, 0}, hi{-1, -1, -1};
    bool any = false;
    for (std::size_t b = 0; b < g.bricks.size(); ++b) {
      const auto& c = g.bricks[b];
      if (any && 4 * c[0] >= lo[0] && 4 * c[0] + 3 <= hi[0] && 4 * c[1] >= lo[1] && 4 * c[1] + 3 <= hi[1] &&
          4 * c[2] >= lo[2] && 4 * c[2] + 3 <= hi[2])
        continue;   // nothing in it can widen the box
      for (int n = 0; n < CompactGrid::kBrickVoxels; ++n) {
        if (g.values[b * CompactGrid::kBrickVoxels + static_cast<std::size_t>(n)] == CompactGrid::kInactive) continue;
        const std::array<int, 3> v{4 * c[0] + (n >> 4), 4 * c[1] + ((n >> 2) & 3), 4 * c[2] + (n & 3)};
        for (int a = 0; a < 3; ++a) {
          lo[a] = any ? std::min(lo[a], v[a]) : v[a];
          hi[a] = any ? std::max(hi[a], v[a]) : v[a];
        }
        any = true;
      }
    }
    if (!any) return;
    coarse_box.extend(Vec3(lo[0], lo[1], lo[2]) * g.voxel);
    coarse_box.extend(Vec3(hi[0], hi[1], hi[2]) * g.voxel);
  }
};

DistanceField::DistanceField() : impl_(std::make_unique<Impl>()) {}
DistanceField::~DistanceField() = default;
DistanceField::DistanceField(DistanceField&&) noexcept = default;
DistanceField& DistanceField::operator=(DistanceField&&) noexcept = default;

namespace {

/// Throws on what the field and the BVH cannot take; returns the mesh's bounding box.
Eigen::AlignedBox3d checked_bounds(const Mesh& mesh, const DistanceFieldSettings& s) {
  if (!(s.fine_voxel > 0.0) || !(s.coarse_voxel > 0.0) || s.fine_band_voxels < 1 ||
      !(s.coarse_margin >= 0.0) || !std::isfinite(s.coarse_margin))
    throw Error("distance field: voxels must be > 0, band >= 1 voxel, margin >= 0", {}, "field");
  if (mesh.faces.empty()) throw Error("distance field: the mesh has no faces", {}, "faces");
  for (const auto& f : mesh.faces)
    for (int k = 0; k < 3; ++k)
      if (f[k] < 0 || static_cast<std::size_t>(f[k]) >= mesh.vertices.size())
        throw Error("distance field: face index out of range", {}, "faces");
  Eigen::AlignedBox3d bbox;
  for (const auto& v : mesh.vertices) {
    if (!finite(v)) throw Error("distance field: non-finite vertex", {}, "vertices");
    bbox.extend(v);
  }
  return bbox;
}

}  // namespace

namespace {

/// Which side of the surface p lies on (true: inside), for signed fields: from the closest point
/// when one was found (the pseudonormal of an oriented mesh, MeshIndex::side), else by ray
/// parity (MeshIndex::inside: meshes wound inconsistently, and points farther than the search
/// reached; outside the mesh's box nothing is inside).
bool inside_at(const MeshIndex& index, bool oriented, const Eigen::AlignedBox3d& bbox, const Vec3& p,
               const ClosestPoint* c) {
  if (c && oriented) return index.side(p, *c) < 0.0;
  if (bbox.squaredExteriorDistance(p) > 0.0) return false;
  return index.inside(p);
}

/// Distances of the coarse box's voxel centres, column by column along k, each voxel in its own
/// slot: exact up to `cap`, `cap` beyond, negative inside when `is_signed`. Bounds from the
/// voxels 1 voxel away keep the BVH work small: the closest points of the previous voxel of the
/// column and of the same voxel of the previous column bound d(p) from above (usually tightly:
/// deep inside a sphere the BVH otherwise visits most triangles), and d(prev) - voxel bounds it
/// from below, which skips runs of voxels beyond the cap (searched up to cap + 4 voxels to learn
/// how far beyond they are).
void coarse_distances(const MeshIndex& index, const Eigen::AlignedBox3d& bbox, const openvdb::Coord& cmin,
                      std::size_t ny, std::size_t nz, double cv, double cap, bool is_signed, bool oriented,
                      std::vector<float>& dense) {
  const double reach = cap + 4.0 * cv;
  const std::size_t columns = dense.size() / nz;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, columns), [&](const auto& range) {
    // closest surface points of the previous column of this range (one voxel away in j, or a
    // farther column: any surface point bounds the distance from above)
    std::vector<std::optional<Vec3>> previous(nz), current(nz);
    for (std::size_t ij = range.begin(); ij != range.end(); ++ij) {
      const int i = cmin.x() + static_cast<int>(ij / ny), j = cmin.y() + static_cast<int>(ij % ny);
      std::optional<Vec3> last;   // closest surface point of the previous voxel
      double lower = 0.0;         // lower bound on the distance of the current voxel
      for (std::size_t kk = 0; kk < nz; ++kk) {
        const Vec3 p = Vec3(i, j, cmin.z() + static_cast<int>(kk)) * cv;
        double d;                   // exact, or a lower bound when >= cap
        std::optional<ClosestPoint> hit;
        if (lower < cap && bbox.squaredExteriorDistance(p) < cap * cap) {
          double near = reach;
          if (last) near = std::min(near, (p - *last).norm());
          if (previous[kk]) near = std::min(near, (p - *previous[kk]).norm());
          const double bound = near * (1.0 + 1e-9) + 1e-12;
          if (bound < reach) hit = index.closest_within(p, bound);
          if (!hit) hit = index.closest_within(p, reach);
          d = hit ? hit->distance : reach;
        } else {
          d = std::max(lower, cap);   // d(p) >= lower, and >= dist(p, bbox) >= cap
        }
        last.reset();
        if (hit) last = hit->point;
        current[kk] = last;
        const auto v = static_cast<float>(std::min(d, cap));
        dense[ij * nz + kk] = is_signed && inside_at(index, oriented, bbox, p, hit ? &*hit : nullptr) ? -v : v;
        lower = d - cv * (1.0 + 1e-9);
      }
      std::swap(previous, current);
    }
  });
}

/// Lattice points within half a voxel diagonal of the surface, and their 26-neighbourhoods
/// grown `band` times: every voxel centre p within `band` voxels of the surface. Its closest
/// surface point q has a nearest lattice point u within half a diagonal (so u is in the shell),
/// and |p - u| <= |p - q| + |q - u| <= band + 1/2 in the max norm, so <= band (integers).
constexpr double kShellRadius = 0.8660254037844386;   // sqrt(3) / 2, in voxels

/// The fine level (see the top comment): every voxel centre within `band` voxels of the surface
/// with its exact distance, negative inside when `is_signed`; sorted by ijk.
SparseGrid fine_band(const MeshIndex& index, const Eigen::AlignedBox3d& bbox, double fv, int band,
                     bool is_signed, bool oriented) {
  const std::vector<ShellVoxel> shell = index.shell(fv, kShellRadius * fv * (1.0 + 1e-9));
  openvdb::Int32Tree tree(-1);   // active voxels: the band; value: the shell entry, or -1
  {
    openvdb::tree::ValueAccessor<openvdb::Int32Tree> acc(tree);
    for (std::size_t n = 0; n < shell.size(); ++n)
      acc.setValue(openvdb::Coord(shell[n].ijk[0], shell[n].ijk[1], shell[n].ijk[2]), static_cast<std::int32_t>(n));
  }
  openvdb::tools::dilateActiveValues(tree, band, openvdb::tools::NN_FACE_EDGE_VERTEX, openvdb::tools::EXPAND_TILES);
  std::vector<std::pair<std::array<std::int32_t, 3>, std::int32_t>> voxels;
  voxels.reserve(tree.activeVoxelCount());
  for (auto it = tree.cbeginValueOn(); it; ++it) {
    openvdb::CoordBBox box;
    it.getBoundingBox(box);   // one voxel, or every voxel of an active tile
    for (auto c = box.begin(); c; ++c) voxels.push_back({{(*c).x(), (*c).y(), (*c).z()}, it.isVoxelValue() ? *it : -1});
  }
  tree.clear();
  std::sort(voxels.begin(), voxels.end(), [](const auto& a, const auto& b) {   // by ijk (each once)
    for (int k = 0; k < 3; ++k)
      if (a.first[k] != b.first[k]) return a.first[k] < b.first[k];
    return false;
  });
  // Exact distances: the shell's from MeshIndex::shell, the others from the BVH; voxels beyond
  // the half-width (a hair more: voxels exactly on it, as on faces aligned with the lattice,
  // stay) are dropped.
  const double reach = band * fv * (1.0 + 1e-9);
  std::vector<float> value(voxels.size());
  std::vector<char> keep(voxels.size(), 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, voxels.size(), 256), [&](const auto& range) {
    for (std::size_t n = range.begin(); n != range.end(); ++n) {
      const auto& [ijk, which] = voxels[n];
      const Vec3 p = Vec3(ijk[0], ijk[1], ijk[2]) * fv;
      std::optional<ClosestPoint> hit;
      if (which >= 0) {
        const ShellVoxel& sv = shell[static_cast<std::size_t>(which)];
        hit = ClosestPoint{std::sqrt(sv.sq_distance), sv.point, Vec3::Zero(), sv.face};
      } else {
        hit = index.closest_within(p, reach);
      }
      if (!hit || !(hit->distance <= reach)) continue;
      const auto d = static_cast<float>(hit->distance);
      value[n] = is_signed && inside_at(index, oriented, bbox, p, &*hit) ? -d : d;
      keep[n] = 1;
    }
  });
  SparseGrid out;
  out.voxel = fv;
  for (std::size_t n = 0; n < voxels.size(); ++n)
    if (keep[n]) {
      out.ijk.push_back(voxels[n].first);
      out.value.push_back(value[n]);
    }
  return out;
}

}  // namespace

DistanceField DistanceField::build(const Mesh& mesh, bool is_signed, const DistanceFieldSettings& s) {
  checked_bounds(mesh, s);
  return build(MeshIndex(mesh), is_signed, s);
}

DistanceField DistanceField::build(const MeshIndex& index, bool is_signed, const DistanceFieldSettings& s) {
  const Mesh& mesh = index.mesh();
  const Eigen::AlignedBox3d bbox = checked_bounds(mesh, s);
  // Refuse settings whose grids cannot fit in memory (dense coarse box; fine band ~ area x band;
  // before the distance cut the grown shell holds up to about twice that, for a moment).
  const Vec3 cells = ((bbox.max() - bbox.min()).array() + 2.0 * s.coarse_margin) / s.coarse_voxel + 3.0;
  if (cells.prod() > 5e7)
    throw Error("distance field: the coarse grid would exceed 5e7 voxels", {}, "coarse_voxel");
  if (mesh_area(mesh) / (s.fine_voxel * s.fine_voxel) * (2.0 * s.fine_band_voxels + 1.0) > 2e8)
    throw Error("distance field: the fine band would exceed 2e8 voxels", {}, "fine_voxel");
  init_openvdb();

  DistanceField df;
  Impl& im = *df.impl_;
  im.is_signed = is_signed;
  im.coarse_margin = s.coarse_margin;

  // Coarse box: dense, every point of bbox + margin having its 8 corners inside.
  const double fv = s.fine_voxel, cv = s.coarse_voxel;
  const Vec3 lo = (bbox.min().array() - s.coarse_margin) / cv;
  const Vec3 hi = (bbox.max().array() + s.coarse_margin) / cv;
  const openvdb::Coord cmin(static_cast<int>(std::floor(lo.x())), static_cast<int>(std::floor(lo.y())),
                            static_cast<int>(std::floor(lo.z())));
  const openvdb::Coord cmax(static_cast<int>(std::ceil(hi.x())), static_cast<int>(std::ceil(hi.y())),
                            static_cast<int>(std::ceil(hi.z())));
  const openvdb::Coord dim = cmax - cmin + openvdb::Coord(1);
  const std::size_t nx = static_cast<std::size_t>(dim.x()), ny = static_cast<std::size_t>(dim.y()),
                    nz = static_cast<std::size_t>(dim.z());
  // Farther than `cap` from the surface a voxel holds `cap`, a lower bound on its distance.
  const double cap = s.coarse_margin + 2.0 * cv;
  std::vector<float> dense(nx * ny * nz);

  // Fine level and coarse level side by side (each parallel inside).
  const bool oriented = is_signed && index.oriented();
  SparseGrid fine;
  tbb::parallel_invoke([&] { fine = fine_band(index, bbox, fv, s.fine_band_voxels, is_signed, oriented); },
                       [&] { coarse_distances(index, bbox, cmin, ny, nz, cv, cap, is_signed, oriented, dense); });
  im.fine = Level::make(compact_from_sparse(fine), "fine");
  fine = SparseGrid{};
  {
    std::vector<std::pair<std::array<std::int32_t, 3>, double>> cells(dense.size());
    for (std::size_t ij = 0; ij < nx * ny; ++ij)
      for (std::size_t kk = 0; kk < nz; ++kk)
        cells[ij * nz + kk] = {{cmin.x() + static_cast<int>(ij / ny), cmin.y() + static_cast<int>(ij % ny),
                                cmin.z() + static_cast<int>(kk)},
                               dense[ij * nz + kk]};
    im.coarse = Level::make(compact_from_cells(cv, cells), "coarse");
  }
  im.built = true;
  im.set_box();
  return df;
}

DistanceField DistanceField::from_sparse(SparseGrid fine, SparseGrid coarse, bool is_signed,
                                         double coarse_margin) {
  if (fine.ijk.size() != fine.value.size() || coarse.ijk.size() != coarse.value.size())
    throw Error("distance field: ijk and value sizes differ", {}, "ijk/value");
  if (!(fine.voxel > 0.0) || !(coarse.voxel > 0.0))
    throw Error("distance field: voxel size must be positive", {}, "voxel");
  for (float v : fine.value)
    if (!std::isfinite(v)) throw Error("distance field: non-finite value", {}, "fine/value");
  for (float v : coarse.value)
    if (!std::isfinite(v)) throw Error("distance field: non-finite value", {}, "coarse/value");
  return from_compact(compact_from_sparse(fine), compact_from_sparse(coarse), is_signed, coarse_margin);
}

DistanceField DistanceField::from_compact(CompactGrid fine, CompactGrid coarse, bool is_signed,
                                          double coarse_margin) {
  if (!(coarse_margin >= 0.0) || !std::isfinite(coarse_margin))
    throw Error("distance field: coarse margin must be a non-negative number", {}, "coarse_margin");
  DistanceField df;
  Impl& im = *df.impl_;
  im.is_signed = is_signed;
  im.coarse_margin = coarse_margin;
  im.fine = Level::make(std::move(fine), "fine");
  im.coarse = Level::make(std::move(coarse), "coarse");
  im.built = true;
  im.set_box();
  return df;
}

SparseGrid DistanceField::fine_sparse() const { return impl_->built ? impl_->fine.sparse() : SparseGrid{}; }
SparseGrid DistanceField::coarse_sparse() const { return impl_->built ? impl_->coarse.sparse() : SparseGrid{}; }
CompactGrid DistanceField::fine_compact() const { return impl_->built ? impl_->fine.grid : CompactGrid{}; }
CompactGrid DistanceField::coarse_compact() const { return impl_->built ? impl_->coarse.grid : CompactGrid{}; }

std::size_t DistanceField::memory_bytes() const {
  if (!impl_ || !impl_->built) return 0;
  return impl_->fine.bytes() + impl_->coarse.bytes();
}

bool DistanceField::empty() const { return !impl_ || !impl_->built; }
bool DistanceField::is_signed() const { return impl_->is_signed; }
double DistanceField::coarse_margin() const { return impl_->coarse_margin; }

double DistanceField::distance(const Vec3& p_object) const {
  if (empty()) return std::numeric_limits<double>::infinity();
  return impl_->query(p_object);
}

void DistanceField::distances(const Vec3* pts, std::size_t n, const Pose& T_object_query,
                              double* out) const {
  if (empty()) {
    std::fill(out, out + n, std::numeric_limits<double>::infinity());
    return;
  }
  CellCache cache;
  for (std::size_t i = 0; i < n; ++i) out[i] = impl_->query(T_object_query * pts[i], &cache);
}

void DistanceField::distances_gradients(const Vec3* pts, std::size_t n, const Pose& T_object_query,
                                        double* out, Vec3* grad) const {
  if (empty()) {
    std::fill(out, out + n, std::numeric_limits<double>::infinity());
    std::fill(grad, grad + n, Vec3::Zero());
    return;
  }
  for (std::size_t i = 0; i < n; ++i) out[i] = impl_->query_gradient(T_object_query * pts[i], grad[i]);
}

}  // namespace geometry
}  // namespace ts
