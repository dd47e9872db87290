// Stage "scene": the query in a local frame (Section 4.1.2 clouds; Section 4.3.1 normals and
// features), the evaluations the step uses, and the objects large enough to span the contacts.
// Reads RecognizerSettings::scene (SceneSettings: lengths in m), evaluate, ransac.size_slack.
#include "engine/recognition/pipeline/stages.hpp"

#include "engine/detail.hpp"

#include <algorithm>
#include <string>

namespace ts::inline recognition::pipeline {

namespace {

/// Distinct points, up to 3 (exact coordinates: the scene's points are as given, less the origin).
std::size_t distinct_points(const std::vector<Vec3>& p) {
  std::vector<Vec3> seen;
  for (const Vec3& q : p) {
    if (std::find(seen.begin(), seen.end(), q) == seen.end()) seen.push_back(q);
    if (seen.size() >= 3) break;
  }
  return seen.size();
}

/// Contacts on a found support plane that a hypothesis sunk below it is checked against.
constexpr std::size_t kFloorWitnesses = 32;

class SceneStage final : public Stage {
 public:
  std::string_view name() const override { return "scene"; }

  void run(StepContext& c) const override {
    const auto t0 = detail::Clock::now();
    const RecognizerSettings& s = c.s;
    SceneSettings scs = s.scene;
    scs.descriptor = c.db.settings().descriptor;   // the queries' descriptor is the database's
    if (scs.free_clearance < 0.0)  // automatic: d_thresh of Eq. 8
      scs.free_clearance = s.evaluate.d_thresh > 0.0 ? s.evaluate.d_thresh : 0.5 * s.evaluate.res_free;
    c.scene = prepare_scene(c.contacts(), c.free_world, c.db.settings().fpfh, scs, s.seed, c.step_u());
    if (s.evaluate.grasp_offset_sigma > 0.0 || s.twins.rivals > 0) set_grasps(c.scene, c.grasp_groups());
    if (const SupportSurface& sup = c.res.support;
        s.support.sink > 0.0 && sup.found && sup.shape == SupportSurface::Shape::plane) {
      c.scene.floor.on = true;
      c.scene.floor.normal = sup.normal;
      c.scene.floor.offset = sup.offset - sup.normal.dot(c.scene.origin);
      c.scene.floor.margin = s.support.sink;
      c.scene.floor.cost = s.support.sink_cost;
      c.scene.floor.tolerance = s.support.tolerance;
      // Up to kFloorWitnesses of the contacts it explains, evenly through the cloud's order.
      std::vector<Vec3> on;
      for (const Vec3& x : c.contacts_world.points)
        if (sup.explains(x, s.support.tolerance)) on.push_back(x - c.scene.origin);
      const std::size_t keep = std::min(on.size(), kFloorWitnesses);
      for (std::size_t k = 0; k < keep; ++k) c.scene.floor.on_plane.push_back(on[k * on.size() / keep]);
    }
    StepResult& res = c.res;
    res.times.prepare_s = detail::seconds_since(t0);
    res.contacts = c.scene.contacts.size();
    res.free_points = c.scene.free_space.size();
    res.unobservable_dof = c.scene.unobservable_dof;
    res.pose_ambiguous = c.scene.unobservable_dof > 0;
    if (c.scene.contacts.empty()) {   // nothing to match: the state waits for data
      c.finished = "no contacts";
      return;
    }
    // A pose needs three points off one spot: fewer distinct contacts (repeats of one reading,
    // a cloud of two points) neither pose a triplet nor tell the state anything.
    if (const std::size_t n = distinct_points(c.scene.contacts.points); n < 3) {
      c.finished = "fewer than 3 distinct contacts (" + std::to_string(n) + ")";
      return;
    }
    const bool with_free = s.method == Method::ransac_icp_fs || s.method == Method::bricpsf;
    c.ev = s.evaluate;
    c.ev.free_space = c.ev.free_space && with_free;
    // Per-grasp offsets score refined hypotheses only: the raw RANSAC candidates are ranked by
    // the plain Eq. 4 (thousands of them), which only chooses the ones to refine.
    c.grasp_fit = c.ev.grasp_offset_sigma > 0.0 && !c.scene.grasps.empty();
    c.ev_raw = c.ev;
    c.ev_raw.grasp_offset_sigma = 0.0;
    c.allowed = objects_spanning(c.scene, c.db, s.ransac.size_slack);
    if (!s.objects.empty())
      for (std::size_t o = 0; o < c.allowed.size(); ++o) c.allowed[o] = c.allowed[o] && s.objects[o];
  }
};

}  // namespace

std::unique_ptr<const Stage> scene_stage() { return std::make_unique<SceneStage>(); }

}  // namespace ts::recognition::pipeline
