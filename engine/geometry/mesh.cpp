// Triangle-mesh measurements and the MeshIndex BVH (binned-SAH build, flat depth-first node
// array, stack traversal). Queries never mutate the index, so they are thread-safe.
#include "engine/geometry/mesh.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <unordered_map>

namespace ts {

// ---------------------------------------------------------------------------------------------
// Measurements
// ---------------------------------------------------------------------------------------------

namespace {

bool face_valid(const Mesh& mesh, const Eigen::Vector3i& f) {
  const auto n = static_cast<int>(mesh.vertices.size());
  return f[0] >= 0 && f[1] >= 0 && f[2] >= 0 && f[0] < n && f[1] < n && f[2] < n;
}

}  // namespace

double mesh_area(const Mesh& mesh) {
  double area = 0.0;
  for (const auto& f : mesh.faces) {
    if (!face_valid(mesh, f)) continue;
    const Vec3& a = mesh.vertices[f[0]];
    area += 0.5 * (mesh.vertices[f[1]] - a).cross(mesh.vertices[f[2]] - a).norm();
  }
  return area;
}

double mesh_signed_volume(const Mesh& mesh) {
  // Divergence theorem: sum of signed tetrahedra (c, a, b, d) / 6, with the apex c at the
  // bounding-box centre so that far-from-origin meshes keep their precision.
  if (mesh.vertices.empty()) return 0.0;
  const Vec3 c = mesh_bounds(mesh).center();
  double six_v = 0.0;
  for (const auto& f : mesh.faces) {
    if (!face_valid(mesh, f)) continue;
    const Vec3 a = mesh.vertices[f[0]] - c;
    const Vec3 b = mesh.vertices[f[1]] - c;
    const Vec3 d = mesh.vertices[f[2]] - c;
    six_v += a.dot(b.cross(d));
  }
  return six_v / 6.0;
}

Eigen::AlignedBox3d mesh_bounds(const Mesh& mesh) {
  Eigen::AlignedBox3d box;  // empty
  for (const auto& v : mesh.vertices) box.extend(v);
  return box;
}

MeshTopology mesh_topology(const Mesh& mesh) {
  // Undirected edge -> number of faces using it. Degenerate faces (a repeated vertex) and
  // faces with out-of-range indices are ignored.
  std::unordered_map<std::uint64_t, std::uint32_t> uses;
  uses.reserve(mesh.faces.size() * 2);
  for (const auto& f : mesh.faces) {
    if (!face_valid(mesh, f) || f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) continue;
    for (int e = 0; e < 3; ++e) {
      auto a = static_cast<std::uint64_t>(f[e]), b = static_cast<std::uint64_t>(f[(e + 1) % 3]);
      if (a > b) std::swap(a, b);
      ++uses[(a << 32) | b];
    }
  }
  MeshTopology topo;
  for (const auto& [edge, n] : uses) {
    if (n == 1) ++topo.boundary_edges;
    if (n > 2) ++topo.nonmanifold_edges;
  }
  return topo;
}

// ---------------------------------------------------------------------------------------------
// MeshIndex
// ---------------------------------------------------------------------------------------------

namespace {

constexpr int kLeafSize = 4;     // triangles per leaf at most (unless they cannot be split)
constexpr int kBins = 16;        // SAH bins per axis
constexpr int kMaxDepth = 60;    // the traversal stacks hold kMaxDepth + 2 entries
constexpr int kStackSize = 2 * kMaxDepth + 4;

constexpr double kInf() { return std::numeric_limits<double>::infinity(); }

struct Node {
  Vec3 lo, hi;
  std::int32_t start = 0;  ///< leaf: first triangle; inner: index of the right child
  std::int32_t count = 0;  ///< leaf: number of triangles (> 0); inner: 0 (left child = this + 1)
};

/// A node as the closest-point search reads it: the box in floats rounded outward (it holds the
/// exact box, so pruning stays conservative), 32 bytes instead of 56.
struct SearchNode {
  float lo[3], hi[3];
  std::int32_t start = 0;  ///< as Node
  std::int32_t count = 0;
};

/// Squared distance from p to a search node's box (0 inside); never more than box_sq_distance
/// of the node it was made from.
inline double box_sq_distance(const SearchNode& n, const Vec3& p) {
  double d2 = 0.0;
  for (int k = 0; k < 3; ++k) {
    const double e = std::max({double(n.lo[k]) - p[k], 0.0, p[k] - double(n.hi[k])});
    d2 += e * e;
  }
  return d2;
}

SearchNode search_node(const Node& n) {
  SearchNode s;
  for (int k = 0; k < 3; ++k) {
    s.lo[k] = static_cast<float>(n.lo[k]);
    if (double(s.lo[k]) > n.lo[k]) s.lo[k] = std::nextafter(s.lo[k], -std::numeric_limits<float>::infinity());
    s.hi[k] = static_cast<float>(n.hi[k]);
    if (double(s.hi[k]) < n.hi[k]) s.hi[k] = std::nextafter(s.hi[k], std::numeric_limits<float>::infinity());
  }
  s.start = n.start;
  s.count = n.count;
  return s;
}

/// One triangle in leaf order, with what the queries need precomputed.
struct Tri {
  Vec3 a, e1, e2;   ///< vertex a and edges b - a, c - a
  Vec3 normal;      ///< unit geometric normal as wound (zero for degenerate triangles)
  int face;         ///< index into mesh.faces
};

/// Möller–Trumbore (1997) with a small barycentric tolerance, so a ray through an edge shared
/// by two triangles hits at least one of them. Returns t along the unit direction, or +inf.
inline double intersect(const Tri& tri, const Vec3& o, const Vec3& d, double eps) {
  const Vec3 p = d.cross(tri.e2);
  const double det = tri.e1.dot(p);
  // Parallel to the plane (or degenerate): relative test against the edge lengths.
  if (!(std::abs(det) > 1e-14 * tri.e1.norm() * tri.e2.norm())) return kInf();
  const double inv = 1.0 / det;
  const Vec3 s = o - tri.a;
  const double u = s.dot(p) * inv;
  if (u < -eps || u > 1.0 + eps) return kInf();
  const Vec3 q = s.cross(tri.e1);
  const double v = d.dot(q) * inv;
  if (v < -eps || u + v > 1.0 + eps) return kInf();
  return tri.e2.dot(q) * inv;
}

/// Closest point on triangle (a, a+e1, a+e2) to p: Ericson, Real-Time Collision Detection, 5.1.5.
inline Vec3 closest_on_triangle(const Vec3& p, const Tri& tri) {
  const Vec3& a = tri.a;
  const Vec3 b = a + tri.e1, c = a + tri.e2;
  const Vec3& ab = tri.e1;
  const Vec3& ac = tri.e2;
  const Vec3 ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    const double denom = d1 - d3;
    return denom > 0.0 ? Vec3(a + (d1 / denom) * ab) : a;
  }
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    const double denom = d2 - d6;
    return denom > 0.0 ? Vec3(a + (d2 / denom) * ac) : a;
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    const double denom = (d4 - d3) + (d5 - d6);
    return denom > 0.0 ? Vec3(b + ((d4 - d3) / denom) * (c - b)) : b;
  }
  const double sum = va + vb + vc;
  if (!(sum > 0.0)) return a;  // degenerate triangle
  const double inv = 1.0 / sum;
  return a + ab * (vb * inv) + ac * (vc * inv);
}

/// Squared distance from p to a box (0 inside).
inline double box_sq_distance(const Node& n, const Vec3& p) {
  double d2 = 0.0;
  for (int k = 0; k < 3; ++k) {
    const double e = std::max({n.lo[k] - p[k], 0.0, p[k] - n.hi[k]});
    d2 += e * e;
  }
  return d2;
}

struct Ray {
  Vec3 o, d, inv;
};

/// Slab test: entry distance of the ray into the box, or +inf when it misses (t in [t0, t1]).
inline double box_entry(const Node& n, const Ray& r, double t0, double t1) {
  for (int k = 0; k < 3; ++k) {
    double ta = (n.lo[k] - r.o[k]) * r.inv[k];
    double tb = (n.hi[k] - r.o[k]) * r.inv[k];
    if (ta > tb) std::swap(ta, tb);
    // Argument order matters: std::max / std::min return the first argument when the
    // second is NaN (0 * inf for a ray in the slab plane), which then constrains nothing.
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  return t0 <= t1 ? t0 : kInf();
}

inline Ray make_ray(const Vec3& o, const Vec3& unit_dir) {
  // A zero component gives an infinite inverse; box_entry then ignores the NaN of 0 * inf,
  // so a ray lying in a slab plane counts as inside that slab (no leaks along box faces).
  // Zero components (also -0.0) get +inf, so the NaN lands in the right slot of box_entry.
  Ray r{o, unit_dir, Vec3()};
  for (int k = 0; k < 3; ++k) r.inv[k] = unit_dir[k] == 0.0 ? kInf() : 1.0 / unit_dir[k];
  return r;
}

/// Part of polygon `poly` on one side of the plane x[axis] = at (Sutherland–Hodgman, one plane).
std::vector<Vec3> clip_polygon(const std::vector<Vec3>& poly, int axis, double at, bool keep_below) {
  std::vector<Vec3> out;
  const std::size_t n = poly.size();
  for (std::size_t k = 0; k < n; ++k) {
    const Vec3& a = poly[k];
    const Vec3& b = poly[(k + 1) % n];
    const double da = keep_below ? at - a[axis] : a[axis] - at;
    const double db = keep_below ? at - b[axis] : b[axis] - at;
    if (da >= 0.0) out.push_back(a);
    if ((da >= 0.0) != (db >= 0.0)) {
      Vec3 x = a + (da / (da - db)) * (b - a);
      x[axis] = at;
      out.push_back(x);
    }
  }
  return out;
}

/// Append the boxes of `poly` cut into pieces no longer than max_extent (at most 2^depth pieces).
void split_reference(const std::vector<Vec3>& poly, double max_extent, double pad, int depth,
                     std::vector<Eigen::AlignedBox3d>& out) {
  if (poly.empty()) return;
  Eigen::AlignedBox3d box;
  for (const auto& p : poly) box.extend(p);
  int axis = 0;
  const double extent = box.sizes().maxCoeff(&axis);
  if (depth <= 0 || !(extent > max_extent)) {
    // Clipped vertices carry rounding error: pad so the box surely holds its piece.
    out.emplace_back(box.min() - Vec3::Constant(pad), box.max() + Vec3::Constant(pad));
    return;
  }
  const double mid = 0.5 * (box.min()[axis] + box.max()[axis]);
  split_reference(clip_polygon(poly, axis, mid, true), max_extent, pad, depth - 1, out);
  split_reference(clip_polygon(poly, axis, mid, false), max_extent, pad, depth - 1, out);
}

}  // namespace

struct MeshIndex::Impl {
  Mesh mesh;
  std::vector<Node> nodes;
  std::vector<SearchNode> search_nodes;   ///< nodes, as the closest-point search reads them
  std::vector<Tri> tris;

  void build();
  int build_node(std::vector<int>& order, std::vector<Eigen::AlignedBox3d>& boxes,
                 std::vector<Vec3>& centres, int begin, int end, int depth);

  template <class Visit>
  void traverse_ray(const Ray& r, double t_min, double& t_best, Visit&& visit) const;
};

void MeshIndex::Impl::build() {
  const int n_faces = static_cast<int>(mesh.faces.size());
  for (int f = 0; f < n_faces; ++f)
    if (!face_valid(mesh, mesh.faces[f]))
      throw Error("face " + std::to_string(f) + " indexes a missing vertex", "", "faces");
  if (n_faces == 0) return;

  // References: a triangle whose box is long compared with the scene (slivers spanning a gear
  // face or a pipe) is clipped into several references with tight boxes (early split
  // clipping, Ernst & Greiner 2007), so rays passing near it do not all have to test it.
  Eigen::AlignedBox3d scene;
  for (const auto& fc : mesh.faces)
    for (int k = 0; k < 3; ++k) scene.extend(mesh.vertices[fc[k]]);
  const double max_extent = scene.sizes().maxCoeff() / 24.0;
  const double pad = 1e-12 * std::max(scene.sizes().maxCoeff(), scene.max().cwiseAbs().maxCoeff());
  const std::size_t max_refs = 4 * static_cast<std::size_t>(n_faces) + 4096;
  std::vector<Eigen::AlignedBox3d> boxes;
  std::vector<int> ref_face;
  boxes.reserve(n_faces);
  ref_face.reserve(n_faces);
  std::vector<Vec3> poly;
  for (int f = 0; f < n_faces; ++f) {
    const auto& fc = mesh.faces[f];
    poly = {mesh.vertices[fc[0]], mesh.vertices[fc[1]], mesh.vertices[fc[2]]};
    split_reference(poly, max_extent, pad, boxes.size() < max_refs ? 6 : 0, boxes);
    ref_face.resize(boxes.size(), f);
  }
  const int n_refs = static_cast<int>(boxes.size());
  std::vector<int> order(n_refs);
  std::vector<Vec3> centres(n_refs);
  for (int r = 0; r < n_refs; ++r) {
    order[r] = r;
    centres[r] = boxes[r].center();
  }
  nodes.reserve(2 * n_refs / kLeafSize + 1);
  build_node(order, boxes, centres, 0, n_refs, 0);

  tris.resize(n_refs);
  for (int i = 0; i < n_refs; ++i) {
    const int f = ref_face[order[i]];
    const auto& fc = mesh.faces[f];
    Tri& t = tris[i];
    t.a = mesh.vertices[fc[0]];
    t.e1 = mesh.vertices[fc[1]] - t.a;
    t.e2 = mesh.vertices[fc[2]] - t.a;
    t.normal = t.e1.cross(t.e2).normalized();  // Eigen leaves a zero vector unchanged
    t.face = f;
  }
  search_nodes.reserve(nodes.size());
  for (const Node& n : nodes) search_nodes.push_back(search_node(n));
}

int MeshIndex::Impl::build_node(std::vector<int>& order, std::vector<Eigen::AlignedBox3d>& boxes,
                                std::vector<Vec3>& centres, int begin, int end, int depth) {
  const int index = static_cast<int>(nodes.size());
  nodes.emplace_back();
  Eigen::AlignedBox3d box, cbox;
  for (int i = begin; i < end; ++i) {
    box.extend(boxes[order[i]]);
    cbox.extend(centres[order[i]]);
  }
  nodes[index].lo = box.min();
  nodes[index].hi = box.max();
  const int count = end - begin;
  auto make_leaf = [&] {
    nodes[index].start = begin;
    nodes[index].count = count;
    return index;
  };
  if (count <= kLeafSize || depth >= kMaxDepth) return make_leaf();

  // Binned SAH (Wald 2007) over centroid bounds, on every axis with extent.
  auto area = [](const Eigen::AlignedBox3d& b) {
    if (b.isEmpty()) return 0.0;
    const Vec3 e = b.sizes();
    return e.x() * e.y() + e.y() * e.z() + e.z() * e.x();
  };
  double best_cost = std::numeric_limits<double>::infinity();
  int best_axis = -1, best_split = -1;
  const Vec3 cext = cbox.sizes();
  for (int axis = 0; axis < 3; ++axis) {
    if (!(cext[axis] > 0.0)) continue;
    std::array<Eigen::AlignedBox3d, kBins> bin_box;
    std::array<int, kBins> bin_count{};
    const double scale = kBins / cext[axis];
    for (int i = begin; i < end; ++i) {
      const int f = order[i];
      const int b = std::min(kBins - 1, static_cast<int>((centres[f][axis] - cbox.min()[axis]) * scale));
      bin_box[b].extend(boxes[f]);
      ++bin_count[b];
    }
    std::array<double, kBins> right_cost{};
    Eigen::AlignedBox3d acc;
    int acc_n = 0;
    for (int b = kBins - 1; b > 0; --b) {
      acc.extend(bin_box[b]);
      acc_n += bin_count[b];
      right_cost[b] = area(acc) * acc_n;
    }
    acc.setEmpty();
    acc_n = 0;
    for (int b = 0; b < kBins - 1; ++b) {
      acc.extend(bin_box[b]);
      acc_n += bin_count[b];
      const double cost = area(acc) * acc_n + right_cost[b + 1];
      if (acc_n > 0 && acc_n < count && cost < best_cost) {
        best_cost = cost;
        best_axis = axis;
        best_split = b;
      }
    }
  }
  if (best_axis < 0) return make_leaf();  // all centroids coincide
  // Leaf cost vs split cost (traversal cost ~ 1 triangle test).
  if (best_cost >= area(box) * (count - 1.0) && count <= 2 * kLeafSize) return make_leaf();

  const double scale = kBins / cext[best_axis];
  const double lo = cbox.min()[best_axis];
  auto mid_it = std::partition(order.begin() + begin, order.begin() + end, [&](int f) {
    return std::min(kBins - 1, static_cast<int>((centres[f][best_axis] - lo) * scale)) <= best_split;
  });
  const int mid = static_cast<int>(mid_it - order.begin());
  build_node(order, boxes, centres, begin, mid, depth + 1);
  const int right = build_node(order, boxes, centres, mid, end, depth + 1);
  nodes[index].start = right;
  nodes[index].count = 0;
  return index;
}

template <class Visit>
void MeshIndex::Impl::traverse_ray(const Ray& r, double t_min, double& t_best, Visit&& visit) const {
  if (nodes.empty()) return;
  int stack[kStackSize];
  int top = 0;
  if (box_entry(nodes[0], r, t_min, t_best) == kInf()) return;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = nodes[stack[--top]];
    if (n.count > 0) {
      for (int i = n.start; i < n.start + n.count; ++i) visit(i);
      continue;
    }
    const int li = static_cast<int>(&n - nodes.data()) + 1, ri = n.start;
    const double tl = box_entry(nodes[li], r, t_min, t_best);
    const double tr = box_entry(nodes[ri], r, t_min, t_best);
    // Push the farther child first so the nearer one is visited first.
    if (tl <= tr) {
      if (tr != kInf()) stack[top++] = ri;
      if (tl != kInf()) stack[top++] = li;
    } else {
      if (tl != kInf()) stack[top++] = li;
      if (tr != kInf()) stack[top++] = ri;
    }
  }
}

MeshIndex::MeshIndex(Mesh mesh) : impl_(std::make_unique<Impl>()) {
  impl_->mesh = std::move(mesh);
  impl_->build();
}
MeshIndex::~MeshIndex() = default;
MeshIndex::MeshIndex(MeshIndex&&) noexcept = default;
MeshIndex& MeshIndex::operator=(MeshIndex&&) noexcept = default;

const Mesh& MeshIndex::mesh() const { return impl_->mesh; }

std::optional<RayHit> MeshIndex::raycast(const Vec3& origin, const Vec3& dir, double t_max,
                                         double t_min) const {
  // t is measured along the unit direction, so t_min / t_max are distances.
  const double len = dir.norm();
  if (!(len > 0.0) || !std::isfinite(len) || !finite(origin)) return std::nullopt;
  const Ray r = make_ray(origin, dir / len);
  const auto& tris = impl_->tris;
  double t_best = t_max;
  int best = -1;
  // Ties (a ray through a shared edge) go to the smaller face index: the answer does not
  // depend on the tree's shape.
  impl_->traverse_ray(r, t_min, t_best, [&](int i) {
    const double t = intersect(tris[i], r.o, r.d, 1e-9);
    if (!(t > t_min && t <= t_best) || t == kInf()) return;
    if (best < 0 || t < t_best || tris[i].face < tris[best].face) {
      t_best = t;
      best = i;
    }
  });
  if (best < 0) return std::nullopt;
  RayHit hit;
  hit.t = t_best;
  hit.point = r.o + t_best * r.d;
  hit.normal = tris[best].normal;
  hit.face = tris[best].face;
  return hit;
}

bool MeshIndex::occluded(const Vec3& origin, const Vec3& dir, double t_max, double t_min) const {
  // raycast's tests, without its search for the nearest hit: a hit is any t with
  // t_min < t <= t_max (t_best never shrinks below t_max before the first hit).
  const double len = dir.norm();
  if (!(len > 0.0) || !std::isfinite(len) || !finite(origin)) return false;
  const Ray r = make_ray(origin, dir / len);
  const auto& tris = impl_->tris;
  const auto& nodes = impl_->nodes;
  if (nodes.empty() || box_entry(nodes[0], r, t_min, t_max) == kInf()) return false;
  int stack[kStackSize];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = nodes[stack[--top]];
    if (n.count > 0) {
      for (int i = n.start; i < n.start + n.count; ++i) {
        const double t = intersect(tris[i], r.o, r.d, 1e-9);
        if (t > t_min && t <= t_max && t != kInf()) return true;
      }
      continue;
    }
    const int li = static_cast<int>(&n - nodes.data()) + 1, ri = n.start;
    if (box_entry(nodes[ri], r, t_min, t_max) != kInf()) stack[top++] = ri;
    if (box_entry(nodes[li], r, t_min, t_max) != kInf()) stack[top++] = li;
  }
  return false;
}

namespace {

struct Best {
  double d2;
  int tri;
  Vec3 point;
};

}  // namespace

static void closest_search(const std::vector<SearchNode>& nodes, const std::vector<Tri>& tris,
                           const Vec3& p, Best& best) {
  if (nodes.empty()) return;
  // Depth first, nearer child first. A child's box distance is computed once, by its parent,
  // and kept on the stack with it: a node is entered while that distance is <= best.d2.
  struct Entry {
    int node;
    double d2;
  };
  Entry stack[kStackSize];
  int top = 0;
  int cur = 0;
  if (box_sq_distance(nodes[0], p) > best.d2) return;
  for (;;) {
    const SearchNode& n = nodes[cur];
    if (n.count > 0) {
      for (int i = n.start; i < n.start + n.count; ++i) {
        // The distance to the triangle's plane bounds the distance from below: a triangle whose
        // plane is clearly farther than the best is skipped (the margin covers the rounding of
        // the two computations, so the answer is the one without the test).
        const double h = tris[i].normal.dot(p - tris[i].a);
        if (h * h > best.d2 * (1.0 + 1e-6) + 1e-24) continue;
        const Vec3 q = closest_on_triangle(p, tris[i]);
        const double d2 = (q - p).squaredNorm();
        // Ties go to the smaller face index (independent of the tree's shape).
        if (d2 < best.d2 || (d2 == best.d2 && (best.tri < 0 || tris[i].face < tris[best.tri].face))) {
          best.d2 = d2;
          best.tri = i;
          best.point = q;
        }
      }
    } else {
      const int li = cur + 1, ri = n.start;
      const double dl = box_sq_distance(nodes[li], p), dr = box_sq_distance(nodes[ri], p);
      // The nearer child next (the left one on a tie), the other one on the stack.
      const bool left_first = dl <= dr;
      const int near = left_first ? li : ri, far = left_first ? ri : li;
      const double dn = left_first ? dl : dr, df = left_first ? dr : dl;
      if (dn <= best.d2) {
        if (df <= best.d2) stack[top++] = {far, df};
        cur = near;
        continue;
      }
    }
    // The next stacked node still within the best distance, if any.
    for (;;) {
      if (top == 0) return;
      const Entry& e = stack[--top];
      if (e.d2 <= best.d2) {
        cur = e.node;
        break;
      }
    }
  }
}

ClosestPoint MeshIndex::closest(const Vec3& p) const {
  Best best{std::numeric_limits<double>::infinity(), -1, Vec3::Zero()};
  ClosestPoint out;
  if (!finite(p)) {
    out.distance = std::numeric_limits<double>::infinity();
    return out;
  }
  closest_search(impl_->search_nodes, impl_->tris, p, best);
  if (best.tri < 0) {
    out.distance = std::numeric_limits<double>::infinity();
    return out;
  }
  out.distance = std::sqrt(best.d2);
  out.point = best.point;
  out.normal = impl_->tris[best.tri].normal;
  out.face = impl_->tris[best.tri].face;
  return out;
}

std::optional<ClosestPoint> MeshIndex::closest_within(const Vec3& p, double max_distance) const {
  if (!finite(p) || !(max_distance > 0.0)) return std::nullopt;
  // Search with the bound itself: anything at exactly max_distance is rejected below.
  Best best{max_distance * max_distance, -1, Vec3::Zero()};
  closest_search(impl_->search_nodes, impl_->tris, p, best);
  if (best.tri < 0 || !(best.d2 < max_distance * max_distance)) return std::nullopt;
  ClosestPoint out;
  out.distance = std::sqrt(best.d2);
  out.point = best.point;
  out.normal = impl_->tris[best.tri].normal;
  out.face = impl_->tris[best.tri].face;
  return out;
}

bool MeshIndex::inside(const Vec3& p) const {
  // Parity of surface crossings along three fixed, generic (non-axis-aligned, mutually
  // non-coplanar) directions; the majority vote absorbs the rare ray that grazes an edge.
  static const std::array<Vec3, 3> kDirs = {Vec3(0.5773502691896258, 0.5773502691896257, 0.5773502691896259),
                                            Vec3(-0.2672612419124244, 0.8017837257372732, -0.5345224838248488),
                                            Vec3(0.7071067811865476, -0.3015113445777636, -0.6396021490668313)};
  if (!finite(p) || impl_->nodes.empty()) return false;
  const auto& tris = impl_->tris;
  int votes = 0;
  for (const Vec3& dir : kDirs) {
    const Ray r = make_ray(p, dir.normalized());
    double t_best = std::numeric_limits<double>::infinity();  // never shrinks: count all hits
    std::vector<int> crossed;  // a triangle split into several references counts once
    impl_->traverse_ray(r, 0.0, t_best, [&](int i) {
      const double t = intersect(tris[i], r.o, r.d, 0.0);
      if (t > 0.0 && t != kInf()) crossed.push_back(tris[i].face);
    });
    std::sort(crossed.begin(), crossed.end());
    const auto crossings = std::unique(crossed.begin(), crossed.end()) - crossed.begin();
    votes += static_cast<int>(crossings & 1);
  }
  return votes >= 2;
}

}  // namespace ts
