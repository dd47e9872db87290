// Per-object distance field on OpenVDB grids: point-to-surface distance in O(1), used to score
// thousands of hypotheses per step (Eq. 4 and 8). Two levels: a fine narrow band around the
// surface and a coarse grid covering the object's box plus `coarse_margin` (beyond it every
// point is at least coarse_margin from the surface, which Eq. 4 treats as an outlier anyway).
// Voxel values are exact point-to-mesh distances (float) at voxel centres; queries interpolate
// trilinearly (error <~ half a voxel where the distance has a kink: the surface of an unsigned
// field, medial axes). The coarse level is a dense box, so coarse_sparse() lists every voxel of
// it in (i, j, k) order and can be stored as origin + shape + values.
#pragma once

#include "engine/core.hpp"
#include "engine/mesh.hpp"

#include <memory>

namespace ts {

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

/// Sparse voxels of one level, sorted by (i, j, k): the serialized form stored in HDF5.
struct SparseGrid {
  double voxel = 0.0;
  std::vector<std::array<std::int32_t, 3>> ijk;
  std::vector<float> value;   ///< signed distance at voxel centres i*voxel (m)
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
  static DistanceField from_sparse(SparseGrid fine, SparseGrid coarse, bool is_signed,
                                   double coarse_margin);
  SparseGrid fine_sparse() const;
  SparseGrid coarse_sparse() const;

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

}  // namespace ts
