#include "engine/recognition/pipeline/compose.hpp"

#include "engine/recognition/pipeline/stages.hpp"

#include <utility>

namespace ts::inline recognition::pipeline {

namespace {

using Factory = std::unique_ptr<const Stage> (*)();

/// name -> factory, in the order a step may run them.
const std::vector<std::pair<std::string_view, Factory>>& stage_factories() {
  static const std::vector<std::pair<std::string_view, Factory>> all = {
      {"support", support_stage},
      {"scene", scene_stage},
      {"shape_prior", shape_prior_stage},
      {"survivors", survivors_source},
      {"early_stop", early_stop_stage},
      {"ransac", ransac_source},
      {"sparse", sparse_source},
      {"shortlist", shortlist_stage},
      {"select", select_batch},
      {"icp_each", icp_each},
      {"sequential_filter", sequential_filter},
      {"pose_transfer", pose_transfer_source},
      {"posteriors", posteriors_stage},
      {"answer_rule", answer_rule_stage},
      {"state", state_stage},
      {"observability", observability_stage},
      {"attribution", attribution_stage},
  };
  return all;
}

}  // namespace

std::vector<std::string_view> method_stages(Method m) {
  // Every method: the scene, then the sources (the shape prior orders RANSAC's objects on large
  // databases; the feature-free triplets join RANSAC's candidates), then the shortlist. BRICPSF
  // evolves the previous state first (Algorithm 1, lines 3-7), which may explain the step
  // without new hypotheses (early_stop); it takes no draw, so the sources' candidates are the
  // same either way.
  std::vector<std::string_view> s = {"support", "scene", "shape_prior"};
  if (m == Method::bricpsf) s.insert(s.end(), {"survivors", "early_stop"});
  s.insert(s.end(), {"ransac", "sparse", "shortlist"});
  switch (m) {
    case Method::batch_ransac:    // Section 4.3.2: the best candidates by Eq. 5
      s.push_back("select");
      break;
    case Method::ransac_icp:      // Section 5.4: every candidate refined by ICP, Eq. 5
    case Method::ransac_icp_fs:   // ... Eq. 6 (the scene stage turns the free-space term on)
      s.push_back("icp_each");
      break;
    case Method::bricpsf:         // Algorithm 1: lines 8-9
      s.push_back("sequential_filter");
      break;
  }
  // Large databases: the leader's pose tried on the objects that fit there. Then the answer, and
  // (contacts without normals) the pose DOF it leaves free, and what explains each contact.
  for (std::string_view n : {"pose_transfer", "posteriors", "answer_rule", "state", "observability", "attribution"})
    s.push_back(n);
  return s;
}

std::vector<std::string_view> known_stages() {
  std::vector<std::string_view> out;
  for (const auto& [name, make] : stage_factories()) out.push_back(name);
  return out;
}

Pipeline compose(const std::vector<std::string_view>& names) {
  Pipeline out;
  for (std::string_view n : names) {
    Factory make = nullptr;
    for (const auto& [name, f] : stage_factories())
      if (name == n) make = f;
    if (!make) {
      std::string known;
      for (std::string_view k : known_stages()) known += (known.empty() ? "" : ", ") + std::string(k);
      throw Error("unknown stage '" + std::string(n) + "' (known: " + known + ")", {}, "pipeline.stages");
    }
    out.push_back(make());
  }
  return out;
}

}  // namespace ts::recognition::pipeline
