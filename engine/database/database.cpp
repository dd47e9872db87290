#include "engine/database/database.hpp"

#include "engine/geometry/cloud.hpp"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#ifdef __GLIBC__
#include <malloc.h>
#endif

namespace ts {
inline namespace database {

namespace {
template <class Db>
double largest_extent_of(const Db& db) {
  if (db.settings().scale == ObjectScale::fit || db.size() == 0) return db.settings().max_extent;
  double largest = 0.0;
  for (std::size_t i = 0; i < db.size(); ++i) largest = std::max(largest, db.info(i).extent.maxCoeff());
  return largest;
}
}  // namespace

double largest_object_extent(const ObjectSource& source) { return largest_extent_of(source); }
double largest_object_extent(const Database& db) { return largest_extent_of(db); }

const char* to_string(ObjectScale scale) { return scale == ObjectScale::keep ? "keep" : "fit"; }

ObjectScale parse_object_scale(const std::string& word, const std::string& file, const std::string& field) {
  if (word == "fit") return ObjectScale::fit;
  if (word == "keep") return ObjectScale::keep;
  throw Error("object scale must be 'fit' or 'keep', not '" + word + "'", file, field);
}

MemorySource::MemorySource(std::vector<BuiltObject> objects, DatabaseSettings settings)
    : objects_(std::move(objects)), settings_(std::move(settings)) {}

std::size_t MemorySource::size() const { return objects_.size(); }
const ObjectInfo& MemorySource::info(std::size_t i) const { return objects_.at(i).info; }
const DatabaseSettings& MemorySource::settings() const { return settings_; }
ObjectFeatures MemorySource::load_features(std::size_t i) const { return objects_.at(i).features; }
PointCloud MemorySource::load_fine(std::size_t i) const { return objects_.at(i).fine; }
DistanceField MemorySource::load_field(std::size_t i) const {
  const auto& f = objects_.at(i).field;
  return DistanceField::from_sparse(f.fine_sparse(), f.coarse_sparse(), f.is_signed(),
                                    f.coarse_margin());
}

struct Database::Slot {
  std::once_flag keypoints_once;
  std::unique_ptr<ObjectKeypoints> keypoints;
  std::mutex mutex;                           ///< guards geometry, bytes (and loading)
  GeometryRef geometry;
  std::size_t bytes = 0;
  std::atomic<std::uint64_t> last_use{0};
  std::atomic<bool> resident{false};
};

struct Database::Cache {
  std::atomic<std::uint64_t> clock{0};
  std::atomic<std::size_t> bytes{0}, peak{0}, loads{0}, evictions{0}, resident{0};
  std::atomic<std::size_t> budget{0};
  std::atomic<bool> surface{true};
  std::mutex trim_mutex;
};

std::size_t memory_bytes(const ObjectGeometry& g) {
  return g.fine.points.capacity() * sizeof(Vec3) + g.fine.normals.capacity() * sizeof(Vec3) +
         g.tree.memory_bytes() + g.field.memory_bytes() + sizeof(ObjectGeometry);
}

Database::Database(std::shared_ptr<const ObjectSource> source)
    : source_(std::move(source)), slots_(new Slot[source_->size()]), cache_(std::make_unique<Cache>()) {}

Database::~Database() = default;

std::size_t Database::size() const { return source_->size(); }
const ObjectInfo& Database::info(std::size_t i) const { return source_->info(i); }
const DatabaseSettings& Database::settings() const { return source_->settings(); }

std::size_t Database::find(const std::string& name) const {
  for (std::size_t i = 0; i < size(); ++i)
    if (info(i).name == name) return i;
  return size();
}

const ObjectKeypoints& Database::keypoints(std::size_t i) const {
  Slot& s = slots_[i];
  std::call_once(s.keypoints_once, [&] {
    tbb::this_task_arena::isolate([&] {
      auto k = std::make_unique<ObjectKeypoints>();
      k->coarse = source_->load_coarse(i);
      s.keypoints = std::move(k);
    });
  });
  return *s.keypoints;
}

const KdTree3& ObjectKeypoints::tree() const {
  std::call_once(tree_once_, [&] {
    // Isolated: a thread waiting on the once flag must not pick up a task that waits on it too.
    tbb::this_task_arena::isolate([&] { tree_ = KdTree3::over(coarse.points); });
    tree_built_.store(true, std::memory_order_release);
  });
  return tree_;
}

const std::vector<Vec3>& ObjectGeometry::extremes() const {
  std::call_once(extremes_->once, [&] {
    tbb::this_task_arena::isolate([&] {   // (as the keypoints' load)
      const std::vector<Vec3>& from =
          extremes_->db ? extremes_->db->keypoints(extremes_->object).coarse.points : fine.points;
      extremes_->points = extreme_points(from, kExtremeDirections);
    });
  });
  return extremes_->points;
}

ObjectFeatures Database::load_features(std::size_t i) const { return source_->load_features(i); }

GeometryRef Database::geometry(std::size_t i) const {
  Slot& s = slots_[i];
  GeometryRef g;
  bool loaded = false;
  {
    std::lock_guard<std::mutex> lock(s.mutex);
    if (!s.geometry) {
      // Isolated: a thread waiting inside the load (OpenVDB and the tree use TBB) must not pick
      // up another task that could ask for this object and block on this slot.
      auto fresh = tbb::this_task_arena::isolate([&] {
        auto g = std::make_shared<ObjectGeometry>();
        if (cache_->surface.load()) {
          g->fine = source_->load_fine(i);
          g->tree = KdTree3::over(g->fine.points);
        }
        g->field = source_->load_field(i);
        g->extremes_->db = this;
        g->extremes_->object = i;
        return g;
      });
      s.bytes = memory_bytes(*fresh);
      s.geometry = std::move(fresh);
      s.resident.store(true, std::memory_order_release);
      const std::size_t now = cache_->bytes.fetch_add(s.bytes) + s.bytes;
      std::size_t peak = cache_->peak.load();
      while (now > peak && !cache_->peak.compare_exchange_weak(peak, now)) {}
      cache_->loads.fetch_add(1);
      cache_->resident.fetch_add(1);
      loaded = true;
    }
    s.last_use.store(cache_->clock.fetch_add(1) + 1, std::memory_order_relaxed);
    g = s.geometry;
  }
  if (loaded) trim();
  return g;
}

void Database::trim() const {
  const std::size_t budget = cache_->budget.load();
  if (budget == 0 || cache_->bytes.load() <= budget) return;
  std::lock_guard<std::mutex> guard(cache_->trim_mutex);
  std::vector<std::pair<std::uint64_t, std::size_t>> order;  // (last use, object)
  for (std::size_t i = 0; i < size(); ++i)
    if (slots_[i].resident.load(std::memory_order_acquire))
      order.push_back({slots_[i].last_use.load(std::memory_order_relaxed), i});
  std::sort(order.begin(), order.end());
  std::size_t evicted = 0;
  for (const auto& [use, i] : order) {
    if (cache_->bytes.load() <= budget) break;
    Slot& s = slots_[i];
    std::lock_guard<std::mutex> lock(s.mutex);
    if (!s.geometry || s.geometry.use_count() > 1) continue;  // gone, or in use
    s.geometry.reset();
    s.resident.store(false, std::memory_order_release);
    cache_->bytes.fetch_sub(s.bytes);
    cache_->resident.fetch_sub(1);
    cache_->evictions.fetch_add(1);
    s.bytes = 0;
    ++evicted;
  }
#ifdef __GLIBC__
  // Evicted grids are many small blocks; hand the freed pages back so that resident memory
  // follows the budget.
  if (evicted > 0) malloc_trim(0);
#endif
}

bool Database::geometry_loaded(std::size_t i) const {
  return slots_[i].resident.load(std::memory_order_acquire);
}

std::size_t Database::geometry_loads() const { return cache_->loads.load(); }
std::size_t Database::geometry_resident() const { return cache_->resident.load(); }
std::size_t Database::geometry_evictions() const { return cache_->evictions.load(); }
std::size_t Database::geometry_bytes() const { return cache_->bytes.load(); }
std::size_t Database::geometry_peak_bytes() const { return cache_->peak.load(); }

void Database::set_memory_budget(std::size_t bytes) {
  cache_->budget.store(bytes);
  trim();
}

std::size_t Database::memory_budget() const { return cache_->budget.load(); }

void Database::set_surface(bool on) {
  std::lock_guard<std::mutex> guard(cache_->trim_mutex);
  if (cache_->surface.load() == on) return;
  for (std::size_t i = 0; i < size(); ++i) {
    Slot& s = slots_[i];
    std::lock_guard<std::mutex> lock(s.mutex);
    if (s.geometry && s.geometry.use_count() > 1)
      throw Error("cannot change which geometry is loaded while '" + info(i).name + "' is in use");
  }
  cache_->surface.store(on);
  for (std::size_t i = 0; i < size(); ++i) {
    Slot& s = slots_[i];
    std::lock_guard<std::mutex> lock(s.mutex);
    if (!s.geometry) continue;
    s.geometry.reset();
    s.resident.store(false, std::memory_order_release);
    cache_->bytes.fetch_sub(s.bytes);
    cache_->resident.fetch_sub(1);
    s.bytes = 0;
  }
}

bool Database::surface() const { return cache_->surface.load(); }

PointCloud Database::load_fine(std::size_t i) const { return source_->load_fine(i); }

void GeometryPins::load(const Database& db, const std::vector<std::uint32_t>& objects) {
  std::vector<std::uint32_t> missing;
  for (std::uint32_t o : objects) {
    if (db.geometry_loaded(o)) refs_[o] = db.geometry(o);
    else missing.push_back(o);
  }
  tbb::parallel_for(std::size_t{0}, missing.size(), [&](std::size_t k) { refs_[missing[k]] = db.geometry(missing[k]); });
}

}  // namespace database
}  // namespace ts
