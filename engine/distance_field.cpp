// Two-level distance field on OpenVDB FloatGrids (see distance_field.hpp). Index ijk stands for
// the object-frame point ijk * voxel (voxel centres).
//
// Fine level: a band of +-fine_band_voxels around the surface. openvdb::tools::meshToVolume
// finds the band and classifies inside/outside (signed fields), but its values come from
// closest triangles propagated through the band, which on dev45 were off by up to 2 mm for a
// few voxels per thousand (thin parts, sharp edges); every band value is therefore replaced by
// the exact distance from the mesh's BVH (MeshIndex), keeping meshToVolume's sign.
//
// Coarse level: dense over the box B = bbox(mesh) grown by coarse_margin and rounded out to
// whole voxels (each point of bbox + margin has its 8 interpolation corners inside), exact BVH
// distances up to coarse_margin + 2 voxels and that cap (a lower bound) beyond; the sign comes
// from the fine level's classification of space (band values, or meshToVolume's inside/outside
// tiles). A coarse meshToVolume run was tried first: its propagated values were off by up to
// 24 mm in thin regions.
//
// Queries interpolate trilinearly from the fine level when its 8 corners are all active, else
// from the coarse level. Outside B nothing is stored; there the distance to the surface is at
// least dist(p, B) + coarse_margin (B shrunk by the margin still contains the mesh's bounding
// box), and that lower bound is returned.
//
// Determinism: meshToVolume runs in a single-thread task arena, so its output cannot depend on
// how TBB splits the work (meanwhile the coarse distances use the other threads); the exact
// values are computed per voxel into their own slots and written serially. Same mesh and
// settings => same grids and bytes for any thread count.
#include "engine/distance_field.hpp"

#include <openvdb/openvdb.h>
#include <openvdb/tools/MeshToVolume.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <mutex>
#include <optional>

namespace ts {

namespace {

void init_openvdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

/// ts::Mesh in OpenVDB's MeshDataAdapter interface, scaled to index space.
struct MeshAdapter {
  const Mesh& mesh;
  double inv_voxel;
  std::size_t polygonCount() const { return mesh.faces.size(); }
  std::size_t pointCount() const { return mesh.vertices.size(); }
  std::size_t vertexCount(std::size_t) const { return 3; }
  void getIndexSpacePoint(std::size_t n, std::size_t v, openvdb::Vec3d& pos) const {
    const Vec3& p = mesh.vertices[static_cast<std::size_t>(mesh.faces[n][static_cast<int>(v)])];
    pos = openvdb::Vec3d(p.x() * inv_voxel, p.y() * inv_voxel, p.z() * inv_voxel);
  }
};

using Grid = openvdb::FloatGrid;
using Accessor = Grid::ConstUnsafeAccessor;   // unregistered: cheap to create per call

Grid::Ptr run_mesh_to_volume(const Mesh& mesh, double voxel, float ext_band, float int_band,
                             bool is_signed) {
  const MeshAdapter adapter{mesh, 1.0 / voxel};
  const auto transform = openvdb::math::Transform::createLinearTransform(voxel);
  // No renormalization: it smooths the values near self-intersections, and the values are
  // replaced by exact distances anyway.
  const int flags = openvdb::tools::DISABLE_RENORMALIZATION |
                    (is_signed ? 0 : openvdb::tools::UNSIGNED_DISTANCE_FIELD);
  Grid::Ptr grid;
  tbb::task_arena serial(1);
  serial.execute([&] {
    grid = openvdb::tools::meshToVolume<Grid>(adapter, *transform, ext_band, int_band, flags);
  });
  return grid;
}

SparseGrid to_sparse(const Grid& grid, double voxel) {
  SparseGrid s;
  s.voxel = voxel;
  std::vector<std::pair<std::array<std::int32_t, 3>, float>> cells;
  cells.reserve(grid.activeVoxelCount());
  for (auto it = grid.cbeginValueOn(); it; ++it) {
    if (it.isVoxelValue()) {
      const auto c = it.getCoord();
      cells.push_back({{c.x(), c.y(), c.z()}, *it});
    } else {   // active tile: every voxel it covers
      openvdb::CoordBBox box;
      it.getBoundingBox(box);
      for (auto c = box.begin(); c; ++c) cells.push_back({{(*c).x(), (*c).y(), (*c).z()}, *it});
    }
  }
  std::sort(cells.begin(), cells.end(),
            [](const auto& a, const auto& b) { return a.first < b.first; });
  s.ijk.reserve(cells.size());
  s.value.reserve(cells.size());
  for (const auto& [ijk, v] : cells) {
    s.ijk.push_back(ijk);
    s.value.push_back(v);
  }
  return s;
}

Grid::Ptr from_sparse_grid(const SparseGrid& s, float background) {
  auto grid = Grid::create(background);
  grid->setTransform(openvdb::math::Transform::createLinearTransform(s.voxel));
  auto acc = grid->getUnsafeAccessor();
  for (std::size_t n = 0; n < s.ijk.size(); ++n)
    acc.setValue(openvdb::Coord(s.ijk[n][0], s.ijk[n][1], s.ijk[n][2]), s.value[n]);
  return grid;
}

/// Trilinear interpolation at index-space point x when all 8 corners are active.
inline bool trilinear(const Accessor& acc, const Vec3& x, double& out, Vec3* grad = nullptr) {
  const double fx = std::floor(x.x()), fy = std::floor(x.y()), fz = std::floor(x.z());
  constexpr double kLimit = 1e9;   // keep far points out of int32 index range
  if (!(std::abs(fx) < kLimit && std::abs(fy) < kLimit && std::abs(fz) < kLimit)) return false;
  const openvdb::Coord c0(static_cast<int>(fx), static_cast<int>(fy), static_cast<int>(fz));
  const double tx = x.x() - fx, ty = x.y() - fy, tz = x.z() - fz;
  float v[8];
  using Leaf = Grid::TreeType::LeafNodeType;
  static_assert(Leaf::DIM == 8, "leaf offsets below assume 8^3 leaves");
  const Leaf* leaf = acc.probeConstLeaf(c0);
  if (leaf && (c0.x() & 7) != 7 && (c0.y() & 7) != 7 && (c0.z() & 7) != 7) {
    // All 8 corners in one leaf (the common case): read them directly, offsets x*64 + y*8 + z.
    const openvdb::Index o0 = Leaf::coordToOffset(c0);
    const auto& mask = leaf->getValueMask();
    const float* data = leaf->buffer().data();
    for (int n = 0; n < 8; ++n) {
      const openvdb::Index o = o0 + ((n & 1) << 6) + (((n >> 1) & 1) << 3) + ((n >> 2) & 1);
      if (!mask.isOn(o)) return false;
      v[n] = data[o];
    }
  } else {
    for (int n = 0; n < 8; ++n) {
      const openvdb::Coord c = c0.offsetBy(n & 1, (n >> 1) & 1, (n >> 2) & 1);
      if (!acc.probeValue(c, v[n])) return false;
    }
  }
  const double x00 = v[0] + tx * (v[1] - v[0]);
  const double x10 = v[2] + tx * (v[3] - v[2]);
  const double x01 = v[4] + tx * (v[5] - v[4]);
  const double x11 = v[6] + tx * (v[7] - v[6]);
  const double y0 = x00 + ty * (x10 - x00);
  const double y1 = x01 + ty * (x11 - x01);
  out = y0 + tz * (y1 - y0);
  if (grad) {
    // The analytic gradient of the trilinear interpolant (per index unit).
    const double dx00 = v[1] - v[0], dx10 = v[3] - v[2], dx01 = v[5] - v[4], dx11 = v[7] - v[6];
    const double dx0 = dx00 + ty * (dx10 - dx00), dx1 = dx01 + ty * (dx11 - dx01);
    (*grad)[0] = dx0 + tz * (dx1 - dx0);
    (*grad)[1] = (x10 - x00) + tz * ((x11 - x01) - (x10 - x00));
    (*grad)[2] = y1 - y0;
  }
  return true;
}

}  // namespace

struct DistanceField::Impl {
  Grid::Ptr fine, coarse;
  double fine_voxel = 0.0, coarse_voxel = 0.0;
  bool is_signed = false;
  double coarse_margin = 0.0;
  Eigen::AlignedBox3d coarse_box;   // object frame, spanned by the coarse voxel centres

  double query(const Accessor& fa, const Accessor& ca, const Vec3& p) const {
    double d;
    if (trilinear(fa, p / fine_voxel, d)) return d;
    if (coarse_box.contains(p) && trilinear(ca, p / coarse_voxel, d)) return d;
    if (!finite(p)) return std::numeric_limits<double>::infinity();
    return std::sqrt(coarse_box.squaredExteriorDistance(p)) + coarse_margin;
  }

  /// As query(), with the gradient of the interpolant (zero where only a bound is known).
  double query_gradient(const Accessor& fa, const Accessor& ca, const Vec3& p, Vec3& g) const {
    double d;
    if (trilinear(fa, p / fine_voxel, d, &g)) {
      g /= fine_voxel;
      return d;
    }
    if (coarse_box.contains(p) && trilinear(ca, p / coarse_voxel, d, &g)) {
      g /= coarse_voxel;
      return d;
    }
    g.setZero();
    if (!finite(p)) return std::numeric_limits<double>::infinity();
    return std::sqrt(coarse_box.squaredExteriorDistance(p)) + coarse_margin;
  }

  void set_box() {
    coarse_box.setEmpty();
    if (!coarse) return;
    const auto bb = coarse->evalActiveVoxelBoundingBox();
    if (bb.empty()) return;
    coarse_box.extend(Vec3(bb.min().x(), bb.min().y(), bb.min().z()) * coarse_voxel);
    coarse_box.extend(Vec3(bb.max().x(), bb.max().y(), bb.max().z()) * coarse_voxel);
  }
};

DistanceField::DistanceField() : impl_(std::make_unique<Impl>()) {}
DistanceField::~DistanceField() = default;
DistanceField::DistanceField(DistanceField&&) noexcept = default;
DistanceField& DistanceField::operator=(DistanceField&&) noexcept = default;

namespace {

/// Throws on what meshToVolume and the BVH cannot take; returns the mesh's bounding box.
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

/// Unsigned distances of the coarse box's voxel centres, column by column along k, each voxel
/// in its own slot: exact up to `cap`, `cap` beyond. Two bounds from the previous voxel of the
/// column (distance 1 voxel away) keep the BVH work small: its closest point bounds d(p) from
/// above (usually tightly: deep inside a sphere the BVH otherwise visits most triangles), and
/// d(prev) - voxel bounds it from below, which skips runs of voxels beyond the cap (searched
/// up to cap + 4 voxels to learn how far beyond they are).
void coarse_distances(const MeshIndex& index, const Eigen::AlignedBox3d& bbox, const openvdb::Coord& cmin,
                      std::size_t ny, std::size_t nz, double cv, double cap, std::vector<float>& dense) {
  const double reach = cap + 4.0 * cv;
  const std::size_t columns = dense.size() / nz;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, columns), [&](const auto& range) {
    for (std::size_t ij = range.begin(); ij != range.end(); ++ij) {
      const int i = cmin.x() + static_cast<int>(ij / ny), j = cmin.y() + static_cast<int>(ij % ny);
      std::optional<Vec3> last;   // closest surface point of the previous voxel
      double lower = 0.0;         // lower bound on the distance of the current voxel
      for (std::size_t kk = 0; kk < nz; ++kk) {
        const Vec3 p = Vec3(i, j, cmin.z() + static_cast<int>(kk)) * cv;
        double d;                   // exact, or a lower bound when >= cap
        std::optional<Vec3> found;
        if (lower < cap && bbox.squaredExteriorDistance(p) < cap * cap) {
          std::optional<ClosestPoint> hit;
          const double bound = last ? (p - *last).norm() * (1.0 + 1e-9) + 1e-12 : reach;
          if (bound < reach) hit = index.closest_within(p, bound);
          if (!hit) hit = index.closest_within(p, reach);
          d = hit ? hit->distance : reach;
          if (hit) found = hit->point;
        } else {
          d = std::max(lower, cap);   // d(p) >= lower, and >= dist(p, bbox) >= cap
        }
        last = found;
        dense[ij * nz + kk] = static_cast<float>(std::min(d, cap));
        lower = d - cv * (1.0 + 1e-9);
      }
    }
  });
}

}  // namespace

DistanceField DistanceField::build(const Mesh& mesh, bool is_signed, const DistanceFieldSettings& s) {
  checked_bounds(mesh, s);
  return build(MeshIndex(mesh), is_signed, s);
}

DistanceField DistanceField::build(const MeshIndex& index, bool is_signed, const DistanceFieldSettings& s) {
  const Mesh& mesh = index.mesh();
  const Eigen::AlignedBox3d bbox = checked_bounds(mesh, s);
  // Refuse settings whose grids cannot fit in memory (dense coarse box; fine band ~ area x band).
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
  im.fine_voxel = s.fine_voxel;
  im.coarse_voxel = s.coarse_voxel;

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

  // The serial meshToVolume run (fine band topology and inside/outside) and the coarse
  // unsigned distances (parallel, on whatever threads the first leaves free) side by side.
  tbb::parallel_invoke(
      [&] {
        im.fine = run_mesh_to_volume(mesh, fv, static_cast<float>(s.fine_band_voxels),
                                     static_cast<float>(s.fine_band_voxels), is_signed);
      },
      [&] { coarse_distances(index, bbox, cmin, ny, nz, cv, cap, dense); });

  // Fine level values: exact.
  {
    std::vector<openvdb::Coord> coords;
    std::vector<float> values;
    coords.reserve(im.fine->activeVoxelCount());
    for (auto it = im.fine->cbeginValueOn(); it; ++it)
      if (it.isVoxelValue()) {
        coords.push_back(it.getCoord());
        values.push_back(*it);
      }
    const double reach = (s.fine_band_voxels + 1.0) * fv;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, coords.size(), 256), [&](const auto& range) {
      for (std::size_t n = range.begin(); n != range.end(); ++n) {
        const openvdb::Coord& c = coords[n];
        const Vec3 p = Vec3(c.x(), c.y(), c.z()) * fv;
        // meshToVolume's value is the distance to one triangle, an upper bound: searching
        // within it (plus float slack) prunes the BVH hard. The full band is the fallback.
        auto hit = index.closest_within(p, std::abs(values[n]) * (1.0 + 1e-5) + 1e-9);
        if (!hit) hit = index.closest_within(p, reach);
        if (!hit) continue;   // not expected inside the band; keep meshToVolume's value
        const auto d = static_cast<float>(hit->distance);
        values[n] = (is_signed && values[n] < 0.0f) ? -d : d;
      }
    });
    auto acc = im.fine->getUnsafeAccessor();
    for (std::size_t n = 0; n < coords.size(); ++n) acc.setValueOnly(coords[n], values[n]);
  }

  // Coarse signs: inside/outside from the fine level (band values, or the sign of the inactive
  // interior/exterior tiles of meshToVolume's flood fill away from the surface).
  if (is_signed) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, nx * ny), [&](const auto& range) {
      auto fine_acc = im.fine->getConstUnsafeAccessor();
      for (std::size_t ij = range.begin(); ij != range.end(); ++ij)
        for (std::size_t kk = 0; kk < nz; ++kk) {
          const Vec3 p = Vec3(cmin.x() + static_cast<int>(ij / ny), cmin.y() + static_cast<int>(ij % ny),
                              cmin.z() + static_cast<int>(kk)) * cv;
          const openvdb::Coord f(static_cast<int>(std::lround(p.x() / fv)), static_cast<int>(std::lround(p.y() / fv)),
                                 static_cast<int>(std::lround(p.z() / fv)));
          if (fine_acc.getValue(f) < 0.0f) dense[ij * nz + kk] = -dense[ij * nz + kk];
        }
    });
  }
  im.coarse = Grid::create(static_cast<float>(cap));
  im.coarse->setTransform(openvdb::math::Transform::createLinearTransform(cv));
  {
    auto acc = im.coarse->getUnsafeAccessor();
    for (std::size_t ij = 0; ij < nx * ny; ++ij)
      for (std::size_t kk = 0; kk < nz; ++kk)
        acc.setValue(openvdb::Coord(cmin.x() + static_cast<int>(ij / ny), cmin.y() + static_cast<int>(ij % ny),
                                    cmin.z() + static_cast<int>(kk)),
                     dense[ij * nz + kk]);
  }
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
  init_openvdb();
  DistanceField df;
  Impl& im = *df.impl_;
  im.is_signed = is_signed;
  im.coarse_margin = coarse_margin;
  im.fine_voxel = fine.voxel;
  im.coarse_voxel = coarse.voxel;
  im.fine = from_sparse_grid(fine, 0.0f);
  im.coarse = from_sparse_grid(coarse, 0.0f);
  im.set_box();
  return df;
}

SparseGrid DistanceField::fine_sparse() const {
  return impl_->fine ? to_sparse(*impl_->fine, impl_->fine_voxel) : SparseGrid{};
}

SparseGrid DistanceField::coarse_sparse() const {
  return impl_->coarse ? to_sparse(*impl_->coarse, impl_->coarse_voxel) : SparseGrid{};
}

std::size_t DistanceField::memory_bytes() const {
  if (!impl_) return 0;
  return (impl_->fine ? impl_->fine->memUsage() : 0) + (impl_->coarse ? impl_->coarse->memUsage() : 0);
}

bool DistanceField::empty() const { return !impl_ || !impl_->coarse; }
bool DistanceField::is_signed() const { return impl_->is_signed; }
double DistanceField::coarse_margin() const { return impl_->coarse_margin; }

double DistanceField::distance(const Vec3& p_object) const {
  if (empty()) return std::numeric_limits<double>::infinity();
  const Accessor fa = impl_->fine->getConstUnsafeAccessor();
  const Accessor ca = impl_->coarse->getConstUnsafeAccessor();
  return impl_->query(fa, ca, p_object);
}

void DistanceField::distances(const Vec3* pts, std::size_t n, const Pose& T_object_query,
                              double* out) const {
  if (empty()) {
    std::fill(out, out + n, std::numeric_limits<double>::infinity());
    return;
  }
  const Accessor fa = impl_->fine->getConstUnsafeAccessor();
  const Accessor ca = impl_->coarse->getConstUnsafeAccessor();
  for (std::size_t i = 0; i < n; ++i) out[i] = impl_->query(fa, ca, T_object_query * pts[i]);
}

void DistanceField::distances_gradients(const Vec3* pts, std::size_t n, const Pose& T_object_query,
                                        double* out, Vec3* grad) const {
  if (empty()) {
    std::fill(out, out + n, std::numeric_limits<double>::infinity());
    std::fill(grad, grad + n, Vec3::Zero());
    return;
  }
  const Accessor fa = impl_->fine->getConstUnsafeAccessor();
  const Accessor ca = impl_->coarse->getConstUnsafeAccessor();
  for (std::size_t i = 0; i < n; ++i)
    out[i] = impl_->query_gradient(fa, ca, T_object_query * pts[i], grad[i]);
}

}  // namespace ts
