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
constexpr std::size_t kBlock = 128;          ///< rows per block (dims-major inside a block)
constexpr std::uint32_t kPadding = 0xffffffffu;  ///< object of a padding row

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
  std::vector<FeatureRef> refs;     ///< per table row (rows are in k-d leaf order)
  std::vector<float> blocks;        ///< nblocks x kDim x kBlock, padding rows far away
  std::vector<float> lo, hi;        ///< nblocks x kDim: bounding box of each block's rows
  std::size_t rows = 0;
  std::size_t features = 0;         ///< rows that hold a feature (rows minus padding)
  std::vector<std::uint32_t> object_blocks;  ///< first block of each object present (+ end)
  std::size_t nblocks() const { return (rows + kBlock - 1) / kBlock; }
  const float* block(std::size_t b) const { return blocks.data() + b * kDim * kBlock; }
};

FeatureTable::FeatureTable() : impl_(std::make_unique<Impl>()) {}
FeatureTable::~FeatureTable() = default;
FeatureTable::FeatureTable(FeatureTable&&) noexcept = default;
FeatureTable& FeatureTable::operator=(FeatureTable&&) noexcept = default;

namespace {

/// Order rows like the leaves of a k-d tree (split at the median of the widest dimension until
/// a piece fits a block), so that each block holds similar features and a ball around its mean
/// bounds it tightly. Deterministic (ties by row).
void kd_order(const std::vector<const Feature*>& f, std::vector<std::uint32_t>& idx, std::size_t lo,
              std::size_t hi) {
  if (hi - lo <= kBlock) return;
  int dim = 0;
  float widest = -1.0f;
  for (int d = 0; d < kDim; ++d) {
    float mn = (*f[idx[lo]])[d], mx = mn;
    for (std::size_t i = lo; i < hi; ++i) {
      mn = std::min(mn, (*f[idx[i]])[d]);
      mx = std::max(mx, (*f[idx[i]])[d]);
    }
    if (mx - mn > widest) widest = mx - mn, dim = d;
  }
  // Split on a multiple of the block size so that leaves fill whole blocks.
  const std::size_t half = lo + ((hi - lo) / 2 + kBlock - 1) / kBlock * kBlock;
  const std::size_t mid = std::min(half, hi);
  std::nth_element(idx.begin() + static_cast<std::ptrdiff_t>(lo), idx.begin() + static_cast<std::ptrdiff_t>(mid),
                   idx.begin() + static_cast<std::ptrdiff_t>(hi), [&](std::uint32_t a, std::uint32_t b) {
                     const float va = (*f[a])[dim], vb = (*f[b])[dim];
                     return va < vb || (va == vb && a < b);
                   });
  kd_order(f, idx, lo, mid);
  kd_order(f, idx, mid, hi);
}

}  // namespace

FeatureTable::FeatureTable(const Database& db, const std::vector<std::uint8_t>& objects)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  // Each object's rows in k-d leaf order, starting on a block boundary (padding rows between
  // objects), so that a block belongs to one object: knn_per_object searches an object's blocks
  // best-first like knn searches all of them.
  std::vector<FeatureRef> refs;
  std::vector<const Feature*> feats;
  for (std::size_t o = 0; o < db.size(); ++o) {
    if (!objects.empty() && (o >= objects.size() || !objects[o])) continue;
    const auto& fs = db.features(o).features;
    if (fs.empty()) continue;
    std::vector<const Feature*> of(fs.size());
    std::vector<std::uint32_t> idx(fs.size());
    for (std::size_t i = 0; i < fs.size(); ++i) of[i] = &fs[i], idx[i] = static_cast<std::uint32_t>(i);
    kd_order(of, idx, 0, idx.size());
    m.object_blocks.push_back(static_cast<std::uint32_t>(refs.size() / kBlock));
    for (std::uint32_t i : idx) {
      refs.push_back({static_cast<std::uint32_t>(o), i});
      feats.push_back(of[i]);
    }
    while (refs.size() % kBlock != 0) {
      refs.push_back({kPadding, kPadding});
      feats.push_back(nullptr);
    }
    m.features += fs.size();
  }
  m.object_blocks.push_back(static_cast<std::uint32_t>(refs.size() / kBlock));
  if (refs.size() >= std::numeric_limits<std::uint32_t>::max())
    throw Error("FeatureTable: too many features");
  m.rows = refs.size();
  const std::size_t nb = m.nblocks();
  m.refs = std::move(refs);
  m.blocks.assign(nb * kDim * kBlock, 1e18f);  // padding never wins
  m.lo.assign(nb * kDim, std::numeric_limits<float>::infinity());
  m.hi.assign(nb * kDim, -std::numeric_limits<float>::infinity());
  for (std::size_t r = 0; r < m.rows; ++r) {
    if (!feats[r]) continue;
    const Feature& f = *feats[r];
    const std::size_t b = r / kBlock;
    float* blk = m.blocks.data() + b * kDim * kBlock;
    for (int d = 0; d < kDim; ++d) {
      blk[static_cast<std::size_t>(d) * kBlock + r % kBlock] = f[d];
      m.lo[b * kDim + d] = std::min(m.lo[b * kDim + d], f[d]);
      m.hi[b * kDim + d] = std::max(m.hi[b * kDim + d], f[d]);
    }
  }
}

std::size_t FeatureTable::size() const { return impl_->rows; }
std::size_t FeatureTable::features() const { return impl_->features; }
const FeatureRef& FeatureTable::ref(std::size_t i) const { return impl_->refs.at(i); }

namespace {

/// The w nearest feature rows among blocks [b0, b1) to query qv, appended to `out` sorted by
/// (distance, row). Best-first over the blocks by the lower bound (distance to the block's
/// bounding box); stops when the bound exceeds the w-th distance found so far. Exact: a skipped
/// block's rows are all farther than w rows already found.
void search_blocks(const FeatureTable::Impl& m, const float* qv, std::size_t b0, std::size_t b1,
                   std::size_t w, std::vector<std::pair<float, std::uint32_t>>& order,
                   std::vector<Item>& cand, std::vector<Neighbour>& out) {
  order.clear();
  for (std::size_t b = b0; b < b1; ++b) {
    // squared distance from q to the block's bounding box, slightly shrunk (a float row
    // distance is never below it)
    double s2 = 0.0;
    for (int k = 0; k < kDim; ++k) {
      const double x = qv[k], l = m.lo[b * kDim + k], h = m.hi[b * kDim + k];
      const double e = x < l ? l - x : (x > h ? x - h : 0.0);
      s2 += e * e;
    }
    order.push_back({static_cast<float>(s2 * (1.0 - 1e-5)), static_cast<std::uint32_t>(b)});
  }
  std::sort(order.begin(), order.end());
  cand.clear();
  float tau = std::numeric_limits<float>::infinity();
  float d[kBlock];
  for (const auto& [lb, b] : order) {
    if (lb > tau) break;
    block_distances(m.block(b), qv, d);
    const std::size_t base = std::size_t{b} * kBlock;
    for (std::size_t i = 0; i < kBlock; ++i)
      if (d[i] <= tau && m.refs[base + i].object != kPadding)
        cand.push_back({d[i], static_cast<std::uint32_t>(base + i)});
    if (cand.size() >= 2 * w) {
      std::nth_element(cand.begin(), cand.begin() + static_cast<std::ptrdiff_t>(w - 1), cand.end(), before);
      cand.resize(w);
      tau = cand[w - 1].d;
      for (const Item& x : cand) tau = std::max(tau, x.d);
    }
  }
  if (cand.size() > w) {
    std::nth_element(cand.begin(), cand.begin() + static_cast<std::ptrdiff_t>(w - 1), cand.end(), before);
    cand.resize(w);
  }
  std::sort(cand.begin(), cand.end(), before);
  for (const Item& x : cand) out.push_back({x.row, static_cast<double>(x.d)});
}

}  // namespace

namespace {

/// Per query, the w nearest rows within each block range, ranges in order. Parallel over queries.
std::vector<std::vector<Neighbour>> search_ranges(
    const FeatureTable::Impl& m, const std::vector<Feature>& queries, std::size_t w,
    const std::vector<std::pair<std::size_t, std::size_t>>& ranges) {
  std::vector<std::vector<Neighbour>> out(queries.size());
  if (queries.empty() || w == 0 || m.features == 0) return out;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, queries.size(), 1), [&](const tbb::blocked_range<std::size_t>& range) {
    std::vector<std::pair<float, std::uint32_t>> order;
    std::vector<Item> cand;
    for (std::size_t q = range.begin(); q != range.end(); ++q) {
      out[q].reserve(w * ranges.size());
      for (const auto& [b0, b1] : ranges) search_blocks(m, queries[q].data(), b0, b1, w, order, cand, out[q]);
    }
  });
  return out;
}

}  // namespace

std::vector<std::vector<Neighbour>> FeatureTable::knn(const std::vector<Feature>& queries,
                                                      std::size_t w) const {
  const Impl& m = *impl_;
  return search_ranges(m, queries, std::min(w, m.features), {{0, m.nblocks()}});
}

std::vector<std::vector<Neighbour>> FeatureTable::knn_per_object(const std::vector<Feature>& queries,
                                                                 std::size_t w) const {
  const Impl& m = *impl_;
  std::vector<std::pair<std::size_t, std::size_t>> ranges;
  for (std::size_t g = 0; g + 1 < m.object_blocks.size(); ++g)
    ranges.emplace_back(m.object_blocks[g], m.object_blocks[g + 1]);
  return search_ranges(m, queries, w, ranges);
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
