// The query of one exploration step, prepared once and shared by Batch RANSAC, ICP and the
// evaluation: the cumulative contact cloud PC_cum,t^cont and free-space cloud PC_cum,t^free
// (Section 4.1.2) moved into a local frame centred on the contacts, with PCA normals, FPFH
// features (Section 4.3.1), interior flags for triplet sampling, a fixed evaluation order and an
// observability check.
#pragma once

#include "engine/core.hpp"
#include "engine/features/descriptors.hpp"
#include "engine/features/fpfh.hpp"
#include "engine/geometry/search.hpp"

namespace ts {
inline namespace recognition {

struct SceneSettings {
  double query_voxel = 0.0;          ///< m, voxel filter applied to the contacts first (0: none)
  double boundary_shift = 0.25;      ///< interior test: tangential shift of the neighbourhood
                                     ///< centroid, in feature radii, above which a point is on
                                     ///< a patch boundary (Section 4.3.2, triplet sampling)
  int min_neighbours = 5;            ///< fewer neighbours within the feature radius: boundary
  double free_clearance = 0.0;       ///< m; free points closer than this to a contact are
                                     ///< dropped (a free cloud sampled at res_free has none
                                     ///< nearer than res_free / 2; the recognizer sets d_thresh)
  double observability_eps = 0.01;   ///< eigenvalue ratio of the point-to-plane information
                                     ///< matrix below which a pose DOF counts as unobservable
  Descriptor descriptor = Descriptor::fpfh;  ///< the contacts' descriptor: the database's
};

/// One step's query in a local frame: scene = world - origin (a pure translation).
struct Scene {
  Vec3 origin = Vec3::Zero();          ///< world position of the local frame's origin
  PointCloud contacts;                 ///< local frame; unit normals, zero where undefined
  FeatureRows features;                ///< descriptor per contact (zero where invalid)
  std::vector<std::uint8_t> feature_valid;  ///< descriptor defined (normal and neighbours present)
  std::vector<std::uint8_t> interior;  ///< not on a patch boundary (triplet sampling)
  KdTree3 tree;                        ///< over contacts.points
  std::vector<Vec3> free_space;        ///< local frame, in a fixed pseudo-random order
  std::vector<std::uint32_t> order;    ///< fixed pseudo-random permutation of the contacts:
                                       ///< every prefix is a representative subset
  std::vector<Vec3> ordered;           ///< contacts.points permuted by `order` (evaluation)
  double diameter = 0.0;               ///< m, largest distance between two contacts
  double rms_radius = 0.0;             ///< m, RMS distance of the contacts from their centroid
  int unobservable_dof = 6;            ///< pose DOF the contact geometry leaves unconstrained
  std::size_t dropped_non_finite = 0;  ///< input points ignored because not finite
  std::size_t dropped_free = 0;        ///< free points dropped as too close to a contact
  double feature_radius = 0.0;         ///< m, radius the features were computed with
  GraspGroups grasps;                  ///< local frame; the contacts grouped by grasp, or empty
  /// The step's support plane, when found and support.sink_m > 0 (the stage "scene" sets it):
  /// nothing of the object lies below its support, so a hypothesis that puts the object deeper
  /// than `margin` below it loses up to `cost` of ln wt (evaluate: sink_penalty), unless it
  /// explains the plane's contacts as its own face (most of `on_plane` within `tolerance` of its
  /// surface): the plane found may be a face of the object.
  struct Floor {
    bool on = false;
    Vec3 normal = Vec3::UnitZ();       ///< unit, up (the free side)
    double offset = 0.0;               ///< local frame: normal . x = offset
    double margin = 0.0;               ///< m, depth below it that costs nothing
    double cost = 0.0;                 ///< ln wt lost at twice `margin` and deeper
    double tolerance = 0.0;            ///< m, a contact this near the object is its own
    std::vector<Vec3> on_plane;        ///< local frame, some of the contacts the plane explains
  } floor;

  bool has_free_space() const { return !free_space.empty(); }
  /// T_world_object from T_scene_object and back.
  Pose to_world(const Pose& T_scene_object) const;
  Pose to_scene(const Pose& T_world_object) const;
};

/// Build the scene of one step. Contact normals: PCA within fpfh.normal_radius, oriented like
/// the input normals when the cloud has them, else away from the contact centroid. Never throws
/// on data (non-finite points are dropped and counted); an empty or degenerate cloud gives a
/// scene without valid features.
Scene prepare_scene(const PointCloud& contacts_world, const std::vector<Vec3>& free_world,
                    const FpfhSettings& fpfh, const SceneSettings& settings, std::uint64_t seed,
                    std::uint64_t step);

/// Attach the contacts grouped by grasp (world frame) to a scene, in its local frame;
/// non-finite points are dropped and grasps left empty are removed.
void set_grasps(Scene& scene, const GraspGroups& grasps_world);

/// Number of pose DOF left unobservable by points with normals (eigenvalues of the 6x6
/// point-to-plane information matrix below eps * largest; rotations scaled by the RMS radius).
int unobservable_dof(const std::vector<Vec3>& points, const std::vector<Vec3>& normals, double eps);

}  // namespace recognition
}  // namespace ts
