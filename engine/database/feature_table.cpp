#include "engine/database/feature_table.hpp"
#include "engine/target_clones.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <bit>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

namespace ts {
inline namespace database {

namespace {

constexpr std::size_t kBlock = 128;          ///< rows per block (dims-major inside a block)
constexpr std::uint32_t kPadding = 0xffffffffu;  ///< object of a padding row

/// A candidate row as one integer key: the bits of its squared distance (a non-negative float,
/// whose bit patterns order like its values) above the row, so that the integer order is the
/// order by (distance, row) and the selections below compare plain integers instead of calling
/// a comparison function through a pointer.
using Item = std::uint64_t;
inline Item item(float d, std::uint32_t row) {
  return (static_cast<std::uint64_t>(std::bit_cast<std::uint32_t>(d)) << 32) | row;
}
inline float item_distance(Item x) { return std::bit_cast<float>(static_cast<std::uint32_t>(x >> 32)); }
inline std::uint32_t item_row(Item x) { return static_cast<std::uint32_t>(x); }

/// Squared distances of one block's rows to query q of `dim` values (rows dims-major:
/// blk[d * kBlock + r]).
TS_TARGET_CLONES
void block_distances(const float* __restrict blk, const float* __restrict q, int dim, float* __restrict out) {
  for (std::size_t r = 0; r < kBlock; ++r) out[r] = 0.0f;
  for (int d = 0; d < dim; ++d) {
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
  int dim = kFeatureDim;            ///< values per feature (the database's descriptor)
  std::vector<FeatureRef> refs;     ///< per table row (rows are in k-d leaf order)
  std::vector<float> blocks;        ///< nblocks x dim x kBlock, padding rows far away
  std::vector<float> lo, hi;        ///< nblocks x dim: bounding box of each block's rows
  std::vector<float> centre;        ///< nblocks x dim: mean of each block's rows
  std::vector<std::uint8_t> filled; ///< per block: rows that hold a feature (the first ones)
  std::size_t rows = 0;
  std::size_t features = 0;         ///< rows that hold a feature (rows minus padding)
  std::vector<std::uint32_t> object_blocks;  ///< first block of each object present (+ end)
  std::size_t nblocks() const { return (rows + kBlock - 1) / kBlock; }
  std::size_t stride() const { return static_cast<std::size_t>(dim); }
  const float* block(std::size_t b) const { return blocks.data() + b * stride() * kBlock; }
};

FeatureTable::FeatureTable() : impl_(std::make_unique<Impl>()) {}
FeatureTable::~FeatureTable() = default;
FeatureTable::FeatureTable(FeatureTable&&) noexcept = default;
FeatureTable& FeatureTable::operator=(FeatureTable&&) noexcept = default;

namespace {

/// Order rows like the leaves of a k-d tree (split at the median of the widest dimension until
/// a piece fits a block), so that each block holds similar features and a ball around its mean
/// bounds it tightly. Deterministic (ties by row).
void kd_order(const FeatureRows& f, std::vector<std::uint32_t>& idx, std::size_t lo, std::size_t hi) {
  if (hi - lo <= kBlock) return;
  // Each dimension's range, row by row (one pass over the rows, each read whole).
  const int dims = f.dim();
  std::vector<float> mn(f.row(idx[lo]), f.row(idx[lo]) + dims), mx = mn;
  for (std::size_t i = lo + 1; i < hi; ++i) {
    const float* r = f.row(idx[i]);
    for (int d = 0; d < dims; ++d) {
      mn[d] = std::min(mn[d], r[d]);
      mx[d] = std::max(mx[d], r[d]);
    }
  }
  int dim = 0;
  float widest = -1.0f;
  for (int d = 0; d < dims; ++d)
    if (mx[d] - mn[d] > widest) widest = mx[d] - mn[d], dim = d;
  // Split on a multiple of the block size so that leaves fill whole blocks.
  const std::size_t half = lo + ((hi - lo) / 2 + kBlock - 1) / kBlock * kBlock;
  const std::size_t mid = std::min(half, hi);
  std::nth_element(idx.begin() + static_cast<std::ptrdiff_t>(lo), idx.begin() + static_cast<std::ptrdiff_t>(mid),
                   idx.begin() + static_cast<std::ptrdiff_t>(hi), [&](std::uint32_t a, std::uint32_t b) {
                     const float va = f.row(a)[dim], vb = f.row(b)[dim];
                     return va < vb || (va == vb && a < b);
                   });
  kd_order(f, idx, lo, mid);
  kd_order(f, idx, mid, hi);
}

}  // namespace

FeatureTable::FeatureTable(const Database& db, const std::vector<std::uint8_t>& objects)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.dim = descriptor_dim(db.settings().descriptor);
  const std::size_t dim = m.stride();
  // Each object's rows in k-d leaf order, starting on a block boundary (padding rows between
  // objects), so that a block belongs to one object: knn_per_object searches an object's blocks
  // best-first like knn searches all of them. The table keeps the only copy of the features
  // (a few objects' worth in flight while it is built).
  std::size_t expected = 0;  // blocks, from the summaries (a reservation, not trusted)
  for (std::size_t o = 0; o < db.size(); ++o)
    if (objects.empty() || (o < objects.size() && objects[o]))
      expected += (std::min<std::size_t>(db.info(o).coarse_points, 1u << 24) + kBlock - 1) / kBlock;
  // At most 4 GiB of values reserved (address space, not touched): the summaries come from the
  // file and are checked only when an object's rows are loaded.
  expected = std::min<std::size_t>(expected, (std::size_t{1} << 30) / (dim * kBlock));
  m.blocks.reserve(expected * dim * kBlock);
  m.refs.reserve(expected * kBlock);
  struct Loaded {
    std::size_t o = 0;
    FeatureRows fs;
    std::vector<std::uint32_t> idx;
  };
  auto append = [&](const Loaded& L) {
    const std::size_t o = L.o;
    const FeatureRows& fs = L.fs;
    const std::vector<std::uint32_t>& idx = L.idx;
    if (fs.empty()) return;
    const std::size_t b0 = m.refs.size() / kBlock, nb = (fs.size() + kBlock - 1) / kBlock;
    if ((b0 + nb) * kBlock >= std::numeric_limits<std::uint32_t>::max())
      throw Error("FeatureTable: too many features");
    m.object_blocks.push_back(static_cast<std::uint32_t>(b0));
    m.blocks.resize((b0 + nb) * dim * kBlock, 1e18f);  // padding never wins
    m.lo.resize((b0 + nb) * dim, std::numeric_limits<float>::infinity());
    m.hi.resize((b0 + nb) * dim, -std::numeric_limits<float>::infinity());
    m.centre.resize((b0 + nb) * dim, 0.0f);
    m.filled.resize(b0 + nb, 0);
    for (std::size_t k = 0; k < nb * kBlock; ++k) {
      if (k >= idx.size()) {
        m.refs.push_back({kPadding, kPadding});
        continue;
      }
      m.refs.push_back({static_cast<std::uint32_t>(o), idx[k]});
      const float* f = fs.row(idx[k]);
      const std::size_t b = b0 + k / kBlock;
      float* blk = m.blocks.data() + b * dim * kBlock;
      for (std::size_t d = 0; d < dim; ++d) {
        blk[d * kBlock + k % kBlock] = f[d];
        m.lo[b * dim + d] = std::min(m.lo[b * dim + d], f[d]);
        m.hi[b * dim + d] = std::max(m.hi[b * dim + d], f[d]);
      }
    }
    for (std::size_t j = 0; j < nb; ++j) {  // block means, summed in double in row order
      const std::size_t b = b0 + j, rows = std::min(kBlock, fs.size() - j * kBlock);
      m.filled[b] = static_cast<std::uint8_t>(rows);
      for (std::size_t d = 0; d < dim; ++d) {
        double sum = 0.0;
        for (std::size_t r = 0; r < rows; ++r) sum += m.blocks[b * dim * kBlock + d * kBlock + r];
        m.centre[b * dim + d] = static_cast<float>(sum / double(rows));
      }
    }
    m.features += fs.size();
  };
  // Objects are read and k-d ordered in parallel, appended in order: the same table for any
  // thread count, with a few objects in flight at a time.
  std::size_t next = 0;
  const auto tokens = static_cast<std::size_t>(2 * std::max(1, tbb::this_task_arena::max_concurrency()));
  tbb::parallel_pipeline(
      tokens,
      tbb::make_filter<void, std::shared_ptr<Loaded>>(
          tbb::filter_mode::serial_in_order,
          [&](tbb::flow_control& fc) -> std::shared_ptr<Loaded> {
            while (next < db.size() && !objects.empty() && (next >= objects.size() || !objects[next])) ++next;
            if (next >= db.size()) {
              fc.stop();
              return nullptr;
            }
            auto L = std::make_shared<Loaded>();
            L->o = next++;
            return L;
          }) &
          tbb::make_filter<std::shared_ptr<Loaded>, std::shared_ptr<Loaded>>(
              tbb::filter_mode::parallel,
              [&db, dim](std::shared_ptr<Loaded> L) {
                L->fs = db.load_features(L->o).features;  // the reads take turns, inflating does not
                if (L->fs.dim() != static_cast<int>(dim) && !L->fs.empty())
                  throw Error("FeatureTable: object " + db.info(L->o).name + " has features of " +
                              std::to_string(L->fs.dim()) + " values, the database's descriptor " +
                              std::to_string(dim));
                L->idx.resize(L->fs.size());
                for (std::size_t i = 0; i < L->fs.size(); ++i) L->idx[i] = static_cast<std::uint32_t>(i);
                kd_order(L->fs, L->idx, 0, L->idx.size());
                return L;
              }) &
          tbb::make_filter<std::shared_ptr<Loaded>, void>(tbb::filter_mode::serial_in_order,
                                                          [&](std::shared_ptr<Loaded> L) { append(*L); }));
  m.object_blocks.push_back(static_cast<std::uint32_t>(m.refs.size() / kBlock));
  m.rows = m.refs.size();
  m.blocks.shrink_to_fit();
  m.refs.shrink_to_fit();
}

std::size_t FeatureTable::size() const { return impl_->rows; }
std::size_t FeatureTable::features() const { return impl_->features; }
int FeatureTable::dim() const { return impl_->dim; }
const FeatureRef& FeatureTable::ref(std::size_t i) const { return impl_->refs.at(i); }

namespace {

/// Squared distance from query qv to block b's bounding box, shrunk by 1e-5 so that it never
/// exceeds a row's distance as block_distances computes it in float (either sum of 33 squares
/// is within about 4e-6 of the exact one, relatively; the margin grows with the dimension, as
/// the rounding of a longer sum does).
TS_TARGET_CLONES
float block_bound(const float* __restrict lo, const float* __restrict hi, const float* __restrict qv, int dim) {
  float s2 = 0.0f;
  for (int k = 0; k < dim; ++k) {
    const float e = std::max(std::max(lo[k] - qv[k], qv[k] - hi[k]), 0.0f);
    s2 += e * e;
  }
  return s2 * (1.0f - 1e-5f * std::max(1.0f, static_cast<float>(dim) / 33.0f));
}

inline float block_bound(const FeatureTable::Impl& m, const float* qv, std::size_t b) {
  return block_bound(&m.lo[b * m.stride()], &m.hi[b * m.stride()], qv, m.dim);
}

/// Squared distance from query qv to the mean of block b's rows.
inline float centre_distance(const FeatureTable::Impl& m, const float* qv, std::size_t b) {
  float s2 = 0.0f;
  const float* c = &m.centre[b * m.stride()];
  for (int k = 0; k < m.dim; ++k) s2 += (qv[k] - c[k]) * (qv[k] - c[k]);
  return s2;
}

/// The w nearest feature rows among the blocks `blocks` to query qv, appended to `out` sorted
/// by (distance, row). Exact (max_blocks = 0): best-first over the blocks by the lower bound
/// (distance to the block's bounding box); stops when the bound exceeds the w-th distance found
/// so far, so a skipped block's rows are all farther than w rows already found. Approximate
/// (max_blocks > 0): only the max_blocks blocks whose mean is nearest to the query are read
/// (an inverted file whose cells are the k-d leaves), the rest are left out.
template <class Blocks>
void search_blocks(const FeatureTable::Impl& m, const float* qv, const Blocks& blocks,
                   std::size_t w, std::size_t max_blocks,
                   std::vector<std::pair<float, std::uint32_t>>& order,
                   std::vector<Item>& cand, std::vector<Neighbour>& out) {
  order.clear();
  if (max_blocks == 0) {
    for (const std::size_t b : blocks) order.push_back({block_bound(m, qv, b), static_cast<std::uint32_t>(b)});
    std::sort(order.begin(), order.end());
  } else {
    for (const std::size_t b : blocks) order.push_back({centre_distance(m, qv, b), static_cast<std::uint32_t>(b)});
    if (order.size() > max_blocks) {
      std::nth_element(order.begin(), order.begin() + static_cast<std::ptrdiff_t>(max_blocks - 1), order.end());
      order.resize(max_blocks);
    }
  }
  if (w == 0) return;
  // cand[0, nc): the rows in hand. Before a block is read nc < 2w, so 2w + kBlock slots hold it.
  if (cand.size() < 2 * w + kBlock) cand.resize(2 * w + kBlock);
  Item* const c = cand.data();
  std::size_t nc = 0;
  float tau = std::numeric_limits<float>::infinity();
  float d[kBlock];
  for (const auto& [lb, b] : order) {
    if (max_blocks == 0 && lb > tau) break;
    block_distances(m.block(b), qv, m.dim, d);
    const std::size_t base = std::size_t{b} * kBlock, filled = m.filled[b];
    const bool unbounded = tau == std::numeric_limits<float>::infinity();
    // Branch-free: every row is written, and only those within tau are kept.
    for (std::size_t i = 0; i < filled; ++i) {
      c[nc] = item(d[i], static_cast<std::uint32_t>(base + i));
      nc += static_cast<std::size_t>(d[i] <= tau);
    }
    // The first time w rows are in hand, tau (the w-th distance) starts to skip rows and blocks.
    if (nc >= 2 * w || (unbounded && nc >= w)) {
      std::nth_element(c, c + (w - 1), c + nc);
      nc = w;
      tau = item_distance(c[w - 1]);
    }
  }
  if (nc > w) {
    std::nth_element(c, c + (w - 1), c + nc);
    nc = w;
  }
  std::sort(c, c + nc);
  for (std::size_t k = 0; k < nc; ++k) out.push_back({item_row(c[k]), static_cast<double>(item_distance(c[k]))});
}

/// A contiguous run of blocks, iterable as block indices.
struct BlockRange {
  std::size_t b0 = 0, b1 = 0;
  struct It {
    std::size_t b;
    std::size_t operator*() const { return b; }
    It& operator++() { return ++b, *this; }
    bool operator!=(const It& o) const { return b != o.b; }
  };
  It begin() const { return {b0}; }
  It end() const { return {b1}; }
};

/// The block ranges of the objects in the mask (every object's for an empty mask), in order.
std::vector<BlockRange> object_ranges(const FeatureTable::Impl& m, const std::vector<std::uint8_t>& mask) {
  std::vector<BlockRange> ranges;
  for (std::size_t g = 0; g + 1 < m.object_blocks.size(); ++g) {
    const std::uint32_t o = m.refs[std::size_t{m.object_blocks[g]} * kBlock].object;
    if (!mask.empty() && (o >= mask.size() || !mask[o])) continue;
    ranges.push_back({m.object_blocks[g], m.object_blocks[g + 1]});
  }
  return ranges;
}

/// Per query, the w nearest rows over all the ranges' blocks together. Parallel over queries.
std::vector<std::vector<Neighbour>> search_ranges(const FeatureTable::Impl& m,
                                                  const FeatureRows& queries, std::size_t w,
                                                  const std::vector<BlockRange>& ranges) {
  std::vector<std::vector<Neighbour>> out(queries.size());
  if (queries.empty() || w == 0 || m.features == 0 || ranges.empty()) return out;
  std::vector<std::size_t> all;
  for (const BlockRange& r : ranges)
    for (std::size_t b : r) all.push_back(b);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, queries.size(), 1), [&](const tbb::blocked_range<std::size_t>& range) {
    std::vector<std::pair<float, std::uint32_t>> order;
    std::vector<Item> cand;
    for (std::size_t q = range.begin(); q != range.end(); ++q) {
      out[q].reserve(w);
      search_blocks(m, queries.row(q), all, w, 0, order, cand, out[q]);
    }
  });
  return out;
}

}  // namespace

namespace {
void check_queries(const FeatureTable::Impl& m, const FeatureRows& queries) {
  if (queries.dim() != m.dim && !queries.empty())
    throw Error("FeatureTable: queries of " + std::to_string(queries.dim()) + " values, the table's features " +
                std::to_string(m.dim));
}
}  // namespace

std::vector<std::vector<Neighbour>> FeatureTable::knn(const FeatureRows& queries, std::size_t w) const {
  const Impl& m = *impl_;
  check_queries(m, queries);
  return search_ranges(m, queries, std::min(w, m.features), object_ranges(m, {}));
}

std::vector<std::vector<Neighbour>> FeatureTable::knn_per_object(const FeatureRows& queries,
                                                                 std::size_t w) const {
  return knn_per_object(queries, w, std::vector<std::uint8_t>{});
}

std::vector<std::vector<Neighbour>> FeatureTable::knn_per_object(const FeatureRows& queries,
                                                                 std::size_t w,
                                                                 const std::vector<std::uint8_t>& mask,
                                                                 std::size_t max_blocks) const {
  return knn_per_object(queries, w, std::vector<std::vector<std::uint8_t>>(queries.size(), mask), max_blocks);
}

std::vector<std::vector<Neighbour>> FeatureTable::knn_per_object(
    const FeatureRows& queries, std::size_t w,
    const std::vector<std::vector<std::uint8_t>>& masks, std::size_t max_blocks) const {
  const Impl& m = *impl_;
  check_queries(m, queries);
  if (masks.size() != queries.size()) throw Error("FeatureTable: one mask per query expected");
  std::vector<std::vector<Neighbour>> out(queries.size());
  if (w == 0 || m.features == 0) return out;
  // Object-major: the (query, object) searches are grouped by object, and one task runs all of
  // an object's searches, so its blocks are read from memory once and then from cache (query-
  // major, a step of a large database re-read every searched object's blocks for each query).
  // Each search writes its own slot; the slots are concatenated per query, objects ascending.
  const std::vector<BlockRange> all = object_ranges(m, {});
  std::vector<std::uint32_t> object_of(all.size());
  for (std::size_t g = 0; g < all.size(); ++g) object_of[g] = m.refs[all[g].b0 * kBlock].object;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> pairs;  // (query, group), query-major
  std::vector<std::size_t> first(queries.size() + 1, 0);        // pairs of query q: [first[q], first[q+1])
  for (std::size_t q = 0; q < queries.size(); ++q) {
    first[q] = pairs.size();
    const std::vector<std::uint8_t>& mask = masks[q];
    for (std::size_t g = 0; g < all.size(); ++g)
      if (mask.empty() || (object_of[g] < mask.size() && mask[object_of[g]]))
        pairs.push_back({static_cast<std::uint32_t>(q), static_cast<std::uint32_t>(g)});
  }
  first[queries.size()] = pairs.size();
  std::vector<std::vector<std::uint32_t>> by_group(all.size());
  for (std::size_t p = 0; p < pairs.size(); ++p) by_group[pairs[p].second].push_back(static_cast<std::uint32_t>(p));
  std::vector<std::uint32_t> busy;
  for (std::size_t g = 0; g < all.size(); ++g)
    if (!by_group[g].empty()) busy.push_back(static_cast<std::uint32_t>(g));
  std::vector<std::vector<Neighbour>> slot(pairs.size());
  auto search = [&](std::size_t p, std::vector<std::pair<float, std::uint32_t>>& order, std::vector<Item>& cand) {
    slot[p].reserve(w);
    search_blocks(m, queries.row(pairs[p].first), all[pairs[p].second], w, max_blocks, order, cand, slot[p]);
  };
  const auto threads = static_cast<std::size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
  if (busy.size() >= 4 * threads) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, busy.size(), 1), [&](const tbb::blocked_range<std::size_t>& range) {
      std::vector<std::pair<float, std::uint32_t>> order;
      std::vector<Item> cand;
      for (std::size_t k = range.begin(); k != range.end(); ++k)
        for (const std::uint32_t p : by_group[busy[k]]) search(p, order, cand);
    });
  } else {  // too few objects to keep the threads busy: each search its own task
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pairs.size(), 1), [&](const tbb::blocked_range<std::size_t>& range) {
      std::vector<std::pair<float, std::uint32_t>> order;
      std::vector<Item> cand;
      for (std::size_t p = range.begin(); p != range.end(); ++p) search(p, order, cand);
    });
  }
  tbb::parallel_for(std::size_t{0}, queries.size(), [&](std::size_t q) {
    std::size_t n = 0;
    for (std::size_t p = first[q]; p < first[q + 1]; ++p) n += slot[p].size();
    out[q].reserve(n);
    for (std::size_t p = first[q]; p < first[q + 1]; ++p) out[q].insert(out[q].end(), slot[p].begin(), slot[p].end());
  });
  return out;
}

std::size_t FeatureTable::memory_bytes() const {
  const Impl& m = *impl_;
  return m.blocks.size() * sizeof(float) + (m.lo.size() + m.hi.size() + m.centre.size()) * sizeof(float) +
         m.refs.size() * sizeof(FeatureRef) + m.filled.size() +
         m.object_blocks.size() * sizeof(std::uint32_t);
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

}  // namespace database
}  // namespace ts
