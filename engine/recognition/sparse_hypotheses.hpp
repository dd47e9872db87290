// Feature-free hypothesis generation for sparse contacts: touch probes, fingertip contact
// sensors, a joint-torque contact estimate. FPFH needs a neighbourhood of contacts within the
// feature radius; isolated contacts have none, so Batch RANSAC (Section 4.3.2) cannot propose
// anything from them. This source matches contact TRIPLETS on their pairwise distances (and,
// where the contacts carry normals, on the angles of the point-pair feature of Drost et al.
// 2010: angle(n_a, ab), angle(n_b, ab), angle(n_a, n_b)) against per-object point-pair tables,
// like the congruent sets of 4PCS, and registers each match with Kabsch. Its candidates join
// RANSAC's before the evaluation (Eq. 4-6), so dense patches and isolated contacts mix in one
// exploration, and the swept free space of the probe is the evidence that separates them.
//
// When (`mode`): `kSparseAuto` decides from the data, per step. A contact with no other contact
// within the FPFH feature radius (hence no feature) is isolated; the source runs when at least
// `min_isolated` of them make up at least `min_isolated_share` of the contacts. A tactile pad's
// contacts come in patches (5 mm apart), so pad logs do not turn it on (measured: dev45 logs of
// cow, cube, bar, stellated_octahedron, 20 grasps: never, where "no feature" alone turned it on in
// 28 of 80 steps). `kSparseAlways` runs it on every scene of at least 3 contacts, pads too: its
// triplets span patches of different grasps (sides of at least `min_side_share` of the contacts'
// diameter), which FPFH's neighbourhoods, inside one patch, never relate. `kSparseNever`: off.
//
// Normals: the sensor's where it gives them (a probe: minus its approach direction). Under
// `kSparseAlways` a cloud without them (pads) takes the scene's own (PCA within the FPFH normal
// radius, turned away from the contacts' centroid, which concave regions can get wrong; zero for
// an isolated contact, which is then matched on distances); `kSparseAuto` matches such a cloud
// on distances alone, as before.
//
// Tables (SparseTables): each object's keypoints (the stored coarse cloud with normals)
// thinned by a voxel filter to at most `max_model_points` points, and for each of them every
// other one sorted by distance, with the pair's angles. Built from the database on first use (no
// file format change: the coarse cloud is already stored; at most 2.9 MB an object), shared by
// the recognizers of one database (SparseTables::shared) for as long as one of them holds them.
// Matching sweeps each object's table once a step for all the step's triplets.
//
// Numerics: triplets, in the scene and in the model, must be well-conditioned triangles
// (triangle_well_conditioned: near-collinear sets are rejected by geometry, never by residual);
// sides shorter than twice the distance tolerance are refused (quantized contacts, 1 mm, move a
// side by at most 1.7 mm); coplanar contacts are fine for a triangle, and what they leave
// ambiguous (a flat face) is left to the evaluation and the free space. Symmetric objects give
// many equally good matches; they are all proposed and scored alike.
//
// Deterministic: every draw comes from Rng(seed, step, tag, triplet * objects + object), and each
// (triplet, object) fills its own slot, concatenated in that order, whichever task computed it:
// the same candidates for any thread count.
#pragma once

#include "engine/database/database.hpp"
#include "engine/recognition/evaluate.hpp"
#include "engine/recognition/scene.hpp"

#include <memory>
#include <mutex>

namespace ts {
inline namespace recognition {

constexpr int kSparseAuto = 0;        ///< SparseSettings::mode: when the contacts are isolated
constexpr int kSparseAlways = 1;      ///< on every scene of at least 3 contacts (pads too)
constexpr int kSparseNever = 2;       ///< off (Batch RANSAC alone)

struct SparseSettings {
  int mode = kSparseAuto;             ///< kSparseAuto, kSparseAlways or kSparseNever
  std::size_t min_isolated = 3;       ///< isolated contacts needed before the source runs
  double min_isolated_share = 0.3;    ///< and their share of the contacts
  int triplets = 16;                  ///< contact triplets drawn per step
  std::size_t pairs_per_triplet = 48; ///< matched model pairs tried per (triplet, object)
  std::size_t per_object = 24;        ///< candidates kept per (triplet, object)
  double distance_tolerance = 0.006;  ///< m, |d_model - d_contact| of each side
  double normal_tolerance_deg = 40.0; ///< deg, point-pair angles and registered normals must
                                      ///< agree within this (contacts with normals only)
  double model_spacing = 0.01;        ///< m, voxel of the model points (grown by 1.5 until at
                                      ///< most max_model_points remain)
  std::size_t max_model_points = 600; ///< (8 bytes a pair: 2.9 MB an object at 600)
  double min_sv_ratio = 0.2;          ///< triangles with sigma2/sigma1 below this are degenerate
  double min_side_share = 0.2;        ///< triplet sides at least this share of the contacts'
                                      ///< diameter (and 2 x distance_tolerance)
  int triplet_attempts = 400;         ///< draws per triplet slot before it is given up
  double table_budget_mb = 256.0;     ///< pair tables held beyond this: the least recently
                                      ///< wanted that no caller uses are dropped (rebuilt alike
                                      ///< when wanted again; SparseTables::prepare)
};

/// One object's point-pair table: for every thinned keypoint i, every other point j sorted by
/// distance, with the point-pair angles (Drost et al. 2010) of d = p_j - p_i.
struct ObjectPairs {
  std::vector<Vec3> points;           ///< object frame, thinned keypoints
  std::vector<Vec3> normals;          ///< unit, outward
  double unit = 0.0;                  ///< m per distance unit (largest distance / 65535)
  struct Near {
    std::uint16_t distance;           ///< |p_j - p_i| in `unit`s (rounded)
    std::uint16_t index;              ///< j
    /// angle(n_i, d), angle(n_j, d), angle(n_i, n_j) in units of pi / 255
    std::uint8_t a_i, a_j, a_ij, pad;
  };
  std::vector<Near> near;             ///< rows of n - 1 (row i from i * (n - 1)), each sorted
                                      ///< by (distance, index)
  std::size_t memory_bytes() const;
};

/// An angle in the tables' units (pi / 255), rounded: [0, pi] -> 0..255.
int pair_angle_units(double rad);

/// Build one object's table from its keypoints (engine/recognition/pair_table.cpp).
ObjectPairs build_object_pairs(const ObjectKeypoints& keypoints, const SparseSettings& s);

/// Lazily built tables of a database's objects. Thread-safe; built tables are never changed.
class SparseTables {
 public:
  SparseTables(const Database& db, SparseSettings settings);
  /// One cache per (database, table settings), shared while someone holds it: the recognizers of
  /// an experiment's runs (or of `recognize` over many logs) build each table once, not once per
  /// run (45 objects of 600 points: about 0.3 s of one core), and hold it once.
  static std::shared_ptr<SparseTables> shared(const Database& db, const SparseSettings& settings);

  /// Per database object, its table where wanted (null elsewhere). Each table stays valid while
  /// the view holds it, whatever other callers' prepare() drops meanwhile.
  using View = std::vector<std::shared_ptr<const ObjectPairs>>;
  /// The tables of the objects with wanted[o] != 0 (all when empty), building those missing (in
  /// parallel, outside the lock: callers sharing the cache never wait for each other's builds).
  /// When the tables held exceed `table_budget_mb`, the least recently wanted that no caller is
  /// using are dropped until they fit (a table in some view would stay in memory anyway).
  View prepare(const std::vector<std::uint8_t>& wanted);
  std::size_t held_bytes() const;

 private:
  const Database& db_;
  SparseSettings s_;
  mutable std::mutex mutex_;
  std::vector<std::shared_ptr<const ObjectPairs>> tables_;
  std::vector<std::uint64_t> last_wanted_;   ///< per object, the prepare() call that last wanted it
  std::uint64_t calls_ = 0;                  ///< prepare() calls so far
  std::size_t held_ = 0;                     ///< bytes of the tables held
};

/// Free space of a probe's path in the evaluation: its samples are free by the ball radius only
/// and measured with the arm's error (underwater: 3 mm per axis), so Eq. 8's near-surface term
/// would penalize the true pose (measured: a gear's tooth gaps; 3 mm of d_thresh turned a
/// converged pose into 8 mm answers). Eq. 8 is kept to 0.1 mm (kProbeFreeThreshold) and a path
/// point counts against a hypothesis only when deeper inside it than kProbeInsideMargin
/// (EvaluateSettings::free_inside_margin, with free_inside_penalty).
constexpr double kProbeFreeThreshold = 1e-4;
constexpr double kProbeInsideMargin = 0.01;

/// Slots of the candidates this source makes: kSparseSlot + running index (RANSAC's
/// triplet * R + r stays below it, pose transfer's kTransferSlot above).
constexpr std::uint32_t kSparseSlot = 0x40000000u;

/// Contacts without another contact within the feature radius (and so without a feature).
std::size_t isolated_contacts(const Scene& scene);
/// Whether the source runs for this scene (SparseSettings::min_isolated, min_isolated_share).
bool sparse_active(const Scene& scene, const SparseSettings& s);

struct SparseStats {
  bool active = false;                ///< the source ran
  std::size_t isolated = 0;           ///< contacts without a feature
  std::size_t triplets = 0;           ///< triplet slots that found a triplet
  std::size_t candidates = 0;
  double time_s = 0.0;
};

/// The candidates (scene frame) for the allowed objects. `contact_normals_world` are the
/// contacts' normals where the sensor knows them (a probe: minus its approach direction), one
/// per point of `scene.contacts` in the same order, zero where unknown, or empty: none known.
/// Nothing when the source is not active for the scene.
std::vector<Candidate> sparse_candidates(const Scene& scene, SparseTables& tables,
                                         const std::vector<Vec3>& contact_normals,
                                         const std::vector<std::uint8_t>& allowed,
                                         const SparseSettings& s, std::uint64_t seed,
                                         std::uint64_t step, SparseStats* stats = nullptr);

/// The contacts' normals in the scene's order: each scene contact takes the normal of the
/// nearest input contact (within 1e-9 m after the scene's translation), zero where the input
/// has none. Empty when `contacts_world` has no normals.
std::vector<Vec3> scene_contact_normals(const Scene& scene, const PointCloud& contacts_world);
/// The normals the source matches with: scene_contact_normals, or, under kSparseAlways when the
/// input has none (pads), the scene's own PCA normals (zero where undefined).
std::vector<Vec3> sparse_contact_normals(const Scene& scene, const PointCloud& contacts_world,
                                         const SparseSettings& s);

/// Mean distance of the contacts (world frame) to the object's surface under T_world_object,
/// from the distance field (|d|); NaN without contacts. What Vezzani et al. (2017) report.
double mean_contact_distance(const ObjectGeometry& geometry, const Pose& T_world_object,
                             const std::vector<Vec3>& contacts_world);

}  // namespace recognition
}  // namespace ts
