// Database object construction (Section 4.2): simulated laser scan of the CAD model, voxel
// filtered dense and coarse clouds, FPFH features of the coarse points (Section 4.3.1), and the
// object's distance field for hypothesis scoring.
#include "engine/database/database.hpp"
#include "engine/detail.hpp"
#include "engine/geometry/cloud.hpp"
#include "engine/geometry/mesh.hpp"

#include <chrono>

namespace ts {
inline namespace database {

namespace {

using detail::seconds_since;

/// PCA normals (the kind the query side computes from contacts), turned to agree with the
/// scanner's outward normals. Where PCA has too few neighbours the scanner normal is used.
std::vector<Vec3> oriented_pca_normals(const PointCloud& scan, double radius) {
  std::vector<Vec3> n = estimate_normals(scan.points, NormalSettings{radius, 3});
  for (std::size_t i = 0; i < n.size(); ++i) {
    if (n[i].squaredNorm() == 0.0) n[i] = scan.normals[i];
    else if (n[i].dot(scan.normals[i]) < 0.0) n[i] = -n[i];
  }
  return n;
}

}  // namespace

BuiltObject build_object(const Mesh& object_frame_mesh, ObjectInfo info,
                         const DatabaseSettings& settings, std::uint64_t seed) {
  BuiltObject out;
  const auto box = mesh_bounds(object_frame_mesh);
  info.extent = box.isEmpty() ? Vec3::Zero() : Vec3(box.sizes());
  info.closed = mesh_topology(object_frame_mesh).closed();

  // 1. Simulated laser scan: fine cloud on the surface with outward normals, coarse keypoints.
  auto t0 = std::chrono::steady_clock::now();
  const MeshIndex index(object_frame_mesh);
  ScanResult scan = scan_mesh(index, settings.scan, seed);
  out.timings.scan_s = seconds_since(t0);

  // 2. Features: PCA normals on the fine cloud, the database's descriptor (FPFH by default) at
  //    every coarse point from the fine cloud.
  //    The coarse points are fine points (voxel representatives), so the same selection on the
  //    fine cloud carrying PCA normals gives the keypoints with their PCA normals.
  t0 = std::chrono::steady_clock::now();
  PointCloud surface;
  surface.points = scan.fine.points;
  surface.normals = oriented_pca_normals(scan.fine, settings.fpfh.normal_radius);
  const PointCloud keypoints = voxel_representatives(surface, settings.scan.coarse_voxel);
  const KdTree3 tree(surface.points);
  DescriptorSettings ds;
  ds.feature_radius = settings.fpfh.feature_radius;
  const Descriptors desc =
      compute_descriptors(settings.descriptor, keypoints.points, keypoints.normals, surface, tree, ds);
  // Keypoints without a usable neighbourhood (zero histogram) are left out of the database.
  out.features.features = FeatureRows(desc.dim);
  for (std::size_t i = 0; i < keypoints.size(); ++i) {
    if (!desc.valid[i]) continue;
    out.features.coarse.points.push_back(keypoints.points[i]);
    out.features.coarse.normals.push_back(keypoints.normals[i]);
    out.features.features.push_back(desc.row(i).data());
  }
  out.timings.features_s = seconds_since(t0);

  // 3. Distance field (signed only where inside/outside means something).
  t0 = std::chrono::steady_clock::now();
  out.field = DistanceField::build(index, info.closed, settings.field);   // the scan's BVH
  out.timings.field_s = seconds_since(t0);

  info.fine_points = scan.fine.size();
  info.coarse_points = out.features.coarse.size();
  info.coverage = scan.coverage;
  out.info = std::move(info);
  out.fine = std::move(scan.fine);  // exact face normals, outward
  out.mesh = object_frame_mesh;
  return out;
}

}  // namespace database
}  // namespace ts
