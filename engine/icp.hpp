// Pose refinement by ICP (Section 4.4, Algorithm 1 line 4; Section 5.4): the scene's contacts
// are matched to the nearest points of the hypothesis' object (its fine cloud, k-d tree) and the
// pose re-fitted until it stops moving: point-to-point (Besl & McKay 1992, Kabsch fit) or
// point-to-plane (Chen & Medioni 1992, Gauss-Newton on the object's normals, which converges in
// far fewer iterations on the smooth and flat parts tactile data mostly covers). An optional
// correspondence gate and trimming (Chetverikov et al. 2002) make it robust to outlying contacts.
#pragma once

#include "engine/database.hpp"
#include "engine/scene.hpp"

namespace ts {

enum class IcpMetric {
  point_to_point,   ///< nearest fine-cloud point (k-d tree), Kabsch: the paper's ICP
  point_to_plane,   ///< nearest fine-cloud point and its normal (k-d tree), Gauss-Newton
  field             ///< the object's distance field: residual d(y), normal = grad d (forward
                    ///< differences), Gauss-Newton; O(1) per contact, no tree search
};

struct IcpSettings {
  IcpMetric metric = IcpMetric::field;  ///< point_to_point: the paper's ICP (falls back to
                                       ///< point_to_plane when the object has no field)
  int max_iterations = 15;            ///< upper bound on iterations
  double min_translation = 1e-4;      ///< m; converged when an update moves less than this ...
  double min_rotation_deg = 0.01;     ///< ... and turns less than this (degrees)
  double max_correspondence = 0.0;    ///< m; pairs farther apart are ignored (0: keep all)
  double trim_fraction = 1.0;         ///< trimmed ICP: fit the closest share of pairs (1: all)
  double gradient_step = 0.0005;      ///< m, finite-difference step of the field metric
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

}  // namespace ts
