// Stage "observability": which pose DOF the contacts leave free, judged on the answer's surface
// when the contacts carry too few normals to judge it themselves (isolated points: fingertips, a
// probe, a points-only cloud; scene.cpp's unobservable_dof needs three contacts with normals,
// and is trusted only when at least half the contacts have one).
// Each contact within evaluate.d_outlier (and evaluate.outlier_m when set) of the answer's model constrains the pose along the
// model's normal there: the same point-to-plane information, with the model's normals. A sphere
// leaves 3 DOF, a cylinder's side 1 (its axis' rotation; the translation along it too without
// an end), a box's faces none. Reads SceneSettings::observability_eps (the eigenvalue ratio) and
// EvaluateSettings::d_outlier and outlier_m (m).
#include "engine/recognition/pipeline/stages.hpp"

namespace ts::inline recognition::pipeline {

namespace {

class ObservabilityStage final : public Stage {
 public:
  std::string_view name() const override { return "observability"; }

  std::string skip_reason(const StepContext& c) const override {
    if (!c.res.valid) return "no answer";
    // The scene's normals judge it when most contacts have one (patches); a few normals of
    // chance neighbours among isolated points (fingertips across grasps) do not.
    std::size_t with = 0;
    for (const Vec3& n : c.scene.contacts.normals) with += n.squaredNorm() > 0.5;
    if (c.scene.unobservable_dof < 6 && 2 * with >= c.scene.contacts.size()) return "the contacts' normals judge it";
    return {};
  }

  void run(StepContext& c) const override {
    const Working& h = c.next[c.rule.chosen];
    const GeometryPins geometry = pin(c.db, std::vector<Working>{h});
    const ObjectGeometry& geo = geometry[h.cand.object];
    // The surface with its normals: the resident one, else read for this object alone (the
    // database keeps surfaces only when a stage needs them).
    PointCloud read;
    KdTree3 read_tree;
    const bool resident = !geo.fine.empty() && geo.fine.has_normals();
    if (!resident) {
      read = c.db.load_fine(h.cand.object);
      if (read.empty() || !read.has_normals()) return;
      read_tree = KdTree3(read.points);
    }
    const PointCloud& fine = resident ? geo.fine : read;
    const KdTree3& tree = resident ? geo.tree : read_tree;
    const Pose& T = h.cand.T_scene_object;
    const Pose to_object = T.inverse();
    // Beyond the background term's cap (evaluate.outlier_m) a contact constrains nothing: it may
    // be the seabed's or a neighbour's.
    const double d = std::min(c.s.evaluate.d_outlier > 0.0 ? c.s.evaluate.d_outlier : std::numeric_limits<double>::infinity(),
                              eq::background(c.s.evaluate));
    std::vector<Vec3> points, normals;
    for (const Vec3& p : c.scene.contacts.points) {
      const Neighbour nb = tree.nearest(to_object * p);
      if (!(nb.sq_distance <= d * d)) continue;
      points.push_back(p);
      normals.push_back(T.linear() * fine.normals[nb.index]);
    }
    c.res.unobservable_dof = unobservable_dof(points, normals, c.s.scene.observability_eps);
    c.res.pose_ambiguous = c.res.unobservable_dof > 0;
    c.res.observability_from_model = true;
  }
};

}  // namespace

std::unique_ptr<const Stage> observability_stage() { return std::make_unique<ObservabilityStage>(); }

}  // namespace ts::recognition::pipeline
