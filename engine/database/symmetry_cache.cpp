#include "engine/database/symmetry_cache.hpp"

namespace ts {
inline namespace database {

SymmetryCache::SymmetryCache(SymmetrySettings settings) : settings_(settings) {}
SymmetryCache::~SymmetryCache() = default;

const SymmetryGroup& SymmetryCache::get(const Database& db, std::size_t object) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = groups_.find(object);
  if (it != groups_.end()) return *it->second;
  // The fine cloud itself (the database may hold distance fields only).
  const PointCloud fine = db.load_fine(object);
  const KdTree3 tree(fine.points);
  auto g = std::make_unique<SymmetryGroup>(find_symmetries(fine.points, tree, settings_));
  return *groups_.emplace(object, std::move(g)).first->second;
}

}  // namespace database
}  // namespace ts
