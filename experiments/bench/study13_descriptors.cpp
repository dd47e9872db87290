// Study 13 (issue 18 calls it study 10; Hardening's stress study has that number): the paper's Figure 9 (Section 4.3.1). Four local descriptors (FPFH, PFH, SHOT,
// Spin Images; engine/features/descriptors.hpp) on the paper's nine primitive objects and their 19 basic
// shapes, the Euclidean distance between the descriptors of every pair of shapes as a 19 x 19
// matrix per descriptor, and how well each descriptor separates the shapes.
//
//   build/bench/study13_descriptors [--out DIR=study13] [--threads 2] [--noise 0.001] [--seed 1]
//                                   [--grasps 300] [--profile underwater] [--reach 0.005]
//
// Objects (object frame, centred): cubes of side 5 and 10 cm; cylinders of radius 3, 5 and
// 10 cm, height 5 cm (axis z); spheres of radius 3, 5, 10 and 15 cm. Each is scanned by the
// simulated laser scanner (engine/geometry/scanner.hpp, default ScanSettings: 1.5 mm fine cloud), normals
// re-estimated by PCA over 1 cm (the paper's normal radius) and turned outward. Keypoints are
// scan points nearest to 12 target locations per shape, chosen by geometry (a cube's corners,
// edge midpoints, face centres; a cylinder's rims, side at mid-height, caps; points spread over
// a sphere), all further than the 1.5 cm feature radius from any other shape of the object.
//
// Three clouds per object: "scanner" (the scan as it is); "taxel" (each scan point moved by
// Gaussian noise of --noise m per axis, a stand-in for contact points; normals estimated from the
// noisy points); "contacts" (the exploration simulator's tactile contacts: --grasps random grasps
// of the middle finger's distal pad under the --profile noise profile, fused as the recognizer
// fuses them, Eq. 1-2 and the 2 mm voxel filter, then taken into the object frame by the true
// object pose; normals by PCA over 1 cm turned away from the object's centre, as the scene turns
// them away from the contacts' centroid; descriptors from the contacts alone, as a query's). A
// keypoint of the contacts is the contact nearest to its target location, when one lies within
// --reach (the pad does not reach every target: a cube's vertex or a rim is touched only by a
// pad that straddles it); unreached targets are counted and left out.
//
// Output (DIR): D_<cloud>_<descriptor>.tsv, the 19 x 19 matrix of mean distances between the
// keypoints of two shapes (distinct keypoints on the diagonal) divided by the matrix's largest
// entry; separability.tsv; cross.tsv (each noisy or contact keypoint's nearest scanner keypoint:
// of the same shape?); and on stdout the tables. scripts/study13_figure.py draws the maps.
#include "datasets/catalogue/csg.hpp"
#include "datasets/simulator.hpp"
#include "engine/features/descriptors.hpp"
#include "engine/geometry/cloud.hpp"
#include "engine/geometry/mesh.hpp"
#include "engine/geometry/scanner.hpp"
#include "engine/geometry/search.hpp"
#include "engine/touch/fusion.hpp"
#include "experiments/resources.hpp"

#include <CLI/CLI.hpp>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>
#include <vector>

namespace {

using ts::Vec3;
constexpr double kFeatureRadius = 0.015;   // paper: 1.5 cm
constexpr double kNormalRadius = 0.010;    // paper: 1 cm
constexpr int kTargets = 12;               // keypoints per shape

struct Shape {
  std::string name;
  std::vector<Vec3> targets;   // object frame
};

struct Object {
  std::string name;
  ts::Mesh mesh;
  std::vector<Shape> shapes;
};

/// 12 directions: the icosahedron's vertices.
std::vector<Vec3> icosahedron() {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Vec3> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (auto& p : v) p.normalize();
  return v;
}

Object cube(double side) {
  namespace prim = ts::catalogue::prim;
  const double h = side / 2;
  const std::string tag = "cube" + std::to_string(static_cast<int>(std::lround(side * 100)));
  Object o{tag, prim::box(Vec3::Constant(-h), Vec3::Constant(h)), {}};
  Shape vertex{tag + " vertex", {}}, edge{tag + " edge", {}}, face{tag + " face", {}};
  for (int c = 0; c < 8; ++c) vertex.targets.emplace_back(c & 1 ? h : -h, c & 2 ? h : -h, c & 4 ? h : -h);
  for (int axis = 0; axis < 3; ++axis)   // 12 edge midpoints: one coordinate 0, the others +-h
    for (int s = 0; s < 4; ++s) {
      Vec3 p;
      p[axis] = 0;
      p[(axis + 1) % 3] = s & 1 ? h : -h;
      p[(axis + 2) % 3] = s & 2 ? h : -h;
      edge.targets.push_back(p);
    }
  // 6 face centres, and 6 points off-centre by half the margin left by the feature radius
  const double off = 0.5 * (h - kFeatureRadius);
  for (int axis = 0; axis < 3; ++axis)
    for (int s = 0; s < 2; ++s) {
      Vec3 p = Vec3::Zero();
      p[axis] = s ? h : -h;
      face.targets.push_back(p);
      p[(axis + 1) % 3] = s ? off : -off;
      face.targets.push_back(p);
    }
  o.shapes = {vertex, edge, face};
  return o;
}

Object cylinder(double r) {
  namespace prim = ts::catalogue::prim;
  const double hz = 0.025;
  const std::string tag = "cyl" + std::to_string(static_cast<int>(std::lround(r * 100)));
  Object o{tag, prim::cylinder(r, -hz, hz, prim::segments(r, 0.0003)), {}};
  Shape edge{tag + " edge", {}}, side{tag + " curved", {}}, cap{tag + " planar", {}};
  const double tau = 2 * std::numbers::pi;
  for (int k = 0; k < kTargets; ++k) {
    const double a = tau * k / kTargets;
    edge.targets.emplace_back(r * std::cos(a), r * std::sin(a), k % 2 ? hz : -hz);
    side.targets.emplace_back(r * std::cos(a + 0.1), r * std::sin(a + 0.1), 0.0);
  }
  // the two cap centres, and 10 points at half the radius left by the feature radius
  const double rc = 0.5 * (r - kFeatureRadius);
  cap.targets = {Vec3(0, 0, hz), Vec3(0, 0, -hz)};
  for (int k = 0; k < kTargets - 2; ++k) {
    const double a = tau * k / (kTargets - 2);
    cap.targets.emplace_back(rc * std::cos(a), rc * std::sin(a), k % 2 ? hz : -hz);
  }
  o.shapes = {edge, side, cap};
  return o;
}

Object sphere(double r) {
  namespace prim = ts::catalogue::prim;
  const std::string tag = "sph" + std::to_string(static_cast<int>(std::lround(r * 100)));
  Object o{tag, prim::sphere(r, prim::segments(r, 0.0003)), {}};
  Shape surface{tag + " surface", {}};
  for (const Vec3& u : icosahedron()) surface.targets.push_back(r * u);
  o.shapes = {surface};
  return o;
}

/// A cloud with unit normals from PCA over kNormalRadius, turned to agree with `outward`. Where
/// PCA has too few neighbours the normal is `outward` itself when `keep_outward`, else zero (no
/// normal: the point is left out of the descriptors' surface, as a query leaves it out).
ts::PointCloud with_pca_normals(std::vector<Vec3> points, const std::vector<Vec3>& outward, bool keep_outward) {
  ts::NormalSettings ns;
  ns.radius = kNormalRadius;
  std::vector<Vec3> n = ts::estimate_normals(points, ns);
  for (std::size_t i = 0; i < n.size(); ++i) {
    if (n[i].squaredNorm() == 0.0) n[i] = keep_outward ? outward[i] : Vec3::Zero();
    if (n[i].dot(outward[i]) < 0) n[i] = -n[i];
  }
  return {std::move(points), std::move(n)};
}

struct Keypoints {
  std::vector<std::vector<float>> rows;   // valid descriptors
  std::vector<int> shape;                 // shape index of each row
  std::vector<double> shot_agree;         // SHOT only: mass in cosine bins 6..10 (normals along +z of the frame)
  int invalid = 0;
  int unreached = 0;                      // targets with no contact within --reach
};

double sq_distance(const std::vector<float>& a, const std::vector<float>& b) {
  double s = 0;
  for (std::size_t i = 0; i < a.size(); ++i) s += (double(a[i]) - double(b[i])) * (double(a[i]) - double(b[i]));
  return s;
}

/// Mean distance between rows of shapes a and b (distinct rows).
std::vector<double> distance_matrix(const Keypoints& k, int shapes) {
  std::vector<double> sum(shapes * shapes, 0.0), count(shapes * shapes, 0.0);
  for (std::size_t i = 0; i < k.rows.size(); ++i)
    for (std::size_t j = 0; j < k.rows.size(); ++j) {
      if (i == j) continue;
      const double s = sq_distance(k.rows[i], k.rows[j]);
      sum[k.shape[i] * shapes + k.shape[j]] += std::sqrt(s);
      count[k.shape[i] * shapes + k.shape[j]] += 1;
    }
  for (std::size_t c = 0; c < sum.size(); ++c) sum[c] = count[c] > 0 ? sum[c] / count[c] : NAN;
  return sum;
}

/// Fraction of the query rows whose nearest row of `reference` (Euclidean) belongs to the same
/// shape. Rows at exactly the same smallest distance share the credit (identical descriptors of
/// different shapes, e.g. two flat faces, count as a coin toss, not as the lower index). With
/// the same set as query and reference, a row's nearest other row; across clouds, how a query
/// computed on one kind of cloud finds its place among descriptors computed on another (a
/// database is built from scans, queried with contacts).
double nearest_same_shape(const Keypoints& query, const Keypoints& reference) {
  const bool self = &query == &reference;
  double same = 0;
  for (std::size_t i = 0; i < query.rows.size(); ++i) {
    double best = INFINITY;
    int tied = 0, tied_same = 0;
    for (std::size_t j = 0; j < reference.rows.size(); ++j) {
      if (self && i == j) continue;
      const double s = sq_distance(query.rows[i], reference.rows[j]);
      if (s < best) {
        best = s;
        tied = 0;
        tied_same = 0;
      }
      if (s == best) {
        ++tied;
        tied_same += reference.shape[j] == query.shape[i];
      }
    }
    if (tied > 0) same += static_cast<double>(tied_same) / tied;
  }
  return query.rows.empty() ? 0.0 : same / static_cast<double>(query.rows.size());
}

}  // namespace

int main(int argc, char** argv) {
  std::string out_dir = "study13";
  int threads = 2;
  double noise = 0.001;
  std::uint64_t seed = 1;
  std::size_t grasps = 300;
  double reach = 0.005;
  std::string profile = "underwater";
  CLI::App app{"study13_descriptors: the paper's Figure 9, four local descriptors on 19 basic shapes"};
  app.add_option("--out", out_dir, "Output folder (default study13)");
  app.add_option("--threads", threads, "Threads (default 2)")->check(CLI::Range(1, 1024));
  app.add_option("--noise", noise, "Taxel cloud: Gaussian noise per axis, m (default 0.001)")->check(CLI::Range(0.0, 0.01));
  app.add_option("--seed", seed, "Seed of the scanner, the noise and the simulator (default 1)");
  app.add_option("--grasps", grasps, "Contacts cloud: simulated grasps per object (default 300)")->check(CLI::Range(1, 100000));
  app.add_option("--profile", profile, "Contacts cloud: the simulator's noise profile, ideal|underwater|deepsea (default underwater)");
  app.add_option("--reach", reach, "Contacts cloud: a target's keypoint is the nearest contact within this, m (default 0.005)")
      ->check(CLI::Range(1e-4, 0.05));
  CLI11_PARSE(app, argc, argv);
  try {
    const ts::datasets::NoiseSettings noise_profile = ts::datasets::noise_profile(profile);
    tbb::task_arena arena(threads);
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<Object> objects = {cube(0.05), cube(0.10)};
    for (double r : {0.03, 0.05, 0.10}) objects.push_back(cylinder(r));
    for (double r : {0.03, 0.05, 0.10, 0.15}) objects.push_back(sphere(r));
    std::vector<std::string> shape_names;
    for (const auto& o : objects)
      for (const auto& s : o.shapes) shape_names.push_back(s.name);
    const int shapes = static_cast<int>(shape_names.size());
    std::printf("study13_descriptors: %zu objects, %d shapes, feature radius %.3f m, normal radius %.3f m, "
                "taxel noise %.4f m, contacts: %zu grasps, %s noise, reach %.4f m, seed %llu, %d thread(s), %s\n",
                objects.size(), shapes, kFeatureRadius, kNormalRadius, noise, grasps, profile.c_str(), reach,
                static_cast<unsigned long long>(seed), threads, ts::experiments::machine_description().c_str());

    constexpr int kClouds = 3;
    const char* clouds[kClouds] = {"scanner", "taxel", "contacts"};
    std::vector<Keypoints> keys(kClouds * std::size(ts::kAllDescriptors));   // [cloud * 4 + descriptor]
    std::size_t fine_points = 0, contact_points = 0, contact_grasps = 0;
    // Keypoints of one cloud (object frame, unit outward normals; a zero normal: no normal) at
    // the object's targets: the nearest point with a normal, within `reach` (0: any distance).
    const auto describe = [&](int c, const ts::PointCloud& cloud, const Object& o, int shape_base, double reach) {
      ts::PointCloud surf;
      for (std::size_t i = 0; i < cloud.size(); ++i)
        if (cloud.normals[i].squaredNorm() > 0.5) {
          surf.points.push_back(cloud.points[i]);
          surf.normals.push_back(cloud.normals[i]);
        }
      if (surf.size() < 3) throw ts::Error("study 13: " + o.name + ": fewer than 3 points with normals in the " + clouds[c] + " cloud");
      const ts::KdTree3 tree(surf.points);
      std::vector<Vec3> kp, kn;
      std::vector<int> label;
      int unreached = 0;
      for (std::size_t si = 0; si < o.shapes.size(); ++si)
        for (const Vec3& t : o.shapes[si].targets) {
          const auto nearest = tree.nearest(t);
          if (reach > 0 && nearest.sq_distance > reach * reach) {
            ++unreached;
            continue;
          }
          kp.push_back(surf.points[nearest.index]);
          kn.push_back(surf.normals[nearest.index]);
          label.push_back(shape_base + static_cast<int>(si));
        }
      ts::DescriptorSettings ds;
      ds.feature_radius = kFeatureRadius;
      for (std::size_t di = 0; di < std::size(ts::kAllDescriptors); ++di) {
        const ts::Descriptor d = ts::kAllDescriptors[di];
        const ts::Descriptors res = ts::compute_descriptors(d, kp, kn, surf, tree, ds);
        Keypoints& k = keys[c * 4 + di];
        k.unreached += unreached;
        for (std::size_t i = 0; i < kp.size(); ++i) {
          if (!res.valid[i]) {
            ++k.invalid;
            continue;
          }
          const auto row = res.row(i);
          k.rows.emplace_back(row.begin(), row.end());
          k.shape.push_back(label[i]);
          if (d == ts::Descriptor::shot) {
            double agree = 0;
            for (int v = 0; v < 32; ++v)
              for (int b = 6; b <= 10; ++b) agree += double(row[v * 11 + b]) * row[v * 11 + b];
            k.shot_agree.push_back(agree);   // of the squared mass (the norm is 1)
          }
        }
      }
    };
    arena.execute([&] {
      int shape_base = 0;
      for (std::size_t oi = 0; oi < objects.size(); ++oi) {
        const Object& o = objects[oi];
        const ts::MeshIndex index(o.mesh);
        const ts::ScanResult scan = ts::scan_mesh(index, ts::ScanSettings{}, seed + oi);
        fine_points += scan.fine.size();
        for (int c = 0; c < 2; ++c) {
          std::vector<Vec3> pts = scan.fine.points;
          if (c == 1) {
            ts::Rng rng(seed, 10, oi);
            for (Vec3& p : pts) p += noise * Vec3(rng.normal(), rng.normal(), rng.normal());
          }
          describe(c, with_pca_normals(std::move(pts), scan.fine.normals, true), o, shape_base, 0.0);
        }
        // The exploration simulator's contacts, fused as a query's, in the object frame.
        ts::datasets::SimulatorSettings ss;
        ss.grasps = grasps;
        ss.noise = noise_profile;
        ss.seed = seed + oi;
        const ts::datasets::Simulator sim(o.mesh, o.name, ts::Gripper(), ss);
        const ts::datasets::SimulationResult run = sim.run();
        contact_grasps += run.grasps_with_contact;
        const ts::ExplorationClouds ec = ts::exploration_clouds(run.log, run.log.grasps.size());
        const ts::Pose T_object_world = sim.object_pose().inverse();
        std::vector<Vec3> pts;
        pts.reserve(ec.contacts.size());
        for (const Vec3& p : ec.contacts.points) pts.push_back(T_object_world * p);
        contact_points += pts.size();
        const std::vector<Vec3> away = pts;   // away from the centre (the object frame's origin)
        describe(2, with_pca_normals(std::move(pts), away, false), o, shape_base, reach);
        shape_base += static_cast<int>(o.shapes.size());
      }
    });
    std::printf("scans: %zu fine points in all; contacts: %zu after the voxel filter, %zu of %zu grasps touched; %.1f s\n",
                fine_points, contact_points, contact_grasps, grasps * objects.size(),
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());

    std::filesystem::create_directories(out_dir);
    std::ofstream sep(std::filesystem::path(out_dir) / "separability.tsv");
    sep << "cloud\tdescriptor\tkeypoints\tinvalid\tunreached\tbetween\twithin\tratio\tnn_same_shape\n";
    std::printf("\n%-8s %-5s %9s %7s %9s %10s %10s %7s %8s\n", "cloud", "desc", "keypoints", "invalid", "unreached",
                "between", "within", "ratio", "1-NN");
    std::vector<std::vector<double>> matrices(keys.size());
    for (int c = 0; c < kClouds; ++c)
      for (std::size_t di = 0; di < std::size(ts::kAllDescriptors); ++di) {
        const Keypoints& k = keys[c * 4 + di];
        const std::string name = ts::descriptor_name(ts::kAllDescriptors[di]);
        std::vector<double> m = distance_matrix(k, shapes);
        double between = 0, within = 0, top = 0;
        int nb = 0, nw = 0;
        for (int a = 0; a < shapes; ++a)
          for (int b = 0; b < shapes; ++b) {
            const double v = m[a * shapes + b];
            if (!std::isfinite(v)) continue;
            top = std::max(top, v);
            if (a == b) {
              within += v;
              ++nw;
            } else {
              between += v;
              ++nb;
            }
          }
        between /= std::max(nb, 1);
        within /= std::max(nw, 1);
        const double nn = nearest_same_shape(k, k);
        std::printf("%-8s %-5s %9zu %7d %9d %10.4g %10.4g %7.2f %8.3f\n", clouds[c], name.c_str(), k.rows.size(),
                    k.invalid, k.unreached, between, within, between / within, nn);
        sep << clouds[c] << '\t' << name << '\t' << k.rows.size() << '\t' << k.invalid << '\t' << k.unreached << '\t' << between << '\t'
            << within << '\t' << between / within << '\t' << nn << '\n';
        std::ofstream f(std::filesystem::path(out_dir) / ("D_" + std::string(clouds[c]) + "_" + name + ".tsv"));
        f << "shape";
        for (const auto& s : shape_names) f << '\t' << s;
        f << '\n';
        for (int a = 0; a < shapes; ++a) {
          f << shape_names[a];
          for (int b = 0; b < shapes; ++b) f << '\t' << m[a * shapes + b] / top;
          f << '\n';
        }
        for (double& v : m) v /= top;
        matrices[c * 4 + di] = std::move(m);
      }

    // Across clouds: each contact keypoint's nearest scanner keypoint (a query against a
    // database built from scans), and each noisy keypoint's.
    std::printf("\nacross clouds: share of keypoints whose nearest keypoint of the scanner cloud is of the same shape\n");
    std::printf("%-8s", "query");
    for (ts::Descriptor d : ts::kAllDescriptors) std::printf(" %6s", ts::descriptor_name(d).c_str());
    std::printf("\n");
    std::ofstream cross(std::filesystem::path(out_dir) / "cross.tsv");
    cross << "query_cloud\treference_cloud\tdescriptor\tnn_same_shape\n";
    for (int c = 1; c < kClouds; ++c) {
      std::printf("%-8s", clouds[c]);
      for (std::size_t di = 0; di < std::size(ts::kAllDescriptors); ++di) {
        const double nn = nearest_same_shape(keys[c * 4 + di], keys[di]);
        std::printf(" %6.3f", nn);
        cross << clouds[c] << "\tscanner\t" << ts::descriptor_name(ts::kAllDescriptors[di]) << '\t' << nn << '\n';
      }
      std::printf("\n");
    }

    // The paper's observations: per comparison the mean normalized distance between the shapes
    // named (matrix / its largest entry) against the mean normalized within-shape distance of
    // those same shapes (their diagonal entries): a comparison is told apart when the first is
    // well above the second.
    const auto id = [&](const std::string& n) {
      const auto it = std::find(shape_names.begin(), shape_names.end(), n);
      if (it == shape_names.end()) throw ts::Error("study 13: no shape " + n);
      return static_cast<int>(it - shape_names.begin());
    };
    struct Group {
      std::string what;
      std::vector<std::pair<std::string, std::string>> pairs;
    };
    const std::vector<Group> groups = {
        {"cylinder rims vs cube edges", {{"cyl3 edge", "cube5 edge"}, {"cyl5 edge", "cube5 edge"}, {"cyl10 edge", "cube5 edge"},
                                         {"cyl3 edge", "cube10 edge"}, {"cyl5 edge", "cube10 edge"}, {"cyl10 edge", "cube10 edge"}}},
        {"15 cm sphere vs planar faces", {{"sph15 surface", "cube5 face"}, {"sph15 surface", "cube10 face"},
                                          {"sph15 surface", "cyl3 planar"}, {"sph15 surface", "cyl5 planar"},
                                          {"sph15 surface", "cyl10 planar"}}},
        {"cylinder sides of different radii", {{"cyl3 curved", "cyl5 curved"}, {"cyl3 curved", "cyl10 curved"},
                                               {"cyl5 curved", "cyl10 curved"}}},
        {"cylinder rims of different radii", {{"cyl3 edge", "cyl5 edge"}, {"cyl3 edge", "cyl10 edge"}, {"cyl5 edge", "cyl10 edge"}}},
        {"spheres of different radii", {{"sph3 surface", "sph5 surface"}, {"sph3 surface", "sph10 surface"},
                                        {"sph3 surface", "sph15 surface"}, {"sph5 surface", "sph10 surface"},
                                        {"sph5 surface", "sph15 surface"}, {"sph10 surface", "sph15 surface"}}},
        {"planar faces among themselves", {{"cube5 face", "cube10 face"}, {"cube5 face", "cyl3 planar"},
                                           {"cube10 face", "cyl10 planar"}, {"cyl3 planar", "cyl10 planar"}}},
    };
    std::ofstream obs(std::filesystem::path(out_dir) / "observations.tsv");
    obs << "cloud\tcomparison\tdescriptor\tbetween\twithin\n";
    for (int c = 0; c < kClouds; ++c) {
      std::printf("\n%s cloud: between / within, normalized distances (between the shapes compared; within those shapes)\n",
                  clouds[c]);
      std::printf("%-36s", "comparison");
      for (ts::Descriptor d : ts::kAllDescriptors) std::printf(" %15s", ts::descriptor_name(d).c_str());
      std::printf("\n");
      for (const Group& g : groups) {
        std::printf("%-36s", g.what.c_str());
        for (std::size_t di = 0; di < std::size(ts::kAllDescriptors); ++di) {
          const auto& m = matrices[c * 4 + di];
          double between = 0, within = 0;
          for (const auto& [a, b] : g.pairs) {
            const int i = id(a), j = id(b);
            between += m[i * shapes + j];
            within += 0.5 * (m[i * shapes + i] + m[j * shapes + j]);
          }
          between /= static_cast<double>(g.pairs.size());
          within /= static_cast<double>(g.pairs.size());
          std::printf("     %5.3f/%5.3f", between, within);
          obs << clouds[c] << '\t' << g.what << '\t' << ts::descriptor_name(ts::kAllDescriptors[di]) << '\t' << between
              << '\t' << within << '\n';
        }
        std::printf("\n");
      }
    }

    // SHOT's frame on flat patches: its z axis points toward the majority of the neighbours,
    // which on a plane is a tie broken by rounding. Share of the squared descriptor mass in
    // cosine bins 6..10 (normals along the frame's +z): near 1 or near 0 per keypoint.
    std::printf("\nSHOT: keypoints whose frame's z axis agrees with the outward normals (mass in cosine bins 6..10 > 0.5)\n");
    for (int c = 0; c < kClouds; ++c) {
      const Keypoints& k = keys[c * 4 + 2];
      std::printf("%-8s", clouds[c]);
      for (int s = 0; s < shapes; ++s) {
        int n = 0, agree = 0;
        for (std::size_t i = 0; i < k.rows.size(); ++i)
          if (k.shape[i] == s) {
            ++n;
            agree += k.shot_agree[i] > 0.5;
          }
        std::printf(" %s %d/%d;", shape_names[s].c_str(), agree, n);
      }
      std::printf("\n");
    }
    std::printf("\nwrote %s/ (D_*.tsv, separability.tsv, cross.tsv, observations.tsv), %.1f s\n", out_dir.c_str(),
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "study13_descriptors: %s\n", e.what());
    return 1;
  }
  return 0;
}
