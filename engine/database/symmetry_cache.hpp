// The rotational symmetries of a database's objects (engine/geometry/symmetry.hpp), found once
// per object from its fine cloud and kept for the life of the cache.
#pragma once

#include "engine/database/database.hpp"
#include "engine/geometry/symmetry.hpp"

#include <map>
#include <memory>
#include <mutex>

namespace ts {
inline namespace database {

/// Thread-safe per-object cache over a database (computes from the object's fine cloud on first
/// use; loads the object's geometry if it is not loaded yet).
class SymmetryCache {
 public:
  explicit SymmetryCache(SymmetrySettings settings = {});
  ~SymmetryCache();
  const SymmetryGroup& get(const Database& db, std::size_t object);

 private:
  SymmetrySettings settings_;
  std::mutex mutex_;
  std::map<std::size_t, std::unique_ptr<SymmetryGroup>> groups_;
};

}  // namespace database
}  // namespace ts
