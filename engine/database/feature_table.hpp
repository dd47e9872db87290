// Exact W-nearest feature search: the database-wide feature set KT_db,cum^feat of Section 4.3.2
// as a table of blocks of 256 rows in k-d leaf order, each with its bounding box.
// A query visits blocks best-first by their lower bound and computes all distances of a block
// at once (SIMD over rows); it stops when no unvisited block can hold a nearer row. With W =
// 3000 of ~200k FPFH features a classic tree visits most of the set one point at a time; this
// visits few blocks, is exact, and returns the same neighbours for any thread count.
#pragma once

#include "engine/database/database.hpp"
#include "engine/geometry/search.hpp"

#include <memory>

namespace ts {
inline namespace database {

class FeatureTable {
 public:
  FeatureTable();
  /// All objects' coarse features, or those of objects[i] != 0 when `objects` is not empty.
  explicit FeatureTable(const Database& db, const std::vector<std::uint8_t>& objects = {});
  ~FeatureTable();
  FeatureTable(FeatureTable&&) noexcept;
  FeatureTable& operator=(FeatureTable&&) noexcept;

  std::size_t size() const;        ///< rows, padding between objects included (ref() of a
                                   ///< padding row has object 0xffffffff)
  std::size_t features() const;    ///< rows that hold a feature
  int dim() const;                 ///< values per feature (the database's descriptor)
  const FeatureRef& ref(std::size_t i) const;
  /// For each query, the w nearest rows by squared L2 distance (accumulated in float over the
  /// bins in order), sorted by (distance, row). Exact. Parallel (TBB) over queries. Queries must
  /// have the table's dimension (the database's descriptor; ts::Error otherwise).
  std::vector<std::vector<Neighbour>> knn(const FeatureRows& queries, std::size_t w) const;
  /// For each query, the w nearest rows of EVERY object (exact; each object's rows sorted by
  /// (distance, row), objects ascending). Flat patches match thousands of near-identical
  /// features of box-like objects; a global W then starves the other objects, this does not.
  std::vector<std::vector<Neighbour>> knn_per_object(const FeatureRows& queries,
                                                     std::size_t w) const;
  /// The same restricted to the objects with mask[object] != 0 (an empty mask: every object);
  /// only the blocks of those objects are read. max_blocks > 0: approximate, each object's w
  /// nearest among its max_blocks blocks whose mean is nearest to the query (an inverted file
  /// whose cells are the k-d leaves of 128 rows); exact with 0.
  std::vector<std::vector<Neighbour>> knn_per_object(const FeatureRows& queries,
                                                     std::size_t w,
                                                     const std::vector<std::uint8_t>& mask,
                                                     std::size_t max_blocks = 0) const;
  /// The same with a mask per query (masks[q] for queries[q]; an empty mask: every object).
  std::vector<std::vector<Neighbour>> knn_per_object(const FeatureRows& queries,
                                                     std::size_t w,
                                                     const std::vector<std::vector<std::uint8_t>>& masks,
                                                     std::size_t max_blocks = 0) const;
  /// Bytes held by the table (feature rows, bounds, references).
  std::size_t memory_bytes() const;

  /// One table per (database, object mask), shared while someone holds it.
  static std::shared_ptr<const FeatureTable> shared(const Database& db,
                                                    const std::vector<std::uint8_t>& objects = {});

 struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace database
}  // namespace ts
