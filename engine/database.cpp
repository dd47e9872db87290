#include "engine/database.hpp"

namespace ts {

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
  std::once_flag features_once, geometry_once;
  std::unique_ptr<ObjectFeatures> features;
  std::unique_ptr<ObjectGeometry> geometry;
  std::atomic<bool> geometry_ready{false};
};

Database::Database(std::shared_ptr<const ObjectSource> source)
    : source_(std::move(source)), slots_(new Slot[source_->size()]) {}

Database::~Database() = default;

std::size_t Database::size() const { return source_->size(); }
const ObjectInfo& Database::info(std::size_t i) const { return source_->info(i); }
const DatabaseSettings& Database::settings() const { return source_->settings(); }

std::size_t Database::find(const std::string& name) const {
  for (std::size_t i = 0; i < size(); ++i)
    if (info(i).name == name) return i;
  return size();
}

const ObjectFeatures& Database::features(std::size_t i) const {
  Slot& s = slots_[i];
  std::call_once(s.features_once, [&] {
    s.features = std::make_unique<ObjectFeatures>(source_->load_features(i));
  });
  return *s.features;
}

const ObjectGeometry& Database::geometry(std::size_t i) const {
  Slot& s = slots_[i];
  std::call_once(s.geometry_once, [&] {
    auto g = std::make_unique<ObjectGeometry>();
    g->fine = source_->load_fine(i);
    g->tree = KdTree3(g->fine.points);
    g->field = source_->load_field(i);
    s.geometry = std::move(g);
    s.geometry_ready.store(true, std::memory_order_release);
  });
  return *s.geometry;
}

bool Database::geometry_loaded(std::size_t i) const {
  return slots_[i].geometry_ready.load(std::memory_order_acquire);
}

std::size_t Database::geometry_loads() const {
  std::size_t n = 0;
  for (std::size_t i = 0; i < size(); ++i) n += geometry_loaded(i) ? 1 : 0;
  return n;
}

}  // namespace ts
