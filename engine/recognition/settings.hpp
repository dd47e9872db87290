// What a recognizer is asked to do: the method (Section 4.4's BRICPSF, Section 5.4's ablations)
// and every parameter of its stages, with the paper's and Touchstone's presets.
#pragma once

#include "engine/database/database.hpp"
#include "engine/recognition/shape_prior.hpp"
#include "engine/recognition/evaluate.hpp"
#include "engine/recognition/icp.hpp"
#include "engine/recognition/ransac.hpp"
#include "engine/recognition/scene.hpp"
#include "engine/recognition/shortlist.hpp"
#include "engine/recognition/sparse_hypotheses.hpp"
#include "engine/recognition/support.hpp"
#include "engine/recognition/twins.hpp"

#include <optional>
#include <string_view>

namespace ts {
inline namespace recognition {

enum class Method { batch_ransac, ransac_icp, ransac_icp_fs, bricpsf };
std::string_view method_name(Method m);                  ///< "bricpsf", "batch-ransac", ...
std::optional<Method> parse_method(std::string_view name);

struct RecognizerSettings {
  Method method = Method::bricpsf;
  std::size_t n_p = 100;            ///< hypotheses kept per step (Section 5.5: 100)
  double psi = 0.8;                 ///< share of evolved old hypotheses in resampling (0.8)
  bool refine_new = false;          ///< extension: ICP on the new RANSAC hypotheses chosen in
                                    ///< resampling before they join (bricpsf)
  std::size_t refine_pool = 0;      ///< extension: best RANSAC candidates considered for the
                                    ///< (1-Psi) n_p new ones (refined first with refine_new);
                                    ///< 0: (1-Psi) n_p, or twice that with dedupe or a cap
  std::size_t new_per_object = 0;   ///< extension: at most this many new hypotheses of one
                                    ///< object per step (0: no cap)
  bool dedupe = false;              ///< extension: drop hypotheses that duplicate a better one
                                    ///< (same object, pose within dedupe_distance / 2 degrees)
  double dedupe_distance = 0.002;   ///< m
  double icp_top = 0.0;             ///< ransac-icp(-fs): ICP only the best share of candidates
                                    ///< by pre-ICP score (0: all, as in the paper)
  bool early_stop = false;          ///< extension (bricpsf): when the previous state's leading
                                    ///< hypothesis, evolved on this step's contacts, explains
                                    ///< them all within noise and no other object's does, the
                                    ///< step proposes no new hypotheses (the sources are left out)
  double early_stop_rms_sigma = 1.0;  ///< "within noise": no contact beyond 3
                                      ///< evaluate.grasp_contact_sigma, their RMS (each clamped
                                      ///< there) within this many sigmas, and at most
                                      ///< early_stop_free_conflict of Eq. 8's error per free point
  double early_stop_free_conflict = 0.02;
  std::size_t early_stop_max_database = 0;  ///< early stop acts on databases of at most this
                                            ///< many objects (0: any)
  std::uint64_t seed = 1;           ///< every random draw derives from (seed, step, task)
  std::vector<std::uint8_t> objects;  ///< objects the recognizer may answer (1 = yes), by
                                      ///< database index; empty: all
  ShortlistSettings shortlist;      ///< extension: objects whose candidates are evaluated in full
                                    ///< per step (large databases)
  TwinSettings twins;               ///< extension: near-twin verification of the leading objects
  ShapePriorSettings prior;         ///< extension: the shape prior that ranks the objects
                                    ///< for feature pruning (ransac.prior_draws > 0)
  std::size_t prior_min_database = 0;  ///< the shape prior acts only on databases of more
                                       ///< objects than this
  SparseSettings sparse;            ///< extension: feature-free triplet matching when the
                                    ///< contacts are isolated (touch probes; sparse_hypotheses.hpp)
  SceneSettings scene{.free_clearance = -1.0};  ///< free_clearance < 0: d_thresh (Eq. 8)
  SupportSettings support;          ///< extension: the support under the object (a seabed), whose
                                    ///< contacts are set aside (support.hpp; off by default)
  RansacSettings ransac;
  IcpSettings icp;
  EvaluateSettings evaluate;
  FeatureIndexSettings index;

  /// Every length multiplied by `factor` (objects of another size scale).
  RecognizerSettings scaled(double factor) const;

  /// The paper's method (the defaults): Section 4.3-4.4 and 5.5 parameters, no extensions.
  static RecognizerSettings paper();
  /// The paper's method with Touchstone's extensions for accuracy: free space inside a closed
  /// object is penalized, duplicate hypotheses are dropped, the best 60 RANSAC candidates are
  /// refined by ICP before the (1-Psi) n_p new ones are chosen, at most 5 of them per object,
  /// and feature pruning keeps the 200 nearest features of every object (not 3000 overall).
  /// Measured on simulated underwater logs of the 45 objects at step 20: see docs/results/
  /// (bench_recognize; the history in CHANGELOG.md).
  static RecognizerSettings improved();
};

/// Whether recognition with `s` reads the objects' fine clouds and k-d trees (ICP other than
/// the field metric, the evaluation without the field, or d_outlier beyond the field's coarse
/// margin); when not, Database::set_surface(false) loads the distance fields alone.
bool needs_surface(const RecognizerSettings& s, const DatabaseSettings& database);

}  // namespace recognition
}  // namespace ts
