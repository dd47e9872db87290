// Object shortlist: which objects' hypotheses go on to ICP and the full evaluation (Touchstone
// extension for large databases: "leave out what a scene does not need").
//
// Batch RANSAC's candidates spread over every object that feature pruning reaches, and
// evaluating them needs each object's geometry (fine cloud, k-d tree, distance field): on a
// database of hundreds of objects every step would load every object. The shortlist screens
// the candidates first against what is always in memory, each object's coarse cloud (one
// keypoint per coarse voxel, with its normal): a spread sample of the contacts, moved by the
// candidate's pose, is scored against the nearest coarse point x with normal n,
//     d = max(|n . (p - x)|, |p - x| - coarse_voxel)     (the plane distance near the cloud)
//     e = min(1, (d / outlier_distance)^2),  score = mean e   (Eq. 4 with a tight outlier)
// An object ranks by its best candidate; the `objects` best objects, and every object that
// holds a hypothesis of the current state (a found object is never dropped), go on. Feature
// evidence alone cannot do this: a tactile FPFH names its object among the 16 nearest of 45
// only about half the time (experiments/bench/bench_shortlist.cpp); geometry can.
#pragma once

#include "engine/database/database.hpp"
#include "engine/recognition/evaluate.hpp"
#include "engine/recognition/scene.hpp"

#include <cstdint>
#include <vector>

namespace ts {
inline namespace recognition {

struct ShortlistSettings {
  std::size_t objects = 0;          ///< objects whose candidates go on (0: off, all of them)
  std::size_t min_database = 0;     ///< active only on databases of more objects than this
                                    ///< (smaller ones are searched whole and fit in memory)
  std::size_t contacts = 24;        ///< contacts scored per candidate (the scene's fixed order)
  double outlier_distance = 0.01;   ///< m, e = min(1, (d / outlier_distance)^2)
};

struct Shortlist {
  bool active = false;                ///< false: nothing was left out
  std::vector<std::uint8_t> mask;     ///< per database object: its candidates go on
  std::vector<double> best;           ///< per database object: best screening score (lower is
                                      ///< better; exact for the `objects` best, 1 for the others
                                      ///< and where it has no candidate)
  std::vector<std::uint32_t> ranked;  ///< objects with candidates, best first (ties: smaller
                                      ///< index); beyond the `objects` best, in index order
  std::size_t kept = 0;               ///< objects in the mask
};

/// Screening score of every candidate, in [0, 1], lower is better (see above). Parallel,
/// deterministic. Needs only the objects' features (coarse clouds), never their geometry.
std::vector<double> screen_candidates(const Scene& scene, const Database& db,
                                      const std::vector<Candidate>& candidates,
                                      const ShortlistSettings& settings);
/// Per database object, its best (lowest) candidate score: the minimum of screen_candidates over
/// the object's candidates, exactly, but a candidate stops being scored as soon as its partial
/// sum shows it cannot beat the object's best so far (1 for objects without candidates). With
/// keep > 0 only the keep best objects (by score, then index) matter: a candidate also stops once
/// it cannot beat the keep-th best score so far, and every other object reports 1. Either way
/// the result is the same for any thread count.
std::vector<double> screen_objects(const Scene& scene, const Database& db, const std::vector<Candidate>& cands,
                                   const ShortlistSettings& s, std::size_t keep = 0);

/// Rank the objects of `candidates` by their best screening score and keep the settings.objects
/// best and every object of `always`. Inactive (every object kept) when settings.objects is 0
/// or no smaller than the number of objects with candidates.
Shortlist shortlist_objects(const Scene& scene, const Database& db,
                            const std::vector<Candidate>& candidates,
                            const std::vector<std::uint32_t>& always,
                            const ShortlistSettings& settings);

}  // namespace recognition
}  // namespace ts
