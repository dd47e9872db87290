// Touchstone's four local descriptors against the Point Cloud Library's own (issue 18): the
// same keypoints, surface, normals and radius given to engine/features/descriptors.hpp and to PCL's
// FPFHEstimation, PFHEstimation, SHOTEstimation and SpinImageEstimation (image width 8,
// support angle cos 0, no minimum neighbour count), and their outputs compared row by row;
// with the time of each. Built only where PCL 1.13 is found (Debian's libpcl-dev, or the private
// copy scripts/descriptors_vs_pcl unpacks); Touchstone itself never links PCL.
//
//   scripts/descriptors_vs_pcl [--threads 2] [--noise 0.001] [--seed 1]
//
// Clouds: the paper's nine primitive objects of study 13 (cubes of 5 and 10 cm, cylinders of
// radius 3, 5 and 10 cm and height 5 cm, spheres of radius 3, 5, 10 and 15 cm) scanned by the
// simulated laser scanner (1.5 mm fine cloud), as scanned and with Gaussian noise of --noise m
// per axis; normals by PCA over 1 cm turned outward; keypoints the fine points representing each
// 1 cm voxel (a database's are 5 mm: PCL's PFH takes minutes on those). Radii 10 mm
// (recognition) and 15 mm (the paper's comparison).
//
// A row is "equal" when its relative difference |t - p| / |p| (Euclidean) is below 1e-3, and
// both sides must agree on which rows are valid (PCL marks an invalid row with NaN). PCL works
// in single precision, Touchstone in double: a neighbour at the support's edge or a pair feature
// on a bin boundary may fall on the other side, which moves one vote, so a few rows differ by
// more than rounding; the table gives the share of equal rows, the 99th percentile and the
// largest relative difference. SHOT's local frame takes each axis's sign from the majority of the
// neighbours on its side (>= 0); on an exactly planar patch every neighbour lies on the plane up
// to rounding, single and double precision round differently, and the frame flips: "planar"
// counts the rows that differ whose neighbourhood is planar within 1 micrometre (the smallest
// eigenvalue of its covariance).
#define PCL_NO_PRECOMPILE   // the templates from the headers: no dependence on which instantiations the library holds
#include <pcl/features/fpfh.h>
#include <pcl/features/fpfh_omp.h>
#include <pcl/features/pfh.h>
#include <pcl/features/shot.h>
#include <pcl/features/shot_omp.h>
#include <pcl/features/spin_image.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>

#include "datasets/catalogue/csg.hpp"
#include "engine/features/descriptors.hpp"
#include "engine/geometry/cloud.hpp"
#include "engine/geometry/mesh.hpp"
#include "engine/geometry/scanner.hpp"
#include "engine/geometry/search.hpp"
#include "experiments/resources.hpp"

#include <CLI/CLI.hpp>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace {

using ts::Vec3;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

struct Cloud {
  ts::PointCloud surface;            // points with unit outward normals
  std::vector<Vec3> keypoints, keypoint_normals;
};

/// The nine objects' clouds, scanned, with `noise` m per axis when > 0.
std::vector<Cloud> primitive_clouds(double noise, std::uint64_t seed) {
  namespace prim = ts::catalogue::prim;
  std::vector<ts::Mesh> meshes;
  for (double side : {0.05, 0.10}) meshes.push_back(prim::box(Vec3::Constant(-side / 2), Vec3::Constant(side / 2)));
  for (double r : {0.03, 0.05, 0.10}) meshes.push_back(prim::cylinder(r, -0.025, 0.025, prim::segments(r, 0.0003)));
  for (double r : {0.03, 0.05, 0.10, 0.15}) meshes.push_back(prim::sphere(r, prim::segments(r, 0.0003)));
  std::vector<Cloud> out;
  for (std::size_t m = 0; m < meshes.size(); ++m) {
    const ts::ScanResult scan = ts::scan_mesh(ts::MeshIndex(meshes[m]), ts::ScanSettings{}, seed + m);
    std::vector<Vec3> pts = scan.fine.points;
    if (noise > 0) {
      ts::Rng rng(seed, 10, m);
      for (Vec3& p : pts) p += noise * Vec3(rng.normal(), rng.normal(), rng.normal());
    }
    std::vector<Vec3> n = ts::estimate_normals(pts, ts::NormalSettings{0.010, 3});
    for (std::size_t i = 0; i < n.size(); ++i) {
      if (n[i].squaredNorm() == 0.0) n[i] = scan.fine.normals[i];
      n[i].normalize();
      if (n[i].dot(scan.fine.normals[i]) < 0) n[i] = -n[i];
    }
    Cloud c;
    c.surface = ts::PointCloud{std::move(pts), std::move(n)};
    const ts::PointCloud keys = ts::voxel_representatives(c.surface, 0.010);
    c.keypoints = keys.points;
    c.keypoint_normals = keys.normals;
    out.push_back(std::move(c));
  }
  return out;
}

pcl::PointCloud<pcl::PointXYZ>::Ptr pcl_points(const std::vector<Vec3>& v) {
  auto c = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  for (const Vec3& p : v) c->push_back(pcl::PointXYZ(static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z())));
  return c;
}

pcl::PointCloud<pcl::Normal>::Ptr pcl_normals(const std::vector<Vec3>& v) {
  auto c = pcl::make_shared<pcl::PointCloud<pcl::Normal>>();
  for (const Vec3& n : v) c->push_back(pcl::Normal(static_cast<float>(n.x()), static_cast<float>(n.y()), static_cast<float>(n.z())));
  return c;
}

/// PCL's rows of one cloud: NaN rows (PCL's invalid) as they come.
template <typename Estimator, typename Signature, std::size_t N>
std::vector<std::array<float, N>> run_pcl(Estimator& est, const Cloud& c, double radius, bool normals_of_keypoints,
                                          float (Signature::*field)[N]) {
  est.setInputCloud(pcl_points(c.keypoints));
  est.setSearchSurface(pcl_points(c.surface.points));
  est.setInputNormals(pcl_normals(normals_of_keypoints ? c.keypoint_normals : c.surface.normals));
  est.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
  est.setRadiusSearch(radius);
  pcl::PointCloud<Signature> out;
  est.compute(out);
  std::vector<std::array<float, N>> rows(out.size());
  for (std::size_t i = 0; i < out.size(); ++i) std::copy(std::begin(out[i].*field), std::end(out[i].*field), rows[i].begin());
  return rows;
}

struct Comparison {
  std::size_t rows = 0, valid_both = 0, valid_disagree = 0, equal = 0;
  std::size_t differ_planar = 0;   // rows not equal whose neighbourhood is planar
  std::vector<double> rel;   // relative differences of rows valid on both sides
  double ours_s = 0, pcl_s = 0, pcl_omp_s = -1;
};

/// Whether the neighbourhood of `q` within `radius` lies on a plane within 1 micrometre.
bool planar(const Cloud& c, const ts::KdTree3& tree, const Vec3& q, double radius) {
  const auto nb = tree.radius(q, radius);
  if (nb.size() < 3) return false;
  Vec3 mean = Vec3::Zero();
  for (const auto& b : nb) mean += c.surface.points[b.index];
  mean /= static_cast<double>(nb.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& b : nb) {
    const Vec3 d = c.surface.points[b.index] - mean;
    cov += d * d.transpose();
  }
  cov /= static_cast<double>(nb.size());
  const double smallest = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov, Eigen::EigenvaluesOnly).eigenvalues()[0];
  return std::sqrt(std::max(0.0, smallest)) < 1e-6;
}

template <std::size_t N>
void compare(Comparison& cmp, const ts::Descriptors& ours, const std::vector<std::array<float, N>>& theirs,
             const Cloud& c, const ts::KdTree3& tree, double radius) {
  if (theirs.size() != ours.size() || ours.dim != static_cast<int>(N))
    throw ts::Error("bench_descriptors_pcl: PCL returned " + std::to_string(theirs.size()) + " rows of " + std::to_string(N) +
                    ", Touchstone " + std::to_string(ours.size()) + " of " + std::to_string(ours.dim));
  for (std::size_t i = 0; i < ours.size(); ++i) {
    ++cmp.rows;
    const bool pcl_valid = std::all_of(theirs[i].begin(), theirs[i].end(), [](float v) { return std::isfinite(v); });
    if (pcl_valid != static_cast<bool>(ours.valid[i])) {
      ++cmp.valid_disagree;
      continue;
    }
    if (!pcl_valid) continue;
    ++cmp.valid_both;
    double diff = 0, norm = 0;
    const auto row = ours.row(i);
    for (std::size_t k = 0; k < N; ++k) {
      diff += (double(row[k]) - double(theirs[i][k])) * (double(row[k]) - double(theirs[i][k]));
      norm += double(theirs[i][k]) * double(theirs[i][k]);
    }
    const double r = norm > 0 ? std::sqrt(diff / norm) : std::sqrt(diff);
    cmp.rel.push_back(r);
    cmp.equal += r < 1e-3;
    if (r >= 1e-3) cmp.differ_planar += planar(c, tree, c.keypoints[i], radius);
  }
}

}  // namespace

int main(int argc, char** argv) {
  int threads = 2;
  double noise = 0.001;
  std::uint64_t seed = 1;
  CLI::App app{"bench_descriptors_pcl: Touchstone's FPFH, PFH, SHOT and Spin Images against PCL's"};
  app.add_option("--threads", threads, "Touchstone's threads, and PCL's OpenMP estimators' (default 2)")->check(CLI::Range(1, 1024));
  app.add_option("--noise", noise, "The noisy clouds: Gaussian noise per axis, m (default 0.001)")->check(CLI::Range(0.0, 0.01));
  app.add_option("--seed", seed, "Seed of the scanner and the noise (default 1)");
  CLI11_PARSE(app, argc, argv);
  try {
    tbb::task_arena arena(threads);
    std::printf("bench_descriptors_pcl: PCL %s, %d thread(s) (PCL's PFH, Spin Images and single-thread FPFH/SHOT: 1), %s\n",
                PCL_VERSION_PRETTY, threads, ts::experiments::machine_description().c_str());
    std::printf("%-8s %6s %-5s %7s %7s %9s %8s %7s %10s %10s %9s %9s %9s\n", "clouds", "radius", "desc", "rows", "valid",
                "disagree", "equal", "planar", "rel p99", "rel max", "ours s", "PCL s", "PCL omp s");
    int status = 0;
    for (const double cloud_noise : {0.0, noise}) {
      const std::vector<Cloud> clouds = arena.execute([&] { return primitive_clouds(cloud_noise, seed); });
      for (const double radius : {0.010, 0.015}) {
        for (const ts::Descriptor d : ts::kAllDescriptors) {
          Comparison cmp;
          for (const Cloud& c : clouds) {
            ts::DescriptorSettings ds;
            ds.feature_radius = radius;
            const ts::KdTree3 tree(c.surface.points);
            auto t0 = Clock::now();
            const ts::Descriptors ours = arena.execute(
                [&] { return ts::compute_descriptors(d, c.keypoints, c.keypoint_normals, c.surface, tree, ds); });
            cmp.ours_s += seconds_since(t0);
            t0 = Clock::now();
            switch (d) {
              case ts::Descriptor::fpfh: {
                pcl::FPFHEstimation<pcl::PointXYZ, pcl::Normal, pcl::FPFHSignature33> est;
                compare(cmp, ours, run_pcl<decltype(est), pcl::FPFHSignature33, 33>(est, c, radius, false, &pcl::FPFHSignature33::histogram), c, tree, radius);
                cmp.pcl_s += seconds_since(t0);
                t0 = Clock::now();
                pcl::FPFHEstimationOMP<pcl::PointXYZ, pcl::Normal, pcl::FPFHSignature33> omp(static_cast<unsigned>(threads));
                run_pcl<decltype(omp), pcl::FPFHSignature33, 33>(omp, c, radius, false, &pcl::FPFHSignature33::histogram);
                cmp.pcl_omp_s = std::max(0.0, cmp.pcl_omp_s) + seconds_since(t0);
                break;
              }
              case ts::Descriptor::pfh: {
                pcl::PFHEstimation<pcl::PointXYZ, pcl::Normal, pcl::PFHSignature125> est;
                compare(cmp, ours, run_pcl<decltype(est), pcl::PFHSignature125, 125>(est, c, radius, false, &pcl::PFHSignature125::histogram), c, tree, radius);
                cmp.pcl_s += seconds_since(t0);
                break;
              }
              case ts::Descriptor::shot: {
                pcl::SHOTEstimation<pcl::PointXYZ, pcl::Normal, pcl::SHOT352> est;
                compare(cmp, ours, run_pcl<decltype(est), pcl::SHOT352, 352>(est, c, radius, false, &pcl::SHOT352::descriptor), c, tree, radius);
                cmp.pcl_s += seconds_since(t0);
                t0 = Clock::now();
                pcl::SHOTEstimationOMP<pcl::PointXYZ, pcl::Normal, pcl::SHOT352> omp(static_cast<unsigned>(threads));
                run_pcl<decltype(omp), pcl::SHOT352, 352>(omp, c, radius, false, &pcl::SHOT352::descriptor);
                cmp.pcl_omp_s = std::max(0.0, cmp.pcl_omp_s) + seconds_since(t0);
                break;
              }
              case ts::Descriptor::spin: {
                pcl::SpinImageEstimation<pcl::PointXYZ, pcl::Normal, pcl::Histogram<153>> est(8, 0.0, 0);
                compare(cmp, ours, run_pcl<decltype(est), pcl::Histogram<153>, 153>(est, c, radius, true, &pcl::Histogram<153>::histogram), c, tree, radius);
                cmp.pcl_s += seconds_since(t0);
                break;
              }
            }
          }
          std::sort(cmp.rel.begin(), cmp.rel.end());
          const double p99 = cmp.rel.empty() ? 0.0 : cmp.rel[std::min(cmp.rel.size() - 1, cmp.rel.size() * 99 / 100)];
          const double max = cmp.rel.empty() ? 0.0 : cmp.rel.back();
          char omp[32] = "-";
          if (cmp.pcl_omp_s >= 0) std::snprintf(omp, sizeof omp, "%.3f", cmp.pcl_omp_s);
          std::printf("%-8s %6.3f %-5s %7zu %7zu %9zu %7.2f%% %7zu %10.2e %10.2e %9.3f %9.3f %9s\n",
                      cloud_noise > 0 ? "noisy" : "scanner", radius, ts::descriptor_name(d).c_str(), cmp.rows,
                      cmp.valid_both, cmp.valid_disagree,
                      cmp.valid_both ? 100.0 * static_cast<double>(cmp.equal) / static_cast<double>(cmp.valid_both) : 0.0,
                      cmp.differ_planar, p99, max, cmp.ours_s, cmp.pcl_s, omp);
          std::fflush(stdout);
          if (cmp.valid_disagree > 0) status = 1;
        }
      }
    }
    return status;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_descriptors_pcl: %s\n", e.what());
    return 1;
  }
}
