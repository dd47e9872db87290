#include "engine/geometry/kabsch.hpp"
#include "engine/geometry/pose_error.hpp"
#include "engine/recognition/icp.hpp"
#include "recognition_fixture.hpp"

#include <doctest/doctest.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <vector>

using namespace ts;

namespace {

struct IcpCase {
  std::shared_ptr<test::TestSource> src = test::make_source();
  Database db{src};
  std::size_t obj = 4;  // the wedge: no symmetry
  Pose truth = test::random_pose(31, Vec3(0.2, 0.1, -0.3));
  Scene scene(int patches, double noise = 0.0, std::uint64_t seed = 5) {
    const PointCloud c = test::touch(src->fines[obj], truth, patches, seed, 0.0, noise);
    return prepare_scene(c, {}, db.settings().fpfh, {}, 1, 1);
  }
};

Pose perturbed(const Pose& T, double dist, double deg, std::uint64_t seed) {
  Rng rng(seed);
  Pose P = T;
  P.translation() += dist * rng.unit_vector();
  P.linear() = Eigen::AngleAxisd(deg * test::kPi / 180, rng.unit_vector()).toRotationMatrix() * P.linear();
  return P;
}

}  // namespace

TEST_CASE("ICP converges from a perturbed pose to the truth (both metrics)") {
  IcpCase c;
  const Scene sc = c.scene(12);
  const GeometryRef pinned = c.db.geometry(c.obj);
  const ObjectGeometry& geo = *pinned;
  for (IcpMetric metric : {IcpMetric::point_to_point, IcpMetric::point_to_plane, IcpMetric::field}) {
    IcpSettings s;
    s.metric = metric;
    s.max_iterations = 100;
    int iterations = 0;
    for (int trial = 0; trial < 5; ++trial) {
      const Pose start = perturbed(sc.to_scene(c.truth), 0.004, 4.0, 100 + trial);
      const IcpResult r = icp(sc, geo, start, s);
      CHECK(r.valid);
      CHECK(r.converged);
      const PoseError e = pose_error(sc.to_world(r.T_scene_object), c.truth);
      CHECK(e.position_m < 5e-4);
      CHECK(e.orientation_deg < 0.5);
      iterations += r.iterations;
    }
    MESSAGE((metric == IcpMetric::point_to_plane ? "point-to-plane"
             : metric == IcpMetric::field        ? "distance field"
                                                 : "point-to-point")
            << ": mean iterations " << iterations / 5.0);
  }
}

TEST_CASE("Trimmed ICP resists outlying contacts") {
  IcpCase c;
  Scene sc = c.scene(12);
  // Replace every 5th contact (in evaluation order) by an outlier 3 cm off the surface.
  Rng rng(9);
  for (std::size_t i = 0; i < sc.ordered.size(); i += 5) sc.ordered[i] += 0.03 * rng.unit_vector();
  const GeometryRef pinned = c.db.geometry(c.obj);
  const ObjectGeometry& geo = *pinned;
  const Pose start = perturbed(sc.to_scene(c.truth), 0.003, 3.0, 7);
  IcpSettings plain;
  plain.max_iterations = 100;
  IcpSettings trimmed = plain;
  trimmed.trim_fraction = 0.75;
  const PoseError ep = pose_error(sc.to_world(icp(sc, geo, start, plain).T_scene_object), c.truth);
  const PoseError et = pose_error(sc.to_world(icp(sc, geo, start, trimmed).T_scene_object), c.truth);
  CHECK(et.position_m < 1e-3);
  CHECK(et.orientation_deg < 1.0);
  CHECK(et.position_m < ep.position_m);
}

TEST_CASE("ICP's pair gate leaves contacts beyond it out of the fit (the background term's ICP)") {
  IcpCase c;
  Scene sc = c.scene(12);
  // Every 5th contact (in evaluation order) moved 2.5 cm off the surface along its normal side
  // (within the field's band, where it pulls an ungated fit): a neighbour's or the seabed's.
  Rng rng(9);
  for (std::size_t i = 0; i < sc.ordered.size(); i += 5) sc.ordered[i] += 0.025 * rng.unit_vector();
  const GeometryRef pinned = c.db.geometry(c.obj);
  const ObjectGeometry& geo = *pinned;
  const Pose start = perturbed(sc.to_scene(c.truth), 0.003, 3.0, 7);
  IcpSettings plain;
  plain.max_iterations = 100;
  IcpSettings gated = plain;
  gated.max_correspondence = 0.01;
  const IcpResult rg = icp(sc, geo, start, gated);
  const PoseError ep = pose_error(sc.to_world(icp(sc, geo, start, plain).T_scene_object), c.truth);
  const PoseError eg = pose_error(sc.to_world(rg.T_scene_object), c.truth);
  CHECK(eg.position_m < 1e-3);
  CHECK(eg.orientation_deg < 2.0);
  CHECK(eg.position_m < ep.position_m);
  CHECK(eg.orientation_deg < ep.orientation_deg);
  CHECK(rg.pairs < sc.ordered.size());   // the moved contacts were not paired
}

TEST_CASE("ICP on degenerate input keeps the initial pose and says so") {
  IcpCase c;
  const GeometryRef pinned = c.db.geometry(c.obj);
  const ObjectGeometry& geo = *pinned;
  Scene tiny = c.scene(1);
  tiny.ordered.resize(2);
  const Pose start = test::random_pose(3, Vec3(0, 0, 0));
  const IcpResult r = icp(tiny, geo, start, {});
  CHECK_FALSE(r.valid);
  CHECK(r.T_scene_object.isApprox(start));
  Pose bad = start;
  bad.translation().x() = std::nan("");
  const IcpResult rb = icp(c.scene(3), geo, bad, {});
  CHECK_FALSE(rb.valid);
}

TEST_CASE("ICP: bitwise the same poses on 1 thread and with many refinements at once on 2") {
  // icp() itself is serial; what a thread count could change is state shared through the
  // geometry it reads (k-d tree, distance field) or an order of summation. Each start is refined
  // alone on one thread, then all of them at once on two (as refine_all runs them); every
  // metric must give the same bits.
  IcpCase c;
  const Scene sc = c.scene(8, 0.0005);
  const GeometryRef pinned = c.db.geometry(c.obj);
  const ObjectGeometry& geo = *pinned;
  constexpr int kStarts = 12;
  std::vector<Pose> starts;
  for (int k = 0; k < kStarts; ++k) starts.push_back(perturbed(sc.to_scene(c.truth), 0.004, 4.0, 1 + k));
  for (IcpMetric metric : {IcpMetric::point_to_point, IcpMetric::point_to_plane, IcpMetric::field}) {
    IcpSettings s;
    s.metric = metric;
    s.trim_fraction = 0.9;
    std::vector<IcpResult> one(kStarts), two(kStarts);
    tbb::task_arena(1).execute([&] {
      for (int k = 0; k < kStarts; ++k) one[k] = icp(sc, geo, starts[k], s);
    });
    tbb::task_arena(2).execute([&] {
      tbb::parallel_for(0, kStarts, [&](int k) { two[k] = icp(sc, geo, starts[k], s); });
    });
    for (int k = 0; k < kStarts; ++k) {
      CAPTURE(k);
      CHECK(one[k].valid);
      CHECK(one[k].T_scene_object.matrix() == two[k].T_scene_object.matrix());
      CHECK(one[k].iterations == two[k].iterations);
      CHECK(one[k].rms == two[k].rms);
      CHECK(one[k].pairs == two[k].pairs);
    }
  }
}
