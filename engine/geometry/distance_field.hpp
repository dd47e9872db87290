// Per-object distance field on OpenVDB grids: point-to-surface distance in O(1), used to score
// thousands of hypotheses per step (Eq. 4 and 8). Two levels: a fine narrow band around the
// surface and a coarse grid covering the object's box plus `coarse_margin` (beyond it every
// point is at least coarse_margin from the surface, which Eq. 4 treats as an outlier anyway).
// Voxel values are exact point-to-mesh distances at voxel centres, quantized to 16 bits (a
// power-of-two quantum per level: <= 1 um in the fine band, <= 8 um on the coarse grid);
// queries interpolate trilinearly (error <~ half a voxel where the distance has a kink: the
// surface of an unsigned field, medial axes).
//
// Storage: both levels are bricks of 4^3 voxels (CompactGrid) found through a dense brick
// index over the level's box: 2 bytes a voxel of the band instead of OpenVDB's 4 bytes a voxel
// of every touched 8^3 leaf, and a load is a copy of two arrays. OpenVDB dilates the band from
// the surface's shell (MeshIndex::shell) and is then let go.
#pragma once

#include "engine/core.hpp"
#include "engine/geometry/mesh.hpp"

#include <memory>

namespace ts {
inline namespace geometry {

struct DistanceFieldSettings {
  double fine_voxel = 0.002;     ///< m, voxel of the narrow band
  /// Half-width of the narrow band, in fine voxels. The fine level answers within about
  /// (band - 1) voxels of the surface (6 mm by default), which covers contacts of near-correct
  /// hypotheses under 1 mm noise and a few mm of pose error. 4 rather than 6: a third fewer
  /// voxels to build and store (dev45: ~100-400k fine voxels per object at 4).
  int fine_band_voxels = 4;
  double coarse_voxel = 0.01;    ///< m, voxel of the coarse grid (interpolation error <~ voxel/2)
  double coarse_margin = 0.20;   ///< m, the coarse grid covers the bounding box grown by this
};

/// Sparse voxels of one level, sorted by (i, j, k): the form of databases of schema version 1,
/// and a plain view for tests and diagnostics.
struct SparseGrid {
  double voxel = 0.0;
  std::vector<std::array<std::int32_t, 3>> ijk;
  std::vector<float> value;   ///< signed distance at voxel centres i*voxel (m)
};

/// One level as stored (databases of schema version 2) and held: bricks of 4^3 voxels whose
/// values are quantized to int16 (value * quantum metres; kInactive where the level holds no
/// voxel).
struct CompactGrid {
  static constexpr int kBrick = 4;                         ///< voxels along a brick's edge
  static constexpr int kBrickVoxels = kBrick * kBrick * kBrick;
  static constexpr std::int16_t kInactive = -32768;        ///< a voxel the level does not hold
  double voxel = 0.0;     ///< m
  double quantum = 0.0;   ///< m per unit of value (a power of two)
  /// Brick coordinates (voxel ijk floor-divided by kBrick), strictly increasing.
  std::vector<std::array<std::int32_t, 3>> bricks;
  /// kBrickVoxels values per brick; voxel (a, b, c) of a brick at a*16 + b*4 + c.
  std::vector<std::int16_t> values;
};

class DistanceField {
 public:
  DistanceField();
  ~DistanceField();
  DistanceField(DistanceField&&) noexcept;
  DistanceField& operator=(DistanceField&&) noexcept;

  /// Build from a mesh in the object frame. `is_signed`: negative inside (closed meshes only).
  /// Deterministic: the same mesh and settings give the same grids for any thread count.
  /// Throws ts::Error on bad settings, an empty or invalid mesh, or grids too large to hold.
  static DistanceField build(const Mesh& mesh, bool is_signed, const DistanceFieldSettings& s);
  /// Same, reusing the mesh's BVH (its exact distances fill the grids). Uses TBB inside.
  static DistanceField build(const MeshIndex& mesh, bool is_signed, const DistanceFieldSettings& s);
  /// From the sparse form (values quantized on the way in). Throws ts::Error on sizes that
  /// differ, a non-positive voxel or non-finite values.
  static DistanceField from_sparse(SparseGrid fine, SparseGrid coarse, bool is_signed,
                                   double coarse_margin);
  /// From the stored form. Throws ts::Error naming the field ("fine/bricks", ...) on a bad
  /// voxel or quantum, values not 64 per brick, bricks out of order or spanning a box too
  /// large to index.
  static DistanceField from_compact(CompactGrid fine, CompactGrid coarse, bool is_signed,
                                    double coarse_margin);
  SparseGrid fine_sparse() const;     ///< active voxels, sorted by (i, j, k), values dequantized
  SparseGrid coarse_sparse() const;
  CompactGrid fine_compact() const;
  CompactGrid coarse_compact() const;

  bool empty() const;
  bool is_signed() const;
  std::size_t memory_bytes() const;   ///< bytes held by both grids
  double coarse_margin() const;
  /// Signed distance (m; negative inside when is_signed()), trilinear from the fine level near
  /// the surface, else from the coarse level. Where the surface is farther than about
  /// coarse_margin, and outside the coarse domain, it returns a lower bound >= coarse_margin
  /// (what Eq. 4 needs: d_outlier <= coarse_margin). +inf for a non-finite point or an empty
  /// field. Thread-safe.
  double distance(const Vec3& p_object) const;
  /// Batch form: out[i] = distance(T_object_query * pts[i]); one accessor for the batch.
  void distances(const Vec3* pts, std::size_t n, const Pose& T_object_query, double* out) const;
  /// Same, with grad[i] the gradient of the interpolated distance at T_object_query * pts[i],
  /// in the object frame (per metre; the analytic derivative of the trilinear interpolant, so
  /// it matches finite differences of distance() within a cell). Zero where distance() only
  /// returns a lower bound.
  void distances_gradients(const Vec3* pts, std::size_t n, const Pose& T_object_query,
                           double* out, Vec3* grad) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace geometry
}  // namespace ts
