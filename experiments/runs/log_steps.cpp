#include "experiments/runs/log_steps.hpp"

#include "engine/recognition/sparse_hypotheses.hpp"

namespace ts::experiments {

RecognizerSettings log_settings(RecognizerSettings rs, const TactileLog& log, bool inside_margin_given) {
  if (log.sensing == Sensing::probe) {
    if (!(rs.evaluate.d_thresh > 0.0)) rs.evaluate.d_thresh = kProbeFreeThreshold;
    if (!inside_margin_given) rs.evaluate.free_inside_margin = kProbeInsideMargin;
  }
  return rs;
}

ExplorationSettings log_exploration(const Database& db, const RecognizerSettings& rs, double contact_voxel) {
  ExplorationSettings es;
  es.contact_voxel = contact_voxel;
  es.free.res_free = rs.evaluate.res_free;
  es.free.s_obj_max = largest_object_extent(db);
  return es;
}

StepInput step_input(Exploration& ex, std::size_t k, Method method) {
  ex.advance_to(k);
  StepInput in;
  in.contacts = ex.contact_cloud();
  if (method == Method::bricpsf || method == Method::ransac_icp_fs) in.free = ex.free_cloud().points;
  in.grasps = ex.grasp_groups();   // unused when the offsets are off
  return in;
}

}  // namespace ts::experiments
