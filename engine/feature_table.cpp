#include "engine/feature_table.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <limits>
#include <map>
#include <mutex>

namespace ts {

namespace {

constexpr int kDim = kFeatureDim;
constexpr std::size_t kBlock = 256;          ///< rows per block (dims-major inside a block)
constexpr std::size_t kChunkBlocks = 32;     ///< blocks per parallel task (fixed: determinism)
constexpr std::size_t kSampleStride = 8;     ///< every k-th block primes the threshold

struct Item {
  float d;
  std::uint32_t row;
};
inline bool before(const Item& a, const Item& b) { return a.d < b.d || (a.d == b.d && a.row < b.row); }

/// Squared distances of one block's rows to query q (rows dims-major: blk[d * kBlock + r]).
__attribute__((target_clones("avx2", "default")))
void block_distances(const float* __restrict blk, const float* __restrict q, float* __restrict out) {
  for (std::size_t r = 0; r < kBlock; ++r) out[r] = 0.0f;
  for (int d = 0; d < kDim; ++d) {
    const float qd = q[d];
    const float* __restrict col = blk + static_cast<std::size_t>(d) * kBlock;
    for (std::size_t r = 0; r < kBlock; ++r) {
      const float e = col[r] - qd;
      out[r] += e * e;
    }
  }
}

}  // namespace

struct FeatureTable::Impl {
  std::vector<FeatureRef> refs;
  std::vector<float> blocks;   ///< nblocks x kDim x kBlock, padding rows far away
  std::size_t rows = 0;
  std::size_t nblocks() const { return (rows + kBlock - 1) / kBlock; }
  const float* block(std::size_t b) const { return blocks.data() + b * kDim * kBlock; }
};

FeatureTable::FeatureTable() : impl_(std::make_unique<Impl>()) {}
FeatureTable::~FeatureTable() = default;
FeatureTable::FeatureTable(FeatureTable&&) noexcept = default;
FeatureTable& FeatureTable::operator=(FeatureTable&&) noexcept = default;

FeatureTable::FeatureTable(const Database& db, const std::vector<std::uint8_t>& objects)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  for (std::size_t o = 0; o < db.size(); ++o) {
    if (!objects.empty() && (o >= objects.size() || !objects[o])) continue;
    const std::size_t n = db.features(o).features.size();
    for (std::size_t i = 0; i < n; ++i)
      m.refs.push_back({static_cast<std::uint32_t>(o), static_cast<std::uint32_t>(i)});
  }
  if (m.refs.size() >= std::numeric_limits<std::uint32_t>::max())
    throw Error("FeatureTable: too many features");
  m.rows = m.refs.size();
  m.blocks.assign(m.nblocks() * kDim * kBlock, 1e18f);  // padding never wins
  for (std::size_t i = 0; i < m.rows; ++i) {
    const Feature& f = db.features(m.refs[i].object).features[m.refs[i].point];
    float* blk = m.blocks.data() + (i / kBlock) * kDim * kBlock;
    for (int d = 0; d < kDim; ++d) blk[static_cast<std::size_t>(d) * kBlock + i % kBlock] = f[d];
  }
}

std::size_t FeatureTable::size() const { return impl_->rows; }
const FeatureRef& FeatureTable::ref(std::size_t i) const { return impl_->refs.at(i); }

std::vector<std::vector<Neighbour>> FeatureTable::knn(const std::vector<Feature>& queries,
                                                      std::size_t w) const {
  const Impl& m = *impl_;
  const std::size_t Q = queries.size();
  std::vector<std::vector<Neighbour>> out(Q);
  if (Q == 0 || w == 0 || m.rows == 0) return out;
  w = std::min(w, m.rows);
  const std::size_t nb = m.nblocks();

  // 1. Prime a threshold per query from every kSampleStride-th block: the value that about
  //    1.5 W rows of the whole table are expected to reach. Only a filter: if fewer than W
  //    rows pass it, that query is scanned again without it.
  std::vector<float> tau(Q, std::numeric_limits<float>::infinity());
  const std::size_t sampled_blocks = (nb + kSampleStride - 1) / kSampleStride;
  const std::size_t sampled_rows = sampled_blocks * kBlock;
  const std::size_t want = static_cast<std::size_t>(1.5 * double(w) * double(sampled_rows) / double(nb * kBlock)) + 8;
  if (nb >= 4 * kSampleStride && want < sampled_rows) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, Q, 1), [&](const tbb::blocked_range<std::size_t>& r) {
      std::vector<float> d(sampled_rows);
      for (std::size_t q = r.begin(); q != r.end(); ++q) {
        for (std::size_t s = 0; s < sampled_blocks; ++s)
          block_distances(m.block(s * kSampleStride), queries[q].data(), d.data() + s * kBlock);
        std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(want), d.end());
        tau[q] = d[want];
      }
    });
  }

  // 2. One pass over fixed chunks of blocks; every chunk keeps, per query, the rows <= tau.
  auto scan = [&](const std::vector<std::size_t>& which, const std::vector<float>& limit) {
    const std::size_t chunks = (nb + kChunkBlocks - 1) / kChunkBlocks;
    std::vector<std::vector<std::vector<Item>>> found(chunks, std::vector<std::vector<Item>>(which.size()));
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks, 1), [&](const tbb::blocked_range<std::size_t>& r) {
      float d[kBlock];
      for (std::size_t c = r.begin(); c != r.end(); ++c) {
        const std::size_t b1 = std::min(nb, (c + 1) * kChunkBlocks);
        for (std::size_t b = c * kChunkBlocks; b < b1; ++b)
          for (std::size_t j = 0; j < which.size(); ++j) {
            const std::size_t q = which[j];
            block_distances(m.block(b), queries[q].data(), d);
            const float t = limit[q];
            auto& f = found[c][j];
            for (std::size_t i = 0; i < kBlock; ++i)
              if (d[i] <= t) f.push_back({d[i], static_cast<std::uint32_t>(b * kBlock + i)});
          }
      }
    });
    // Per query, in chunk order: the w best by (distance, row).
    std::vector<std::vector<Item>> merged(which.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, which.size(), 1), [&](const tbb::blocked_range<std::size_t>& r) {
      for (std::size_t j = r.begin(); j != r.end(); ++j) {
        auto& all = merged[j];
        for (std::size_t c = 0; c < chunks; ++c) all.insert(all.end(), found[c][j].begin(), found[c][j].end());
        all.erase(std::remove_if(all.begin(), all.end(), [&](const Item& x) { return x.row >= m.rows; }), all.end());
        if (all.size() > w) {
          std::nth_element(all.begin(), all.begin() + static_cast<std::ptrdiff_t>(w - 1), all.end(), before);
          all.resize(w);
        }
        std::sort(all.begin(), all.end(), before);
      }
    });
    return merged;
  };
  std::vector<std::size_t> all_queries(Q);
  for (std::size_t q = 0; q < Q; ++q) all_queries[q] = q;
  auto merged = scan(all_queries, tau);
  std::vector<std::size_t> again;
  for (std::size_t q = 0; q < Q; ++q)
    if (merged[q].size() < w) again.push_back(q);
  if (!again.empty()) {
    std::vector<float> open(Q, std::numeric_limits<float>::infinity());
    auto second = scan(again, open);
    for (std::size_t j = 0; j < again.size(); ++j) merged[again[j]] = std::move(second[j]);
  }
  for (std::size_t q = 0; q < Q; ++q) {
    out[q].reserve(merged[q].size());
    for (const Item& x : merged[q]) out[q].push_back({x.row, static_cast<double>(x.d)});
  }
  return out;
}

std::shared_ptr<const FeatureTable> FeatureTable::shared(const Database& db,
                                                         const std::vector<std::uint8_t>& objects) {
  // Keyed by the database's address and the mask; weak, so a table lives only while used (a
  // new database at a reused address finds the old entry expired).
  static std::mutex mutex;
  static std::map<std::pair<const Database*, std::vector<std::uint8_t>>, std::weak_ptr<const FeatureTable>> cache;
  std::lock_guard<std::mutex> lock(mutex);
  auto& slot = cache[{&db, objects}];
  if (auto t = slot.lock()) return t;
  auto t = std::make_shared<const FeatureTable>(db, objects);
  slot = t;
  return t;
}

}  // namespace ts
