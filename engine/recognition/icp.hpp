// Pose refinement by ICP (Section 4.4, Algorithm 1 line 4; Section 5.4): the scene's contacts
// are matched to the nearest points of the hypothesis' object (its fine cloud, k-d tree) and the
// pose re-fitted until it stops moving: point-to-point (Besl & McKay 1992, Kabsch fit) or
// point-to-plane (Chen & Medioni 1992, Gauss-Newton on the object's normals, which converges in
// far fewer iterations on the smooth and flat parts tactile data mostly covers). An optional
// correspondence gate and trimming (Chetverikov et al. 2002) make it robust to outlying contacts.
#pragma once

#include "engine/database/database.hpp"
#include "engine/recognition/scene.hpp"

namespace ts {
inline namespace recognition {

enum class IcpMetric {
  point_to_point,   ///< nearest fine-cloud point (k-d tree), Kabsch: the paper's ICP
  point_to_plane,   ///< nearest fine-cloud point and its normal (k-d tree), Gauss-Newton
  field             ///< the object's distance field: residual d(y), normal = grad d (the
                    ///< trilinear interpolant's analytic gradient), Gauss-Newton; O(1) per
                    ///< contact, no tree search
};

struct IcpSettings {
  IcpMetric metric = IcpMetric::field;  ///< point_to_point: the paper's ICP (falls back to
                                       ///< point_to_plane when the object has no field)
  int max_iterations = 15;            ///< upper bound on iterations
  double min_translation = 1e-4;      ///< m; converged when an update moves less than this ...
  double min_rotation_deg = 0.01;     ///< ... and turns less than this (degrees), or when
  double min_improvement = 0.001;     ///< ... the RMS improved by less than this fraction in
                                      ///< two successive iterations
  double max_correspondence = 0.0;    ///< m; pairs farther apart are ignored (0: keep all; the
                                      ///< Recognizer makes it 2 x evaluate.outlier_m when the
                                      ///< background term is on)
  double trim_fraction = 1.0;         ///< trimmed ICP: fit the closest share of pairs (1: all)
  std::size_t max_points = 128;       ///< contacts used, a fixed prefix of the scene's
                                      ///< evaluation order (0: all)
};

struct IcpResult {
  Pose T_scene_object = Pose::Identity();
  bool valid = false;       ///< a finite pose (false: degenerate input; the initial pose is kept)
  bool converged = false;   ///< the update fell below the thresholds before max_iterations
  int iterations = 0;
  double rms = 0.0;         ///< m, RMS distance of the fitted pairs at the last fit
  std::size_t pairs = 0;    ///< pairs in the last fit
};

/// Refine T_scene_object of one hypothesis. Deterministic; thread-safe (read-only inputs).
IcpResult icp(const Scene& scene, const ObjectGeometry& geometry, const Pose& T_init,
              const IcpSettings& settings);

/// Conditions at or above this mean a singular system (an eigenvalue at rounding level or 0).
constexpr double kIcpSingular = 1e16;

/// The point-to-plane normal equations H x = -g (H = sum J J^T, J = [(y - c) x n; n], c the
/// centroid of the paired contacts y, n the object's normals) that one ICP iteration would
/// solve at a pose, and how well they are conditioned. Diagnostics only: icp() is unchanged.
struct IcpSystem {
  std::size_t pairs = 0;        ///< contacts paired (as icp() pairs them: gate, trim, field band)
  double radius = 0.0;          ///< m, RMS distance of the paired contacts from their centroid
  double condition = kIcpSingular;  ///< largest / smallest eigenvalue of H with the rotation
                                ///< columns divided by `radius` (unitless, the same for a
                                ///< scaled copy of the scene and object); capped at
                                ///< kIcpSingular, which it also is without a system
  double condition_raw = kIcpSingular;  ///< the same of H as solved (metres, radians), capped
  int unobservable_dof = 6;     ///< eigenvalues of the unitless H below 0.01 x the largest
  bool valid = false;           ///< at least 6 pairs with normals (otherwise H is singular)
};

/// The system at T_scene_object (point-to-point settings are treated as point-to-plane, with
/// the fine cloud's normals). Deterministic; thread-safe. Never NaN or infinite.
IcpSystem icp_system(const Scene& scene, const ObjectGeometry& geometry,
                     const Pose& T_scene_object, const IcpSettings& settings);

}  // namespace recognition
}  // namespace ts
