#include "experiments/params/parameters.hpp"

#include "experiments/params/config.hpp"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <set>
#include <sstream>
#include <type_traits>

namespace ts::experiments {

MethodSettings MethodSettings::preset(const std::string& name) {
  MethodSettings m;
  if (name == "paper")
    m.recognizer = RecognizerSettings::paper();
  else if (name == "improved")
    m.recognizer = RecognizerSettings::improved();
  else
    throw Error("unknown preset '" + name + "' (paper | improved)", {}, "preset");
  return m;
}

namespace {

using Type = Parameter::Type;
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kLarge = 100000000;   // the cap of counts (an implausibly large value)

/// A parameter's description (key, kind, type, unit, range, the paper's value, help, older names).
Parameter setting(std::string key, Parameter::Kind kind, Type type, std::string unit, double lo, double hi,
                  std::string paper, std::string help, std::vector<std::string> aliases = {}) {
  Parameter p;
  p.key = std::move(key);
  p.kind = kind;
  p.type = type;
  p.unit = std::move(unit);
  p.lo = lo;
  p.hi = hi;
  p.paper = std::move(paper);
  p.help = std::move(help);
  p.aliases = std::move(aliases);
  return p;
}

/// A method parameter reading and writing one field: `field` is a generic lambda returning a
/// reference to it in a MethodSettings (const or not).
template <class F>
Parameter declare(std::string key, Type type, std::string unit, double lo, double hi,
                  std::string paper, std::string help, std::vector<std::string> aliases, F field) {
  Parameter p = setting(std::move(key), Parameter::Kind::method, type, std::move(unit), lo, hi, std::move(paper),
                        std::move(help), std::move(aliases));
  p.get = [field](const MethodSettings& m) {
    const auto& x = field(m);
    if constexpr (std::is_enum_v<std::decay_t<decltype(x)>>)
      return static_cast<double>(static_cast<int>(x));
    else
      return static_cast<double>(x);
  };
  p.set = [field](MethodSettings& m, double v) {
    auto& x = field(m);
    using T = std::decay_t<decltype(x)>;
    if constexpr (std::is_enum_v<T>)
      x = static_cast<T>(static_cast<int>(v));
    else if constexpr (std::is_same_v<T, bool>)
      x = v != 0.0;
    else
      x = static_cast<T>(v);
  };
  return p;
}

template <class F>
Parameter integer(std::string key, double lo, double hi, std::string paper, std::string help,
                  std::vector<std::string> aliases, F field) {
  return declare(std::move(key), Type::integer, "", lo, hi, std::move(paper), std::move(help),
                 std::move(aliases), field);
}
template <class F>
Parameter real(std::string key, std::string unit, double lo, double hi, std::string paper,
               std::string help, std::vector<std::string> aliases, F field) {
  return declare(std::move(key), Type::real, std::move(unit), lo, hi, std::move(paper),
                 std::move(help), std::move(aliases), field);
}
template <class F>
Parameter boolean(std::string key, std::string help, std::vector<std::string> aliases, F field) {
  return declare(std::move(key), Type::boolean, "", 0, 1, "", std::move(help), std::move(aliases),
                 field);
}

/// One of `choices`, held by the method settings as its index (an integer field).
template <class F>
Parameter choice(std::string key, std::vector<std::string> choices, std::string paper, std::string help,
                 std::vector<std::string> aliases, F field) {
  const double hi = static_cast<double>(choices.size()) - 1.0;
  Parameter p = declare(std::move(key), Type::choice, "", 0, hi, std::move(paper), std::move(help),
                        std::move(aliases), field);
  p.choices = std::move(choices);
  return p;
}

/// An extension the improved preset turns on only on databases of more objects than a threshold.
template <class F>
Parameter any_database(Parameter p, F threshold) {
  p.min_database = [threshold](MethodSettings& m) -> std::size_t& { return threshold(m); };
  return p;
}

#define TS_FIELD(expr) [](auto& m) -> auto& { return m.expr; }

std::vector<Parameter> declaration() {
  std::vector<Parameter> d;
  // Batch RANSAC (Section 4.3.2).
  d.push_back(integer("ransac.triplets", 1, 1000000, "15 (Section 5.5)", "N, triplets sampled from the contacts per step",
                      {"-N", "--triplets", "N"}, TS_FIELD(recognizer.ransac.triplets)));
  d.push_back(integer("ransac.registrations", 1, 1000000, "200 (Section 5.5)", "R, registrations per triplet",
                      {"-R", "--registrations", "R"}, TS_FIELD(recognizer.ransac.registrations)));
  d.push_back(integer("ransac.prune", 1, kLarge, "3000 (Section 5.3)", "W, nearest database features per triplet point",
                      {"-W", "--prune", "W"}, TS_FIELD(recognizer.ransac.prune_w)));
  d.push_back(integer("ransac.prune_per_object", 0, kLarge, "",
                      "Extension: the W_obj nearest features of every object per triplet point (0: the global W)",
                      {"--prune-per-object", "W_obj", "W_per_object"}, TS_FIELD(recognizer.ransac.prune_per_object)));
  d.push_back(any_database(
      integer("ransac.prune_blocks", 0, 1000000, "",
              "Extension: per-object pruning reads each object's B blocks of 128 features nearest to the query "
              "(approximate; 0: exact)",
              {"--prune-blocks", "prune_blocks"}, TS_FIELD(recognizer.ransac.prune_blocks)),
      TS_FIELD(recognizer.ransac.prune_blocks_min_database)));
  d.push_back(integer("ransac.object_draws", 0, kLarge, "",
                      "Extension: with per-object pruning, objects searched per triplet, the next of a shuffled "
                      "order (0: every object)",
                      {"--object-draws", "object_draws"}, TS_FIELD(recognizer.ransac.object_draws)));
  d.push_back(any_database(
      integer("ransac.prior_draws", 0, kLarge, "",
              "Extension: of each triplet's object draws, this many are the step's best objects by the shape "
              "prior (0: off)",
              {"--prior-draws", "prior_draws"}, TS_FIELD(recognizer.ransac.prior_draws)),
      TS_FIELD(recognizer.prior_min_database)));
  d.push_back(real("ransac.distance_tolerance_m", "m", 1e-9, 1, "",
                   "Triplet registration: allowed difference of each pair's distance",
                   {"--distance-tolerance", "distance_tolerance"}, TS_FIELD(recognizer.ransac.distance_tolerance)));
  d.push_back(real("ransac.min_spacing_m", "m", 0, 1, "", "Minimum distance between triplet points (0: the feature radius)",
                   {"--min-spacing", "min_spacing"}, TS_FIELD(recognizer.ransac.min_spacing)));
  d.push_back(real("ransac.normal_tolerance_deg", "deg", 0, 90, "",
                   "Extension: registered pairs agree in normal angles within this (0: off)",
                   {"--normal-tolerance", "normal_tolerance_deg"}, TS_FIELD(recognizer.ransac.normal_tolerance_deg)));
  d.push_back(real("ransac.min_sv_ratio", "", 0, 1, "",
                   "Triangles with sigma2/sigma1 below this are rejected as near-collinear",
                   {"min_sv_ratio"}, TS_FIELD(recognizer.ransac.min_sv_ratio)));
  d.push_back(real("ransac.size_slack_m", "m", 0, 1, "",
                   "Objects shorter than the contacts' extent minus this are not registered",
                   {"size_slack"}, TS_FIELD(recognizer.ransac.size_slack)));
  // Feature search.
  d.push_back(boolean("index.exact", "Exact feature search (false: approximate randomized k-d trees)",
                      {"--exact-features", "index_exact"}, TS_FIELD(recognizer.index.exact)));
  d.push_back(integer("index.checks", 1, 1 << 30, "", "Approximate feature search: leaves visited per query",
                      {"--feature-checks", "index_checks"}, TS_FIELD(recognizer.index.checks)));
  // Evaluation (Eq. 4-9).
  d.push_back(real("ransac.d_outlier_m", "m", 1e-6, 100, "0.20 (Section 5.3)", "Outlier distance of Eq. 4",
                   {"--d-outlier", "d_outlier"}, TS_FIELD(recognizer.evaluate.d_outlier)));
  d.push_back(real("evaluate.outlier_m", "m", 0, 100, "",
                   "Extension, the background term: a contact farther than this from the object costs what "
                   "one at this distance does (it may have touched the seabed or a neighbour; 0: off, Eq. 4 alone)",
                   {"--outlier", "outlier"}, TS_FIELD(recognizer.evaluate.outlier_m)));
  d.push_back(real("bricpsf.lambda", "", 0, kInf, "0.02 (Section 5.5)", "Free-space weight of Eq. 9",
                   {"--lambda", "lambda"}, TS_FIELD(recognizer.evaluate.lambda)));
  d.push_back(real("evaluate.res_free_m", "m", 1e-6, 10, "0.04 (Section 5.5)",
                   "Free-space resolution; d_thresh = res_free/2 unless set",
                   {"--res-free", "res_free"}, TS_FIELD(recognizer.evaluate.res_free)));
  d.push_back(real("evaluate.d_thresh_m", "m", 0, 10, "0.02 (Section 5.5)",
                   "Eq. 8 threshold: free points nearer the surface are penalized (0: res_free/2; a probe: 0.0001)",
                   {"--d-thresh", "d_thresh"}, TS_FIELD(recognizer.evaluate.d_thresh)));
  d.push_back(boolean("evaluate.free_inside_penalty", "Extension: free space inside a closed object costs the full penalty",
                      {"--free-inside-penalty", "free_inside_penalty"}, TS_FIELD(recognizer.evaluate.free_inside_penalty)));
  d.push_back(real("evaluate.free_inside_margin_m", "m", 0, 10, "",
                   "A free point inside an object costs the full penalty only deeper than this (a probe: 0.01)",
                   {"--free-inside-margin", "free_inside_margin"}, TS_FIELD(recognizer.evaluate.free_inside_margin)));
  d.push_back(real("evaluate.grasp_offset_sigma_m", "m", 0, 1, "",
                   "Extension: arm position error per grasp (per axis); each grasp's contacts may shift by a "
                   "fitted offset before Eq. 4 (0: off; tactile logs only)",
                   {"--grasp-offset-sigma", "grasp_offset_sigma"}, TS_FIELD(recognizer.evaluate.grasp_offset_sigma)));
  d.push_back(real("evaluate.grasp_contact_sigma_m", "m", 1e-9, 1, "", "Contact noise assumed by the per-grasp offset fit",
                   {"grasp_contact_sigma"}, TS_FIELD(recognizer.evaluate.grasp_contact_sigma)));
  d.push_back(integer("evaluate.grasp_offset_iterations", 0, 1000, "", "Gauss-Newton iterations of the per-grasp offset fit",
                      {"grasp_iterations"}, TS_FIELD(recognizer.evaluate.grasp_offset_iterations)));
  d.push_back(integer("evaluate.grasp_fit_points", 1, 1000000, "", "Contacts per grasp of the per-grasp offset fit",
                      {"grasp_fit_points"}, TS_FIELD(recognizer.evaluate.grasp_fit_points)));
  // BRICPSF (Algorithm 1).
  d.push_back(integer("bricpsf.hypotheses", 1, 1000000, "100 (Section 5.5)", "n_p, hypotheses kept per step",
                      {"--n-p", "n_p"}, TS_FIELD(recognizer.n_p)));
  d.push_back(real("bricpsf.psi", "", 0, 1, "0.8 (Section 5.5)", "Psi, share of evolved old hypotheses kept",
                   {"--psi", "psi"}, TS_FIELD(recognizer.psi)));
  d.push_back(boolean("bricpsf.refine_new", "Extension: ICP on new RANSAC hypotheses before they join",
                      {"--refine-new", "refine_new"}, TS_FIELD(recognizer.refine_new)));
  d.push_back(integer("bricpsf.refine_pool", 0, kLarge, "",
                      "Extension: best RANSAC candidates considered (and refined) for the new hypotheses (0: (1-Psi) n_p)",
                      {"--refine-pool", "refine_pool"}, TS_FIELD(recognizer.refine_pool)));
  d.push_back(integer("bricpsf.new_per_object", 0, kLarge, "",
                      "Extension: at most this many new hypotheses per object and step (0: no cap)",
                      {"--new-per-object", "new_per_object"}, TS_FIELD(recognizer.new_per_object)));
  d.push_back(boolean("bricpsf.dedupe", "Extension: drop hypotheses that duplicate a better one (2 mm, 2 degrees)",
                      {"--dedupe", "dedupe"}, TS_FIELD(recognizer.dedupe)));
  d.push_back(boolean("early_stop.enabled",
                      "Extension: a step whose contacts the leading survivor alone explains within noise proposes "
                      "no new hypotheses (bricpsf)",
                      {"--early-stop"}, TS_FIELD(recognizer.early_stop)));
  d.push_back(real("early_stop.rms_sigma", "", 0, 3, "",
                   "Early stop: the contacts' RMS distance (each clamped at 3 sigma) within this many "
                   "evaluate.grasp_contact_sigma, and none beyond 3",
                   {}, TS_FIELD(recognizer.early_stop_rms_sigma)));
  d.push_back(real("early_stop.free_conflict", "", 0, 1, "",
                   "Early stop: at most this Eq. 8 error per free point",
                   {}, TS_FIELD(recognizer.early_stop_free_conflict)));
  d.push_back(integer("early_stop.max_database", 0, kLarge, "",
                      "Early stop: acts on databases of at most this many objects (0: any)",
                      {}, TS_FIELD(recognizer.early_stop_max_database)));
  // ICP.
  d.push_back(integer("icp.iterations", 0, 100000, "", "ICP iteration cap",
                      {"--icp-iterations", "icp_iterations"}, TS_FIELD(recognizer.icp.max_iterations)));
  d.push_back(real("icp.trim", "", 0.1, 1, "", "Trimmed ICP: share of the closest pairs fitted",
                   {"--icp-trim", "icp_trim"}, TS_FIELD(recognizer.icp.trim_fraction)));
  d.push_back(real("icp.max_correspondence_m", "m", 0, 100, "", "ICP pair distance gate (0: none, or with the background term on twice evaluate.outlier_m)",
                   {"--icp-max-correspondence", "icp_max_correspondence"}, TS_FIELD(recognizer.icp.max_correspondence)));
  d.push_back(integer("icp.points", 0, kLarge, "", "Contacts used by ICP (0: all)",
                      {"--icp-points", "icp_points", "icp_max_points"}, TS_FIELD(recognizer.icp.max_points)));
  d.push_back(choice("icp.metric", {"point_to_point", "point_to_plane", "field"}, "point_to_point (Section 4.4)",
                     "ICP error metric: point_to_point (the paper), point_to_plane (k-d tree), field "
                     "(point-to-plane on the distance field)",
                     {"--icp-metric", "icp_metric"}, TS_FIELD(recognizer.icp.metric)));
  // Large databases (shortlist, near-twin verification, shape prior).
  d.push_back(any_database(
      integer("shortlist.objects", 0, kLarge, "",
              "Extension: objects whose RANSAC candidates go on to ICP and evaluation per step (0: all)",
              {"--shortlist", "shortlist"}, TS_FIELD(recognizer.shortlist.objects)),
      TS_FIELD(recognizer.shortlist.min_database)));
  d.push_back(integer("shortlist.contacts", 1, 1000000, "", "Contacts scored per candidate by the shortlist's screening",
                      {"shortlist_contacts"}, TS_FIELD(recognizer.shortlist.contacts)));
  d.push_back(real("shortlist.outlier_distance_m", "m", 1e-9, 10, "", "The screening's error: min(1, (d / this)^2)",
                   {"shortlist_outlier"}, TS_FIELD(recognizer.shortlist.outlier_distance)));
  d.push_back(integer("twins.rivals", 0, 1000, "",
                      "Extension: near-twin verification, leading objects compared by a likelihood with per-grasp "
                      "offsets (0: off; tactile logs only)",
                      {"--twins", "twins"}, TS_FIELD(recognizer.twins.rivals)));
  d.push_back(integer("twins.refine", 0, 100, "",
                      "Extension: near-twin verification refines each rival's pose and offsets, at most this many "
                      "Gauss-Newton steps (0: off)",
                      {"--twins-refine", "twins_refine"}, TS_FIELD(recognizer.twins.refine)));
  d.push_back(real("twins.max_gap", "", 0, kInf, "", "Near-twin verification: ln wt gap within which objects compete",
                   {"--twins-max-gap", "twins_max_gap"}, TS_FIELD(recognizer.twins.max_gap)));
  d.push_back(real("twins.offset_sigma_m", "m", 1e-6, 1, "",
                   "Near-twin verification: prior sigma of a grasp's offset (the arm's pose error, per axis)",
                   {"twins_offset_sigma"}, TS_FIELD(recognizer.twins.offset_sigma)));
  d.push_back(real("twins.contact_sigma_m", "m", 1e-6, 1, "",
                   "Near-twin verification: contact noise of its likelihood (residuals clamped at 3 sigma)",
                   {"twins_contact_sigma"}, TS_FIELD(recognizer.twins.contact_sigma)));
  d.push_back(real("twins.free_sigma_m", "m", 0, 1, "",
                   "Near-twin verification: depth scale of its free-space term, the grasps' final hand surfaces inside the object (0: off)",
                   {"twins_free_sigma"}, TS_FIELD(recognizer.twins.free_sigma)));
  d.push_back(real("twins.rotation_sigma_deg", "deg", 0, 30, "",
                   "Near-twin verification: prior sigma of a grasp's arm rotation error about its end effector, per axis (0: translations only)",
                   {"twins_rotation_sigma"}, TS_FIELD(recognizer.twins.rotation_sigma)));
  d.push_back(any_database(
      integer("twins.transfer", 0, 100000, "",
              "Extension: the leading pose is also tried on this many look-alike objects (0: off)",
              {"--transfer", "transfer"}, TS_FIELD(recognizer.twins.transfer)),
      TS_FIELD(recognizer.twins.transfer_min_database)));
  d.push_back(integer("twins.transfer_pool", 0, kLarge, "",
                      "Extension: with the shape prior, pose transfer screens only its this-many best objects of "
                      "the step (0: every object)",
                      {"--transfer-pool", "transfer_pool"}, TS_FIELD(recognizer.twins.transfer_pool)));
  // The feature-free proposal source (engine/recognition/sparse_hypotheses.hpp).
  d.push_back(choice("sparse.mode", {"auto", "always", "never"}, "",
                     "Feature-free triplets matched on point-pair distances and angles: auto (when the "
                     "contacts are isolated: probes), always (pads too: triplets across grasps), never",
                     {"--sparse", "sparse"}, TS_FIELD(recognizer.sparse.mode)));
  d.push_back(integer("sparse.triplets", 1, 100000, "", "Feature-free source: contact triplets drawn per step",
                      {"--sparse-triplets", "sparse_triplets"}, TS_FIELD(recognizer.sparse.triplets)));
  d.push_back(real("sparse.table_budget_mb", "MB", 0, 1e9, "",
                   "Feature-free source: point-pair tables held besides those in use; beyond this, the "
                   "least recently wanted are dropped and rebuilt when wanted again. Never changes results",
                   {"--sparse-table-budget", "sparse_table_budget"}, TS_FIELD(recognizer.sparse.table_budget_mb)));
  // The support under the object (engine/recognition/support.hpp).
  d.push_back(choice("support.mode", {"off", "plane", "cylinder"}, "",
                     "The support under the object: off, plane (a seabed, a deck) or cylinder (a pipe it sits "
                     "on), looked for among the contacts each step; its contacts are set aside and the object "
                     "matched to the rest",
                     {"--support"}, TS_FIELD(recognizer.support.mode)));
  d.push_back(real("support.tolerance_m", "m", 1e-4, 0.1, "",
                   "Support: a contact nearer its plane or cylinder than this is the support's",
                   {"--support-tolerance"}, TS_FIELD(recognizer.support.tolerance)));
  d.push_back(integer("support.min_contacts", 3, kLarge, "",
                      "Support: contacts on the plane or cylinder, and off it, needed to decide",
                      {"--support-min-contacts"}, TS_FIELD(recognizer.support.min_contacts)));
  d.push_back(real("support.above_share", "", 0.51, 1, "",
                   "Support: of the contacts off the plane or cylinder, the share that must lie above or outside "
                   "it (the object rests on its support; a face of the object has the object behind it)",
                   {"--support-above-share"}, TS_FIELD(recognizer.support.above_share)));
  d.push_back(real("support.free_margin_m", "m", -1, 1, "",
                   "Support: free space deeper than this below the plane (inside the cylinder) refutes it (< 0: "
                   "the tolerance plus "
                   "half the free-space resolution)",
                   {"--support-free-margin"}, TS_FIELD(recognizer.support.free_margin)));
  d.push_back(real("support.min_radius_m", "m", 1e-3, 10, "",
                   "Support: the thinnest cylinder taken for a pipe (support.mode = cylinder); the object's own "
                   "thinner round parts (a finger, a bar, a bone's shaft) are not",
                   {"--support-min-radius"}, TS_FIELD(recognizer.support.min_radius)));
  d.push_back(real("support.attribution_m", "m", 1e-4, 1, "",
                   "A contact this near the answer's surface is the object's; the others are the support's "
                   "or unexplained (the step's attribution; with support.mode on or evaluate.outlier_m > 0)",
                   {"--attribution"}, TS_FIELD(recognizer.support.attribution)));
  d.push_back(real("support.sink_m", "m", 0, 1, "",
                   "Support: with a plane found, a pose that puts the object deeper than this below it loses "
                   "ln wt (up to support.sink_cost, reached at twice this depth); nothing of the object lies "
                   "below its support (0: off)",
                   {"--support-sink"}, TS_FIELD(recognizer.support.sink)));
  d.push_back(real("support.sink_cost", "", 0, 100, "",
                   "Support: the ln wt a pose loses at twice support.sink_m below the plane and deeper",
                   {"--support-sink-cost"}, TS_FIELD(recognizer.support.sink_cost)));
  d.push_back(integer("prior.angle_bins", 1, 64, "", "Shape prior: bins of each angle term",
                      {"--prior-angle-bins"}, TS_FIELD(recognizer.prior.angle_bins)));
  d.push_back(real("prior.distance_bin_m", "m", 1e-4, 1, "", "Shape prior: pair-distance bin",
                   {"--prior-distance-bin"}, TS_FIELD(recognizer.prior.distance_bin)));
  d.push_back(integer("prior.object_points", 2, kLarge, "", "Shape prior: keypoints per object histogram",
                      {"--prior-object-points"}, TS_FIELD(recognizer.prior.object_points)));
  // Contact fusion.
  d.push_back(real("exploration.contact_voxel_m", "m", 1e-6, 1, "", "Voxel filter of the cumulative contact cloud",
                   {"--contact-voxel", "contact_voxel"}, TS_FIELD(contact_voxel)));
  // Active touch (engine/touch/active_touch.hpp): experiments choose each grasp after the first with
  // the planner; `recognize --suggest` reads the planner's parameters.
  d.push_back(choice("exploration.strategy", {"random", "active"}, "random (Section 5.1: the operator's grasps)",
                     "Experiments: grasps after the first drawn at random from the pool, or chosen by the "
                     "next-grasp planner (active) and executed on the true object",
                     {"--exploration", "exploration"}, TS_FIELD(exploration)));
  d.push_back(integer("active.candidates", 1, 100000, "", "Active touch: candidate grasps scored per step",
                      {"active_candidates"}, TS_FIELD(active.candidates)));
  d.push_back(integer("active.hypotheses", 1, 100000, "",
                      "Active touch: K, hypotheses the outcomes are predicted under (the best of each object first)",
                      {"active_hypotheses"}, TS_FIELD(active.hypotheses)));
  d.push_back(integer("active.leaders", 1, 100000, "", "Active touch: hypotheses whose models the candidates aim at",
                      {"active_leaders"}, TS_FIELD(active.leaders)));
  d.push_back(real("active.aim_radius_m", "m", 0, 100, "",
                   "Active touch: aims only at model points within this of a contact so far (0: anywhere)",
                   {"active_aim_radius"}, TS_FIELD(active.aim_radius)));
  d.push_back(integer("active.attempts", 1, 10000, "",
                      "Active touch: aims per candidate (one the open hand cannot reach on its own model is redrawn)",
                      {"active_attempts"}, TS_FIELD(active.attempts)));
  d.push_back(real("active.sigma_m", "m", 1e-5, 1, "", "Active touch: noise of a predicted pad distance",
                   {"active_sigma"}, TS_FIELD(active.sigma)));
  d.push_back(real("active.offset_sigma_m", "m", 0, 1, "",
                   "Active touch: the arm's per-grasp error along the pad normal, common to the patch, "
                   "marginalized when outcomes are compared (0: off, left in active.sigma_m)",
                   {}, TS_FIELD(active.offset_sigma)));
  d.push_back(real("active.collision_weight", "", 0, 1e6, "",
                   "Active touch: score penalty (nats) per unit of hypothesis weight that blocks the hand",
                   {"active_collision_weight"}, TS_FIELD(active.collision_weight)));
  d.push_back(real("active.temperature", "", 1e-6, 1e12, "",
                   "Active touch: ln wt divided by this before the hypotheses' weights are normalized",
                   {"active_temperature"}, TS_FIELD(active.temperature)));
  d.push_back(real("active.pose_weight", "", 0, 1e6, "",
                   "Active touch: weight of the expected information about the pose within an object against that "
                   "about the object (1: about the hypothesis, object and pose alike; 0: the object only)",
                   {"active_pose_weight"}, TS_FIELD(active.pose_weight)));
  d.push_back(real("active.coverage_weight", "", 0, 1e6, "",
                   "Active touch: score bonus (nats) of an aim at least active.coverage_radius_m from every contact so "
                   "far (linear below; 0: off)",
                   {"active_coverage_weight"}, TS_FIELD(active.coverage_weight)));
  d.push_back(real("active.coverage_radius_m", "m", 1e-4, 100, "",
                   "Active touch: distance from the contacts so far at which an aim counts as new ground",
                   {"active_coverage_radius"}, TS_FIELD(active.coverage_radius)));
  d.push_back(boolean("diagnostics.truth_pose",
                      "Diagnostics: each step also evaluates the true object at its true pose (ICP, Eq. 6, the "
                      "answer rule): would a perfect search name it? (simulated runs and logs with a truth; "
                      "changes no result)",
                      {"truth_pose"}, TS_FIELD(truth_pose)));
  d.push_back(real("diagnostics.oracle_belief", "", 0, 0.99, "",
                   "Diagnostics of active exploration: at least this share of the planner's belief goes to the true "
                   "object at its true pose (0: off): an upper bound on what a better belief would give the planner, "
                   "not a method (it reads the ground truth; simulated runs whose object the recognizer may name)",
                   {"oracle_belief"}, TS_FIELD(oracle_belief)));
  return d;
}

#undef TS_FIELD

/// The shortest text that reads back as `v`.
std::string number_text(double v) {
  char buffer[64];
  const auto [end, ec] = std::to_chars(buffer, buffer + sizeof buffer, v);
  return ec == std::errc() ? std::string(buffer, end) : std::to_string(v);
}

// ---- The simulator and experiment parameters: values held by ExperimentConfig ----

using J = nlohmann::ordered_json;
using Inputs = std::vector<std::string>;
using Kind = Parameter::Kind;

std::string joined(const Inputs& inputs) {
  std::string s;
  for (const auto& i : inputs) s += (s.empty() ? "" : ",") + i;
  return s;
}

const std::string& single(const Inputs& inputs, const std::string& file, const std::string& name) {
  if (inputs.size() != 1)
    throw Error(name + " expects one value, got " + std::to_string(inputs.size()) +
                    (inputs.empty() ? "" : " ('" + joined(inputs) + "')"),
                file, name);
  return inputs.front();
}

/// A list of names: "all" (alone) means empty = everything; inputs may also be comma lists.
std::vector<std::string> name_list(const Inputs& inputs, const std::string& file, const std::string& key) {
  auto fail = [&](const std::string& what) { throw Error(key + what, file, key); };
  std::vector<std::string> out;
  for (const auto& in : inputs) {
    std::size_t start = 0;
    while (start <= in.size()) {
      const std::size_t comma = std::min(in.find(',', start), in.size());
      std::string name = in.substr(start, comma - start);
      name.erase(0, name.find_first_not_of(" \t"));
      name.erase(name.find_last_not_of(" \t") + 1);
      if (name.empty()) fail(" has an empty object name ('" + joined(inputs) + "')");
      out.push_back(name);
      start = comma + 1;
    }
  }
  if (out.empty()) fail(" is empty (use \"all\")");
  if (out.size() == 1 && out.front() == "all") return {};
  std::set<std::string> seen;
  for (const auto& n : out) {
    if (n == "all") fail(": \"all\" cannot be combined with names");
    if (!seen.insert(n).second) fail(" lists '" + n + "' twice");
  }
  return out;
}


/// A number held by the configuration: `field` returns a reference to an int, a double or an
/// optional of either (unset: null).
template <class F>
Parameter number(Parameter p, F field) {
  const Parameter shape = p;
  p.set_config = [shape, field](ExperimentConfig& c, const Inputs& in, const std::string& file,
                                const std::string& name) {
    const double v = parse_value(shape, single(in, file, name), file, name);
    auto& x = field(c);
    using T = std::decay_t<decltype(x)>;
    if constexpr (std::is_same_v<T, std::optional<int>> || std::is_same_v<T, int>)
      x = static_cast<int>(v);
    else
      x = v;
  };
  p.get_config = [field](const ExperimentConfig& c) {
    const auto& x = field(c);
    using T = std::decay_t<decltype(x)>;
    if constexpr (std::is_same_v<T, std::optional<int>> || std::is_same_v<T, std::optional<double>>)
      return x ? J(*x) : J(nullptr);
    else
      return J(x);
  };
  return p;
}

/// One of `choices`, held by the configuration as its name (a std::string field).
template <class F>
Parameter named(Parameter p, std::vector<std::string> choices, F field) {
  p.type = Type::choice;
  p.choices = std::move(choices);
  p.hi = static_cast<double>(p.choices.size() - 1);
  const Parameter shape = p;
  p.set_config = [shape, field](ExperimentConfig& c, const Inputs& in, const std::string& file,
                                const std::string& name) {
    field(c) = shape.text(parse_value(shape, single(in, file, name), file, name));
  };
  p.get_config = [field](const ExperimentConfig& c) { return J(field(c)); };
  return p;
}

#define TS_CONFIG(expr) [](auto& c) -> auto& { return c.expr; }

/// The simulator and experiment parameters before the method's, and after them (the order of a
/// configuration's JSON).
std::pair<std::vector<Parameter>, std::vector<Parameter>> config_declaration() {
  const Kind E = Kind::experiment, S = Kind::simulator;
  std::vector<Parameter> d;
  auto text = [](Parameter p, auto field, bool join) {
    p.set_config = [field, join](ExperimentConfig& c, const Inputs& in, const std::string& file,
                                 const std::string& name) { field(c) = join ? joined(in) : single(in, file, name); };
    p.get_config = [field](const ExperimentConfig& c) { return J(field(c)); };
    p.sweepable = false;
    return p;
  };
  auto names = [](Parameter p, auto field, bool all_when_empty) {
    p.set_config = [field](ExperimentConfig& c, const Inputs& in, const std::string& file, const std::string& name) {
      field(c) = name_list(in, file, name);
    };
    p.get_config = [field, all_when_empty](const ExperimentConfig& c) {
      const auto& v = field(c);
      return v.empty() && all_when_empty ? J("all") : J(v);
    };
    p.sweepable = false;
    return p;
  };
  d.push_back(text(setting("name", E, Type::text, "", 0, 0, "", "The study's name (informative)"), TS_CONFIG(name), false));
  d.push_back(text(setting("description", E, Type::text, "", 0, 0, "", "What the study measures (informative)"),
                   TS_CONFIG(description), true));
  d.push_back(names(setting("objects", E, Type::names, "", 0, 0, "", "Explored objects: all, or names of the database"),
                    TS_CONFIG(objects), true));
  d.push_back(names(setting("database", E, Type::names, "", 0, 0, "",
                            "Objects the recognizer may answer: all, names of the database, or each: only the "
                            "explored object in its own runs (known-object localization, recognize --only)"),
                    TS_CONFIG(database), true));
  d.push_back(number(setting("database_size", E, Type::integer, "", 1, kLarge, "",
                             "The recognizer's database cut to this many objects, the explored ones first (unset: all)"),
                     TS_CONFIG(database_size)));
  d.push_back(names(setting("hidden", E, Type::names, "", 0, 0, "",
                            "Open set: objects removed from the recognizer's database (they may be explored), or "
                            "each: every explored object hidden from its own runs (leave-one-out)"),
                    TS_CONFIG(hidden), false));
  for (Parameter& p : d) p.sweepable = p.key == "database_size";
  d.push_back(number(setting("runs", E, Type::integer, "", 1, kLarge, "20 or 50 (Section 5.2)",
                             "Exploration runs per object"), TS_CONFIG(runs)));
  d.push_back(number(setting("steps", E, Type::integer, "", 1, kLarge, "40 (Section 5.2)",
                             "Exploration steps (grasps) per run"), TS_CONFIG(steps)));
  d.push_back(number(setting("pool", E, Type::integer, "", 1, kLarge, "at least 50 (Section 5.1)",
                             "Simulated grasps per pool, at least steps: a run draws its steps from it"),
                     TS_CONFIG(pool)));
  for (std::size_t i = d.size() - 3; i < d.size(); ++i) d[i].sweepable = false;   // runs, steps, pool
  d.push_back(named(setting("protocol", E, Type::choice, "", 0, 0, "shared_pool (Section 5.1)",
                            "What a run shares: independent (its own object pose and grasp pool from its own seed) "
                            "or shared_pool (the paper's: one pose and pool per object that its runs draw from)"),
                    {"independent", "shared_pool"}, TS_CONFIG(protocol)));
  d.back().sweepable = false;   // variants share their runs' grasps
  d.push_back(named(setting("method", E, Type::choice, "", 0, 0, "bricpsf (Algorithm 1)", "The recognition method"),
                    {"bricpsf", "batch-ransac", "ransac-icp", "ransac-icp-fs"}, TS_CONFIG(method)));
  d.push_back(named(setting("preset", E, Type::choice, "", 0, 0, "",
                            "The method parameters' defaults: improved (Touchstone's extensions) or paper "
                            "(Sections 4-5 exactly)"),
                    {"improved", "paper"}, TS_CONFIG(preset)));
  // The simulator.
  Parameter noise = named(setting("noise", S, Type::choice, "", 0, 0, "underwater (Section 5.1)",
                                  "Noise profile of the simulated arm and sensors"),
                          {"ideal", "underwater", "deepsea"}, TS_CONFIG(noise));
  noise.simulate = true;
  d.push_back(noise);
  auto override_of = [&](std::string key, std::string unit, double hi, std::string help,
                         std::vector<std::string> aliases, auto field) {
    Parameter p = number(setting(std::move(key), S, Type::real, std::move(unit), 0, hi, "", std::move(help),
                                 std::move(aliases)),
                         field);
    p.simulate = !p.aliases.empty();
    d.push_back(std::move(p));
  };
  override_of("noise.arm_position_sigma_m", "m", 1, "Arm position error per axis and grasp (unset: the profile's)",
              {"--arm-position-sigma"}, TS_CONFIG(noise_params.arm_position_sigma_m));
  override_of("noise.arm_rotation_sigma_deg", "deg", 90, "Arm rotation error per grasp (unset: the profile's)",
              {"--arm-rotation-sigma"}, TS_CONFIG(noise_params.arm_rotation_sigma_deg));
  override_of("noise.arm_scale", "", 10,
              "Times the arm's position and rotation errors, after the profile and the two keys above "
              "(unset: 1; 0: no arm error; a sweep of it is the arm error's size at a fixed ratio)",
              {"--arm-scale"}, TS_CONFIG(noise_params.arm_scale));
  override_of("noise.sensel_noise", "", 10, "Sensel signal noise, a share of the signal (unset: the profile's)",
              {"--signal-noise"}, TS_CONFIG(noise_params.sensel_noise));
  override_of("noise.force_noise", "", 10, "Force-resolution noise of contacted sensels, a share (unset: the profile's)",
              {"--force-noise"}, TS_CONFIG(noise_params.force_noise));
  override_of("noise.contact_sigma_m", "m", 1,
              "Contact position noise per axis: a sensel's lateral error, or the probe's own noise (unset: the profile's)",
              {"--lateral-sigma", "--contact-sigma"}, TS_CONFIG(noise_params.contact_sigma_m));
  override_of("noise.joint_sigma_deg", "deg", 90, "Finger joint reading error per joint and grasp (unset: the profile's)",
              {"--joint-sigma"}, TS_CONFIG(noise_params.joint_sigma_deg));
  {
    Parameter p = setting("sensors", S, Type::choice, "", 0, 1, "1 (Section 5.1)",
                          "Tactile pads logged: 1 (the middle finger's distal pad) or 6");
    p.choices = {"1", "6"};
    const Parameter shape = p;
    p.set_config = [shape](ExperimentConfig& c, const Inputs& in, const std::string& file, const std::string& name) {
      c.sensors = std::stoi(shape.text(parse_value(shape, single(in, file, name), file, name)));
    };
    p.get_config = [](const ExperimentConfig& c) { return J(c.sensors); };
    p.simulate = true;
    d.push_back(std::move(p));
  }
  d.push_back(named(setting("sensing", S, Type::choice, "", 0, 0, "pads",
                            "pads: the gripper's tactile arrays; probe: a ball-tipped probe, one contact per step "
                            "(noise.contact_sigma_m is then the probe's own noise); fingertips: one contact point "
                            "per fingertip that touched, no normals unless fingertips.normals_deg"),
                    {"pads", "probe", "fingertips"}, TS_CONFIG(sensing)));
  d.back().sweepable = false;
  d.back().simulate = true;
  auto probe_setting = [&](std::string key, std::string unit, double lo, double hi, std::string help,
                           std::string alias, auto field) {
    Parameter p = number(setting(std::move(key), S, Type::real, std::move(unit), lo, hi, "", std::move(help),
                                 {std::move(alias)}),
                         field);
    p.simulate = true;
    d.push_back(std::move(p));
  };
  probe_setting("probe.ball_radius_m", "m", 1e-4, 0.05, "Probe ball-tip radius (unset: 3 mm; sensing = probe)",
                "--ball-radius", TS_CONFIG(probe_params.ball_radius_m));
  probe_setting("probe.tilt_deg", "deg", 0, 89,
                "Probe approach within this cone about the surface normal (unset: 20; sensing = probe)",
                "--probe-tilt", TS_CONFIG(probe_params.tilt_deg));
  probe_setting("probe.quantization_m", "m", 0, 0.1,
                "Probe positions recorded rounded to this (unset, 0: none; sensing = probe)", "--quantization",
                TS_CONFIG(probe_params.quantization_m));
  probe_setting("fingertips.quantization_m", "m", 0, 0.1,
                "Fingertip contacts reported rounded to this (unset, 0: none; sensing = fingertips)",
                "--tip-quantization", TS_CONFIG(fingertip_params.quantization_m));
  probe_setting("fingertips.normals_deg", "deg", -1, 89,
                "Fingertips report surface normals with this noise per axis (unset or -1: no normals; sensing = "
                "fingertips)",
                "--tip-normals", TS_CONFIG(fingertip_params.normals_deg));
  d.push_back(named(setting("scene", S, Type::choice, "", 0, 0, "none",
                            "What lies around the object: none (water alone), seabed (the object rests on a "
                            "support surface that the hand touches too, shaped by scene.*), panel (it is mounted "
                            "against a flat vertical plate, the fixture; scene.* but slope and relief) or pipe (it "
                            "rests on a horizontal pipe; scene.* but slope and relief) or cluttered (a seabed "
                            "with scene.neighbours other database objects lying beside it); sensing = pads or "
                            "fingertips"),
                    {"none", "seabed", "panel", "pipe", "cluttered"}, TS_CONFIG(scene)));
  d.back().sweepable = false;
  d.back().simulate = true;
  probe_setting("scene.slope_deg", "deg", 0, 60, "The seabed's tilt from horizontal (unset: 0; scene = seabed)",
                "--scene-slope", TS_CONFIG(scene_params.slope_deg));
  probe_setting("scene.relief_m", "m", 0, 0.2,
                "Peak amplitude of the seabed's sediment relief (unset, 0: flat; scene = seabed)", "--scene-relief",
                TS_CONFIG(scene_params.relief_m));
  probe_setting("scene.relief_wavelength_m", "m", 0.01, 10,
                "Wavelength of the sediment relief's components (unset: 0.12; scene = seabed)",
                "--scene-relief-wavelength", TS_CONFIG(scene_params.relief_wavelength_m));
  probe_setting("scene.gap_m", "m", 0, 1,
                "The object's lowest point above the seabed (unset, 0: it rests on it; below 0 the seabed would "
                "intersect the object, refused; scene = seabed)",
                "--scene-gap", TS_CONFIG(scene_params.gap_m));
  probe_setting("scene.off_target", "", 0, 0.99,
                "Share of the grasps aimed at the seabed (or panel, or pipe) beside the object instead of the "
                "object (unset: 0; scene = seabed, panel or pipe)",
                "--scene-off-target", TS_CONFIG(scene_params.off_target));
  probe_setting("scene.off_target_radius_m", "m", 0, 10,
                "Those grasps aim within this of the object's footprint centre (a pipe: along its axis) (unset, "
                "0: 1.5 x the object's radius; scene = seabed, panel or pipe)",
                "--scene-off-target-radius", TS_CONFIG(scene_params.off_target_radius_m));
  probe_setting("scene.extent_m", "m", 0, 100,
                "Half-size of the seabed patch about the object, a pipe's half-length (unset, 0: the object's "
                "radius + the hand's reach + 5 cm; scene = seabed, panel or pipe)",
                "--scene-extent", TS_CONFIG(scene_params.extent_m));
  probe_setting("scene.pipe_radius_m", "m", 0, 5,
                "The pipe's radius (unset, 0: the object's bounding radius, at least 5 cm; scene = pipe, refused "
                "for a seabed or a panel)",
                "--scene-pipe-radius", TS_CONFIG(scene_params.pipe_radius_m));
  {
    Parameter p = number(setting("scene.neighbours", S, Type::integer, "", 1, 8, "",
                                 "Other database objects lying beside the object, drawn by the seed (unset: 2; "
                                 "scene = cluttered)",
                                 {"--scene-neighbours"}),
                         TS_CONFIG(scene_params.neighbours));
    p.simulate = true;
    d.push_back(std::move(p));
  }
  probe_setting("scene.neighbour_distance_m", "m", 0.005, 1,
                "The neighbours' surfaces lie this far from the object's, to 1.25 times it (unset: 0.05; scene = "
                "cluttered)",
                "--scene-neighbour-distance", TS_CONFIG(scene_params.neighbour_distance_m));
  probe_setting("scene.neighbour_share", "", 0, 1,
                "Share of the off-target grasps aimed at a neighbour, the rest at the seabed (unset: 0.5; scene = "
                "cluttered)",
                "--scene-neighbour-share", TS_CONFIG(scene_params.neighbour_share));
  {
    Parameter p = setting("seed", E, Type::integer, "", 0, kInf, "", "Seed of every random draw (unsigned integer)");
    p.set_config = [](ExperimentConfig& c, const Inputs& in, const std::string& file, const std::string& name) {
      const std::string& t = single(in, file, name);
      std::uint64_t v = 0;
      auto [q, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
      if (ec != std::errc() || q != t.data() + t.size() || t.empty())
        throw Error(name + " must be an unsigned integer (got '" + t + "')", file, name);
      c.seed = v;
    };
    p.get_config = [](const ExperimentConfig& c) { return J(c.seed); };
    p.sweepable = false;
    d.push_back(std::move(p));
  }
  {
    Parameter p = setting("ransac.samples", E, Type::text, "", 0, 0, "15x200 (Section 5.5)",
                          "NxR: ransac.triplets and ransac.registrations together");
    p.set_config = [](ExperimentConfig& c, const Inputs& in, const std::string& file, const std::string& name) {
      const std::string& t = single(in, file, name);
      const auto cross = t.find_first_of("xX*");
      if (cross == std::string::npos)
        throw Error(name + " must read NxR, e.g. 15x200 (got '" + t + "')", file, name);
      // N and R within the ranges of ransac.triplets and ransac.registrations.
      auto part = [&](const std::string& text, const char* what, const std::string& key) {
        const auto hi = static_cast<long long>(find_parameter(key)->hi);
        long long v = 0;
        auto [q, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
        if (ec != std::errc() || q != text.data() + text.size() || text.empty() || v < 1 || v > hi)
          throw Error(name + ": " + what + " must be a whole number from 1 to " + std::to_string(hi) + " (" + key +
                          "; got '" + t + "')",
                      file, name);
        return static_cast<double>(v);
      };
      c.params["ransac.triplets"] = part(t.substr(0, cross), "N", "ransac.triplets");
      c.params["ransac.registrations"] = part(t.substr(cross + 1), "R", "ransac.registrations");
    };
    d.push_back(std::move(p));   // no getter: it sets ransac.triplets and ransac.registrations
  }
  std::vector<Parameter> after;
  after.push_back(number(setting("memory_budget_mb", E, Type::real, "MB", 0, kInf, "",
                                 "Resident object geometry, loaded on demand and evicted least-recently-used (0: no "
                                 "limit; unset: the recognizer's default). Never changes results",
                                 {"--memory-budget"}),
                         TS_CONFIG(memory_budget_mb)));
  after.push_back(text(setting("calibration", E, Type::text, "", 0, 0, "",
                               "Confidence calibration file (touchstone calibrate); empty: confidences not computed"),
                       TS_CONFIG(calibration), false));
  after.push_back(named(setting("schedule", E, Type::choice, "", 0, 0, "",
                                "Parallel over runs (throughput) or inside each step (latency). Never changes "
                                "results"),
                        {"runs", "steps"}, TS_CONFIG(schedule)));
  for (Parameter& p : after) p.sweepable = false;
  return {std::move(d), std::move(after)};
}

#undef TS_CONFIG

/// Every parameter: the simulator and experiment ones around the method's. The method
/// parameters are held by the configuration's `params` (key -> value; absent: the preset's).
struct Declaration {
  std::vector<Parameter> all;
  std::size_t method_begin = 0, method_end = 0;
};

const Declaration& the_declaration() {
  static const Declaration d = [] {
    Declaration out;
    auto [before, after] = config_declaration();
    out.all = std::move(before);
    out.method_begin = out.all.size();
    for (Parameter& p : declaration()) {
      const Parameter shape = p;
      p.set_config = [shape](ExperimentConfig& c, const Inputs& in, const std::string& file, const std::string& name) {
        c.params[shape.key] = parse_value(shape, single(in, file, name), file, name);
      };
      p.get_config = [shape](const ExperimentConfig& c) {
        const auto it = c.params.find(shape.key);
        return it == c.params.end() ? J(nullptr) : shape.json(it->second);
      };
      out.all.push_back(std::move(p));
    }
    out.method_end = out.all.size();
    for (Parameter& p : after) out.all.push_back(std::move(p));
    return out;
  }();
  return d;
}

/// Names compared with `-` and `_` alike and without leading dashes.
std::string normalized(std::string s) {
  s.erase(0, s.find_first_not_of('-'));
  std::replace(s.begin(), s.end(), '-', '_');
  return s;
}

}  // namespace

std::string Parameter::flag() const {
  std::string f = "--" + key;
  std::replace(f.begin(), f.end(), '_', '-');
  return f;
}

std::vector<std::string> Parameter::flag_aliases() const {
  std::vector<std::string> out;
  for (const auto& a : aliases)
    if (a.front() == '-') out.push_back(a);
  return out;
}

std::vector<std::string> Parameter::key_aliases() const {
  std::vector<std::string> out;
  for (const auto& a : aliases)
    if (a.front() != '-') out.push_back(a);
  return out;
}

std::string Parameter::text(double v) const {
  switch (type) {
    case Type::boolean: return v != 0.0 ? "true" : "false";
    case Type::choice: return choices.at(static_cast<std::size_t>(v));
    case Type::integer: return std::to_string(static_cast<long long>(v));
    case Type::real:
    case Type::text:
    case Type::names: return number_text(v);
  }
  return number_text(v);
}

nlohmann::ordered_json Parameter::json(double v) const {
  switch (type) {
    case Type::boolean: return v != 0.0;
    case Type::choice: return choices.at(static_cast<std::size_t>(v));
    case Type::integer: return static_cast<long long>(v);
    case Type::real:
    case Type::text:
    case Type::names: return v;
  }
  return v;
}

const std::vector<Parameter>& parameters() { return the_declaration().all; }

std::span<const Parameter> method_parameters() {
  const Declaration& d = the_declaration();
  return std::span<const Parameter>(d.all).subspan(d.method_begin, d.method_end - d.method_begin);
}

const char* kind_name(Parameter::Kind kind) {
  switch (kind) {
    case Kind::method: return "method";
    case Kind::simulator: return "simulator";
    case Kind::experiment: return "experiment";
  }
  return "method";
}

const Parameter* find_parameter(const std::string& name) {
  const std::string n = normalized(name);
  for (const auto& p : parameters())
    if (normalized(p.key) == n) return &p;
  for (const auto& p : parameters())
    for (const auto& a : p.aliases)
      if (normalized(a) == n) return &p;
  return nullptr;
}

double parse_value(const Parameter& p, const std::string& text, const std::string& file,
                   const std::string& name) {
  const std::string& key = name.empty() ? p.key : name;
  auto fail = [&](const std::string& what) -> double { throw Error(key + " " + what, file, key); };
  switch (p.type) {
    case Type::boolean:
      if (text == "true" || text == "1" || text == "on" || text == "yes") return 1.0;
      if (text == "false" || text == "0" || text == "off" || text == "no") return 0.0;
      return fail("must be true or false (got '" + text + "')");
    case Type::choice: {
      for (std::size_t i = 0; i < p.choices.size(); ++i)
        if (text == p.choices[i]) return static_cast<double>(i);
      if (p.kind == Kind::method)   // a method choice as stored in result files: its index
        for (std::size_t i = 0; i < p.choices.size(); ++i)
          if (text == std::to_string(i)) return static_cast<double>(i);
      std::string all;
      for (const auto& c : p.choices) all += (all.empty() ? "" : ", ") + c;
      return fail("must be one of " + all + " (got '" + text + "')");
    }
    case Type::text:
    case Type::names:
      return fail("has no single numeric value");
    case Type::integer: {
      long long v = 0;
      const char* b = text.data();
      const char* e = b + text.size();
      if (!text.empty() && *b == '+') ++b;
      auto [q, ec] = std::from_chars(b, e, v);
      if (ec != std::errc() || q != e || text.empty()) return fail("must be an integer (got '" + text + "')");
      if (static_cast<double>(v) < p.lo)
        return fail("must be at least " + number_text(p.lo) + " (got " + std::to_string(v) + ")");
      if (static_cast<double>(v) > p.hi)
        return fail(p.hi >= kLarge ? "is implausibly large (got " + std::to_string(v) + ")"
                                   : "must be at most " + number_text(p.hi) + " (got " + std::to_string(v) + ")");
      return static_cast<double>(v);
    }
    case Type::real: {
      double v = 0;
      auto [q, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
      if (ec != std::errc() || q != text.data() + text.size() || text.empty() || !std::isfinite(v))
        return fail("must be a number (got '" + text + "')");
      if (v < p.lo || v > p.hi)
        return fail("must lie in [" + number_text(p.lo) + ", " + (std::isinf(p.hi) ? "inf" : number_text(p.hi)) +
                    "] (got " + text + ")");
      return v;
    }
  }
  return 0.0;
}

void apply(MethodSettings& m, const Parameter& p, double value) {
  p.set(m, value);
  if (p.min_database) p.min_database(m) = 0;   // asked for explicitly: on any database
}

MethodSettings method_settings(const ExperimentConfig& c) {
  MethodSettings m = MethodSettings::preset(c.preset);
  RecognizerSettings& s = m.recognizer;
  // A probe's path: free by the ball radius only, measured with the arm's error (sparse_hypotheses.hpp).
  if (c.sensing == "probe") {
    s.evaluate.d_thresh = kProbeFreeThreshold;
    s.evaluate.free_inside_penalty = true;
    s.evaluate.free_inside_margin = kProbeInsideMargin;
  }
  const auto method = parse_method(c.method);
  if (!method) throw Error("unknown method '" + c.method + "'", {}, "method");
  s.method = *method;
  for (const Parameter& p : method_parameters()) {
    const auto it = c.params.find(p.key);
    if (it != c.params.end()) apply(m, p, it->second);
  }
  return m;
}

std::vector<std::pair<std::string, double>> stored_parameters(const MethodSettings& m) {
  std::vector<std::pair<std::string, double>> out;
  for (const auto& p : method_parameters()) out.emplace_back(p.key, p.get(m));
  return out;
}

void add_parameter_flags(CLI::App& app, ParameterFlags& flags, const std::string& group,
                         const std::function<bool(const Parameter&)>& which) {
  for (const auto& p : parameters()) {
    if (which ? !which(p) : p.kind != Kind::method) continue;
    std::string names;
    std::string help = p.help + (p.unit.empty() ? "" : " (" + p.unit + ")");
    const std::string key = p.key;
    if (p.type == Type::boolean) {
      // --key / --no-key, and the older flags alike; --key=false also works.
      for (const std::string& f : [&] {
             std::vector<std::string> all{p.flag()};
             for (const auto& a : p.flag_aliases()) all.push_back(a);
             return all;
           }())
        names += (names.empty() ? "" : ",") + f + "{true},--no-" + f.substr(2) + "{false}";
      app.add_flag_function(names, [&flags, key](std::int64_t v) { flags.given[key] = v > 0 ? "true" : "false"; },
                            help)
          ->group(group);
      continue;
    }
    names = p.flag();
    for (const auto& a : p.flag_aliases()) names += "," + a;
    const Parameter* pp = &p;
    app.add_option_function<std::string>(
           names,
           [&flags, pp](const std::string& v) {
             if (pp->type != Type::text && pp->type != Type::names && pp->key != "seed") {
               try {   // checked when given: the error names the flag
                 parse_value(*pp, v, {}, pp->flag());
               } catch (const Error& e) {
                 throw CLI::ValidationError(pp->flag(), e.what());
               }
             }
             flags.given[pp->key] = v;
           },
           help)
        ->group(group)
        ->type_name(p.type == Type::integer ? "INT"
                    : p.type == Type::choice ? "NAME"
                    : p.type == Type::real   ? "NUMBER"
                                             : "TEXT");
  }
}

void apply_flags(const ParameterFlags& flags, MethodSettings& m) {
  for (const auto& p : method_parameters()) {
    const auto it = flags.given.find(p.key);
    if (it == flags.given.end()) continue;
    try {
      apply(m, p, parse_value(p, it->second, {}, p.flag()));
    } catch (const Error& e) {
      throw CLI::ValidationError(p.flag(), e.what());
    }
  }
}

bool bench_run_parameter(const Parameter& p) {
  return p.key == "method" || p.key == "preset" ||
         (p.simulate && p.key != "sensing" && !p.key.starts_with("probe.") && !p.key.starts_with("fingertips.") &&
          p.key != "scene" && !p.key.starts_with("scene."));
}

void apply_flags(const ParameterFlags& flags, ExperimentConfig& c) {
  for (const Parameter& p : parameters()) {
    const auto it = flags.given.find(p.key);
    if (it == flags.given.end()) continue;
    try {
      set_key(c, p.key, {it->second});
    } catch (const Error& e) {
      throw Error(e.message(), {}, p.flag());
    }
  }
}

namespace {

/// The commands that take `p` as a flag (besides `experiment --set KEY=VALUE`, which takes all).
std::vector<std::string> flag_commands(const Parameter& p) {
  if (p.kind == Kind::method) return {"recognize", "bench_recognize"};
  std::vector<std::string> out{"experiment"};
  if (p.simulate) out.push_back("simulate");
  if (bench_run_parameter(p)) out.push_back("bench_recognize");
  return out;
}

/// A parameter's default as JSON in each preset (a method parameter's from the preset; the
/// others' from the configuration's defaults, alike in both).
nlohmann::ordered_json default_json(const Parameter& p, MethodSettings& s, const std::string& preset) {
  if (p.kind != Kind::method) {
    ExperimentConfig c;
    c.preset = preset;
    return p.get_config ? p.get_config(c) : J(nullptr);
  }
  nlohmann::ordered_json v = p.json(p.get(s));
  if (p.min_database && p.min_database(s) > 0)
    v = {{"value", v}, {"databases_above", p.min_database(s)}, {"otherwise", p.json(0.0)}};
  return v;
}

}  // namespace

nlohmann::ordered_json parameters_json(const std::string& preset) {
  std::vector<std::string> presets = {"paper", "improved"};
  if (!preset.empty()) presets = {preset};
  std::vector<MethodSettings> settings;
  for (const auto& p : presets) settings.push_back(MethodSettings::preset(p));
  nlohmann::ordered_json out = nlohmann::ordered_json::array();
  static const char* type_names[] = {"integer", "real", "boolean", "choice", "text", "names"};
  for (const auto& p : parameters()) {
    nlohmann::ordered_json j;
    j["key"] = p.key;
    j["kind"] = kind_name(p.kind);
    j["flag"] = p.flag();
    j["commands"] = flag_commands(p);
    j["sweepable"] = p.sweepable;
    j["aliases"] = p.aliases;
    j["type"] = type_names[static_cast<int>(p.type)];
    if (p.type == Type::choice) j["choices"] = p.choices;
    j["unit"] = p.unit;
    if (p.type == Type::integer || p.type == Type::real) {
      j["min"] = p.lo;
      j["max"] = std::isinf(p.hi) ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(p.hi);
    }
    nlohmann::ordered_json defaults;
    for (std::size_t i = 0; i < presets.size(); ++i) defaults[presets[i]] = default_json(p, settings[i], presets[i]);
    j["default"] = defaults;
    j["paper"] = p.paper.empty() ? nlohmann::ordered_json(nullptr) : nlohmann::ordered_json(p.paper);
    j["help"] = p.help;
    out.push_back(j);
  }
  return out;
}

std::string parameters_markdown() {
  MethodSettings paper = MethodSettings::preset("paper");
  MethodSettings improved = MethodSettings::preset("improved");
  auto value = [](const Parameter& p, MethodSettings& s) {
    if (p.kind != Kind::method) {
      const J v = default_json(p, s, "improved");
      if (v.is_array() && v.empty()) return std::string("none");
      return v.is_null() ? std::string("unset") : v.is_string() ? v.get<std::string>() : v.dump();
    }
    std::string v = p.text(p.get(s));
    if (p.min_database && p.min_database(s) > 0)
      v += " (databases of more than " + std::to_string(p.min_database(s)) + " objects; else " + p.text(0.0) + ")";
    return v;
  };
  std::ostringstream md;
  const std::pair<Kind, const char*> kinds[] = {
      {Kind::method, "Method parameters: flags of `recognize` and `bench_recognize`"},
      {Kind::simulator, "Simulator parameters: flags of `experiment` (those marked *simulate* also of `simulate`)"},
      {Kind::experiment, "Experiment parameters: flags of `experiment`"}};
  for (const auto& [kind, title] : kinds) {
    md << (kind == Kind::method ? "" : "\n") << "**" << title << ".**\n\n";
    if (kind == Kind::method)
      md << "| key | flag (older names) | unit | range | paper preset | improved preset | paper | help |\n"
         << "|---|---|---|---|---|---|---|---|\n";
    else
      md << "| key | flag (older names) | unit | range | default | paper | help |\n"
         << "|---|---|---|---|---|---|---|\n";
    for (const auto& p : parameters()) {
      if (p.kind != kind) continue;
      std::string aliases;
      for (const auto& a : p.aliases) aliases += (aliases.empty() ? "" : ", ") + ("`" + a + "`");
      std::string range;
      if (p.type == Type::boolean) range = "true, false";
      else if (p.type == Type::choice)
        for (const auto& c : p.choices) range += (range.empty() ? "" : ", ") + c;
      else if (p.type == Type::names) range = "all, or object names";
      else if (p.type == Type::text) range = p.key == "ransac.samples" ? "NxR" : "text";
      else
        range = number_text(p.lo) + " – " + (std::isinf(p.hi) ? std::string("∞") : number_text(p.hi));
      std::string notes;
      if (p.kind != Kind::method && p.sweepable) notes += "sweepable";
      if (p.simulate) notes += std::string(notes.empty() ? "" : ", ") + "*simulate*";
      md << "| `" << p.key << "` | `" << p.flag() << "`" << (aliases.empty() ? "" : " (" + aliases + ")") << " | "
         << p.unit << " | " << range << " | ";
      if (kind == Kind::method)
        md << value(p, paper) << " | " << value(p, improved);
      else
        md << value(p, improved);
      md << " | " << p.paper << " | " << p.help << (notes.empty() ? "" : " (" + notes + ")") << " |\n";
    }
  }
  return md.str();
}

}  // namespace ts::experiments
