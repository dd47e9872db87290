// `touchstone catalogue`: a generator of parametric subsea objects for database-scalability
// studies (thousands of closed meshes at true size, in metres).
//
// Pipeline (generate_catalogue):
//   1. families: the selected families with their (possibly overridden) ranges and weights;
//      object i gets a family by smooth weighted round robin (all weights 1: plain round robin);
//   2. per object, in parallel: parameters drawn from Rng(seed, kStream, i, attempt), the CSG
//      solid built and meshed (OpenVDB level sets, voxel from the object's size, see
//      BuildSettings), checked (closed, consistently wound outward, no degenerate face) and
//      written as binary PLY; only a signature is kept in memory;
//   3. congruence: in index order, an object whose signature lies within `tolerance` of an
//      earlier object's is redrawn (attempt + 1), until none is;
//   4. the closest pairs, manifest.tsv, catalogue.tsv and closest_pairs.tsv.
// Threading guarantee: every draw comes from a stream seeded by (seed, index, attempt), every
// task writes its own slot and the congruence pass is serial in index order: the output bytes
// do not depend on the number of threads (set by the caller's task arena).
// Output: everything is written into "<out>.tmp-<pid>" and renamed onto <out> at the end; an
// existing <out> is an error unless `force` (then it is replaced only once the new catalogue is
// complete). A failure leaves <out> as it was. Temporary folders "<out>.tmp-<pid>" of runs
// whose process no longer exists (killed, interrupted) are removed by the next run.
#pragma once

#include "datasets/catalogue/families.hpp"

#include <array>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace ts::catalogue {

/// Generator version, recorded in manifest.tsv and catalogue.tsv.
constexpr const char* kGeneratorVersion = "catalogue-1";

/// How solids are voxelized and meshed.
struct BuildSettings {
  /// voxel = max(triangle-budget voxel, min(thinnest feature / feature_voxels, extent * max_voxel_fraction)),
  /// at least extent * min_voxel_fraction, times coarsen.
  double feature_voxels = 3.0;      ///< voxels across the thinnest feature (wall, rod) when affordable
  double max_voxel_fraction = 1.0 / 120;   ///< voxel at most extent * this
  double min_voxel_fraction = 1.0 / 400;  ///< voxel at least extent * this
  double target_triangles = 30000;  ///< at most this many triangles (from a coarse preview), features permitting
  double max_triangles = 60000;     ///< more than this: mesh again with a coarser voxel
  double preview_voxel_fraction = 1.0 / 40;  ///< preview meshing (triangle count) at extent * this
  double coarsen = 1.0;             ///< multiplies the voxel (tests use > 1 for speed)
  double half_width = 3.0;          ///< level-set narrow band, voxels
  int finer_retries = 2;            ///< an invalid mesh is meshed again at 0.8 x the voxel this often
};

/// A built object.
struct BuiltObject {
  Mesh mesh;            ///< metres, closed, wound outward
  double voxel = 0.0;   ///< m
  double extent = 0.0;  ///< m, largest bounding-box side
  MeshCheck check;
  int remeshed = 0;     ///< times meshed again at a finer voxel because the check failed
};

/// Build one object of `family` from `params`. Throws ts::Error naming the family and the
/// parameter values when the mesh is not a valid closed, outward-wound 2-manifold.
BuiltObject build_object(const Family& family, const Params& params, const BuildSettings& settings = {});

/// Rotation-invariant shape signature, in metres: (V^(1/3), A^(1/2), sqrt of the three
/// eigenvalues of the solid's covariance (second moments about its centroid), ascending).
using Signature = std::array<double, 5>;
Signature shape_signature(const Mesh& mesh);
/// max_k |ln(a_k / b_k)|: 0 for congruent solids; 0.01 means some measure differs by ~1 %.
double signature_distance(const Signature& a, const Signature& b);

struct ClosePair {
  std::size_t a = 0, b = 0;   ///< a < b
  double distance = 0.0;
};
/// The `k` closest pairs (ascending distance, ties by (a, b)); O(N^2), parallel, deterministic.
std::vector<ClosePair> closest_pairs(const std::vector<Signature>& signatures, std::size_t k);
/// For each object, the first earlier object within `tolerance` (index order), or -1.
std::vector<long> congruent_to_earlier(const std::vector<Signature>& signatures, double tolerance);

/// Family selection and range overrides (from --families and --config).
struct FamilySet {
  std::vector<Family> families;   ///< selected, in catalogue order
  /// All families, or those named (comma-separated list; unknown name: ts::Error).
  static FamilySet select(const std::string& names = {});
  /// Override a parameter's range (or a family's "weight" with lo == hi). Throws ts::Error
  /// naming `file` and "family.param" for an unknown family or parameter, lo > hi, a
  /// non-positive length, a negative weight or a choice index out of range.
  void set_range(const std::string& family, const std::string& param, double lo, double hi,
                 const std::string& file = {});
  /// Check every range (as set_range does) and that some family has a positive weight.
  void validate(const std::string& file = {}) const;
};

struct CatalogueSettings {
  std::size_t count = 0;          ///< objects, 1..100000
  std::uint64_t seed = 1;
  FamilySet families = FamilySet::select();
  BuildSettings build;
  /// Signature distance at or below which two objects count as congruent. The same solid meshed
  /// at a voxel 13 % finer moves by up to ~0.011 (elbow, hot_stab, grab_bar; most families
  /// < 0.005): objects closer than that are indistinguishable at mesh accuracy.
  double tolerance = 0.01;
  int max_attempts = 50;          ///< redraws of one object before giving up
  bool force = false;             ///< replace an existing output folder
  std::size_t report_pairs = 5;   ///< closest pairs reported
  /// Called from worker threads (serialize inside) as objects finish: (done, total).
  std::function<void(std::size_t, std::size_t)> progress;
};

struct CatalogueObject {
  std::string name, family;
  Params params;
  int attempts = 1;               ///< draws until accepted
  int remeshed = 0;               ///< finer remeshes after a failed mesh check
  double voxel = 0.0, extent = 0.0, volume = 0.0;
  std::size_t vertices = 0, triangles = 0, bytes = 0;
  Signature signature{};
};

struct CatalogueReport {
  std::vector<CatalogueObject> objects;
  std::vector<ClosePair> closest;     ///< the settings.report_pairs closest pairs
  std::size_t redraws = 0;            ///< objects redrawn because of a congruent earlier object
  std::size_t bytes = 0;              ///< mesh files in total
  double seconds = 0.0;               ///< wall time
};

/// Generate the catalogue into `out` (see the header comment). Throws ts::Error on bad
/// settings, an existing folder without force, or an object that fails its mesh check.
CatalogueReport generate_catalogue(const std::filesystem::path& out, const CatalogueSettings& settings);

}  // namespace ts::catalogue
