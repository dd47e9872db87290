// Batch RANSAC database matching (Section 4.3.2), hypothesis generation part:
//   triplet sampling     N triplets of interior contacts, pairwise at least min_spacing apart
//                        and far from collinear;
//   feature pruning      the W nearest database features of each triplet point (KT_db,cum^feat);
//   triplet registration R times per triplet: one pruned feature per triplet point, all three of
//                        one object, inter-point distances matching the input's; Kabsch (Arun).
// Scoring (Eq. 4-5) and the choice of the best lives in engine/recognition/evaluate (select_top).
// Parallel over triplets and over registrations; every draw comes from Rng(seed, step, task),
// every task fills its own slot, so the candidates are the same for any thread count.
#pragma once

#include "engine/database/database.hpp"
#include "engine/database/feature_table.hpp"
#include "engine/geometry/search.hpp"
#include "engine/recognition/evaluate.hpp"
#include "engine/recognition/scene.hpp"

namespace ts {
inline namespace recognition {

struct RansacSettings {
  int triplets = 15;                  ///< N, triplets sampled from the input (paper: 15)
  int registrations = 200;            ///< R, registrations per triplet (paper: 200)
  std::size_t prune_w = 3000;         ///< W, nearest database features per point (paper: 3000)
  std::size_t prune_per_object = 0;   ///< extension: the W_obj nearest features of EVERY
                                      ///< allowed object instead of the W nearest overall
                                      ///< (0: the paper's global W); needs feature_table
  std::size_t object_draws = 0;       ///< extension, large databases: with per-object pruning,
                                      ///< each triplet searches only this many allowed objects,
                                      ///< the next slice of the run's shuffled object order
                                      ///< (every allowed object once before any twice; all of
                                      ///< them when there are no more allowed objects than
                                      ///< draws; 0: always all). Bounds the pruning of a step
                                      ///< by N x object_draws objects, whatever the database
  std::size_t prior_draws = 0;        ///< extension, large databases: of each triplet's
                                      ///< object_draws, this many are the step's best objects
                                      ///< by the shape prior (the same for every triplet; the
                                      ///< rest is the triplet's slice of the shuffled order)
  std::size_t prune_blocks = 0;       ///< extension: per-object pruning reads only each
                                      ///< object's prune_blocks blocks of 128 features nearest
                                      ///< to the query (approximate; 0: exact, every block
                                      ///< that can hold one of the W_obj nearest)
  std::size_t prune_blocks_min_database = 0;  ///< prune_blocks acts only on databases of more
                                              ///< objects than this (smaller ones: exact)
  bool feature_table = true;          ///< W-nearest search: exact batched brute force
                                      ///< (FeatureTable); false: the FeatureIndex
  double min_spacing = 0.0;           ///< m between triplet points; 0: the FPFH feature radius.
                                      ///< Capped at 0.3 x the contact cloud's diameter
  double distance_tolerance = 0.006;  ///< m, allowed |d_db - d_input| of each point pair
  double normal_tolerance_deg = 0.0; ///< extension: registered pairs must also agree in the
                                      ///< angles between their normals and chord, within this
                                      ///< (0: off, the paper's distance test only)
  double min_sv_ratio = 0.15;         ///< triangles (input and database) with sigma2/sigma1
                                      ///< below this are degenerate (near-collinear)
  int triplet_attempts = 500;         ///< draws before a triplet slot is given up
  int registration_attempts = 30;     ///< first-feature draws per registration before giving up
  double size_slack = 0.02;           ///< m; objects whose bounding-box diagonal is shorter than
                                      ///< the contact cloud's diameter minus this are excluded
};

struct RansacStats {
  std::size_t triplets = 0;               ///< triplet slots that found a valid triplet
  std::size_t pruned = 0;                 ///< pruned features kept (allowed objects), summed
  std::size_t registrations = 0;          ///< valid registrations (candidates)
  std::size_t objects_allowed = 0;        ///< objects large enough to span the contacts
  std::size_t objects_reached = 0;        ///< objects with at least one candidate
  std::size_t objects_searched = 0;       ///< (triplet, object) pairs whose features were searched
  std::vector<std::uint8_t> searched;     ///< per database object: some triplet searched it
  bool boundary_fallback = false;         ///< too few interior points: boundary points used
  double time_prune_s = 0.0;              ///< triplet sampling and feature pruning
  double time_register_s = 0.0;           ///< triplet registration
};

/// Objects whose bounding-box diagonal can span the contacts (1 = allowed).
std::vector<std::uint8_t> objects_spanning(const Scene& scene, const Database& db, double slack);

/// Build the database-wide feature index (KT_db,cum^feat) over the coarse features of every
/// object, or of the objects with objects[i] != 0 when `objects` is not empty.
FeatureIndex build_feature_index(const Database& db, const FeatureIndexSettings& settings,
                                 const std::vector<std::uint8_t>& objects = {});

/// KT_db,cum^feat: the W-nearest database features of query features, from a FeatureTable
/// (exact, batched) when set, else from a FeatureIndex.
struct FeatureSearch {
  std::shared_ptr<const FeatureTable> table;
  std::shared_ptr<const FeatureIndex> index;

  std::size_t size() const;
  const FeatureRef& ref(std::size_t i) const;
  /// Per query, the w nearest (sorted by distance, then row). Parallel.
  std::vector<std::vector<Neighbour>> knn(const FeatureRows& queries, std::size_t w) const;
  /// Per query, the w nearest of every object of the mask (all: empty mask)
  /// (FeatureTable::knn_per_object; table only).
  std::vector<std::vector<Neighbour>> knn_per_object(const FeatureRows& queries,
                                                     std::size_t w,
                                                     const std::vector<std::vector<std::uint8_t>>& masks,
                                                     std::size_t max_blocks = 0) const;
};

/// N x R registrations; the valid ones, in slot order (slot = triplet * R + registration).
/// Per-object pruning searches the allowed objects only; the paper's global W nearest are
/// searched among all objects (KT_db,cum^feat) and then filtered. `preferred`: objects best
/// first (the shape prior's ranking), the first prior_draws allowed ones searched by every
/// triplet when object draws are on.
std::vector<Candidate> ransac_candidates(const Scene& scene, const Database& db,
                                         const FeatureSearch& search,
                                         const std::vector<std::uint8_t>& allowed,
                                         const RansacSettings& settings, std::uint64_t seed,
                                         std::uint64_t step, RansacStats* stats = nullptr,
                                         const std::vector<std::uint32_t>& preferred = {});

}  // namespace recognition
}  // namespace ts
