// Triangle-mesh measurements and the MeshIndex BVH (binned-SAH build, flat depth-first node
// array, stack traversal). Queries never mutate the index, so they are thread-safe.
#include "engine/geometry/mesh.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <mutex>
#include <unordered_map>

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace ts {
inline namespace geometry {

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

/// Up to four children of a node of the tree that closest-point searches and occlusion rays
/// walk (the binary tree collapsed, Wald et al. 2008's BVH4): their boxes in floats rounded
/// outward (each holds its exact box, so pruning stays conservative), laid out so that the four
/// box tests run together.
struct SearchNode4 {
  float lo[3][4], hi[3][4];   ///< [axis][child]
  std::int32_t start[4];      ///< leaf child: first triangle; inner child: its SearchNode4
  std::int32_t count[4];      ///< leaf child: number of triangles (> 0); inner: 0; no child: -1
};

/// Squared distance from p to each child's box (0 inside), each computed as for one box: the
/// largest of lo - p, 0 and p - hi per axis, squared and summed over x, y, z in that order (two
/// children at a time with SSE2, which every x86-64 has; the same values either way).
inline void box_sq_distances(const SearchNode4& n, const Vec3& p, double d2[4]) {
#if defined(__SSE2__)
  const __m128d zero = _mm_setzero_pd();
  for (int h = 0; h < 4; h += 2) {
    __m128d acc = zero;
    for (int k = 0; k < 3; ++k) {
      const __m128d pk = _mm_set1_pd(p[k]);
      const __m128d lo = _mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(&n.lo[k][h]))));
      const __m128d hi = _mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(&n.hi[k][h]))));
      const __m128d e = _mm_max_pd(_mm_max_pd(_mm_sub_pd(lo, pk), zero), _mm_sub_pd(pk, hi));
      acc = _mm_add_pd(acc, _mm_mul_pd(e, e));
    }
    _mm_storeu_pd(d2 + h, acc);
  }
#else
  for (int c = 0; c < 4; ++c) {
    const double ex = std::max(std::max(double(n.lo[0][c]) - p.x(), 0.0), p.x() - double(n.hi[0][c]));
    const double ey = std::max(std::max(double(n.lo[1][c]) - p.y(), 0.0), p.y() - double(n.hi[1][c]));
    const double ez = std::max(std::max(double(n.lo[2][c]) - p.z(), 0.0), p.z() - double(n.hi[2][c]));
    d2[c] = ex * ex + ey * ey + ez * ez;
  }
#endif
}

/// A box in floats that holds the double one.
inline void outward(const Vec3& lo, const Vec3& hi, float out_lo[3], float out_hi[3]) {
  for (int k = 0; k < 3; ++k) {
    out_lo[k] = static_cast<float>(lo[k]);
    if (double(out_lo[k]) > lo[k]) out_lo[k] = std::nextafter(out_lo[k], -std::numeric_limits<float>::infinity());
    out_hi[k] = static_cast<float>(hi[k]);
    if (double(out_hi[k]) < hi[k]) out_hi[k] = std::nextafter(out_hi[k], std::numeric_limits<float>::infinity());
  }
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

/// Where on a triangle its closest point lies (closest_on_triangle): the interior, a vertex or
/// an edge. Edge k joins the face's vertices k and (k + 1) % 3.
enum Region : int { kFace = 0, kVertexA, kVertexB, kVertexC, kEdgeAB, kEdgeBC, kEdgeCA };

/// Closest point on triangle (a, a+e1, a+e2) to p: Ericson, Real-Time Collision Detection, 5.1.5.
/// `region` (when given) receives the feature that holds it.
[[gnu::always_inline]] inline Vec3 closest_on_triangle(const Vec3& p, const Tri& tri, int* region = nullptr) {
  const auto at = [&](int r, const Vec3& q) {
    if (region) *region = r;
    return q;
  };
  const Vec3& a = tri.a;
  const Vec3 b = a + tri.e1, c = a + tri.e2;
  const Vec3& ab = tri.e1;
  const Vec3& ac = tri.e2;
  const Vec3 ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return at(kVertexA, a);
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return at(kVertexB, b);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    const double denom = d1 - d3;
    return denom > 0.0 ? at(kEdgeAB, Vec3(a + (d1 / denom) * ab)) : at(kVertexA, a);
  }
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return at(kVertexC, c);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    const double denom = d2 - d6;
    return denom > 0.0 ? at(kEdgeCA, Vec3(a + (d2 / denom) * ac)) : at(kVertexA, a);
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    const double denom = (d4 - d3) + (d5 - d6);
    return denom > 0.0 ? at(kEdgeBC, Vec3(b + ((d4 - d3) / denom) * (c - b))) : at(kVertexB, b);
  }
  const double sum = va + vb + vc;
  if (!(sum > 0.0)) return at(kVertexA, a);  // degenerate triangle
  const double inv = 1.0 / sum;
  return at(kFace, a + ab * (vb * inv) + ac * (vc * inv));
}

/// The triangle of face f as the index stores it (the same arithmetic as Impl::build).
inline Tri make_tri(const Mesh& mesh, int f) {
  const auto& fc = mesh.faces[f];
  Tri t;
  t.a = mesh.vertices[fc[0]];
  t.e1 = mesh.vertices[fc[1]] - t.a;
  t.e2 = mesh.vertices[fc[2]] - t.a;
  t.normal = t.e1.cross(t.e2).normalized();  // Eigen leaves a zero vector unchanged
  t.face = f;
  return t;
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

/// Which children of a search node the ray enters within [t0, t1], as bits: box_entry's slab
/// test on each child's (outward) box, its NaN handling included (a ray lying in a slab plane
/// counts as inside that slab). Two children at a time with SSE2.
inline int box_hits(const SearchNode4& n, const Ray& r, double t0, double t1) {
  int mask = 0;
#if defined(__SSE2__)
  for (int h = 0; h < 4; h += 2) {
    __m128d enter = _mm_set1_pd(t0), leave = _mm_set1_pd(t1);
    for (int k = 0; k < 3; ++k) {
      const __m128d o = _mm_set1_pd(r.o[k]), inv = _mm_set1_pd(r.inv[k]);
      const __m128d lo = _mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(&n.lo[k][h]))));
      const __m128d hi = _mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(&n.hi[k][h]))));
      const __m128d ta = _mm_mul_pd(_mm_sub_pd(lo, o), inv), tb = _mm_mul_pd(_mm_sub_pd(hi, o), inv);
      // minpd / maxpd return their second operand when either is NaN: the operand order makes
      // a NaN bound drop out, as std::max(t0, ta) and std::min(t1, tb) do in box_entry.
      enter = _mm_max_pd(_mm_min_pd(tb, ta), enter);
      leave = _mm_min_pd(_mm_max_pd(ta, tb), leave);
    }
    mask |= _mm_movemask_pd(_mm_cmple_pd(enter, leave)) << h;
  }
#else
  for (int c = 0; c < 4; ++c) {
    double enter = t0, leave = t1;
    for (int k = 0; k < 3; ++k) {
      double ta = (double(n.lo[k][c]) - r.o[k]) * r.inv[k];
      double tb = (double(n.hi[k][c]) - r.o[k]) * r.inv[k];
      if (ta > tb) std::swap(ta, tb);
      enter = std::max(enter, ta);
      leave = std::min(leave, tb);
    }
    if (enter <= leave) mask |= 1 << c;
  }
#endif
  for (int c = 0; c < 4; ++c)
    if (n.count[c] < 0) mask &= ~(1 << c);   // no child (its box, lo > hi, would pass)
  return mask;
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

/// The closest triangle so far of a closest-point search.
struct Best {
  double d2;
  int tri;
  Vec3 point;
};

/// Angle-weighted pseudonormals of an oriented mesh (MeshIndex::side), made on first use.
struct Pseudonormals {
  bool oriented = false;
  std::vector<Vec3> face;                 ///< unit normal as wound (zero when degenerate)
  std::vector<Vec3> vertex;               ///< sum of incident face normals times their angle there
  std::vector<std::array<Vec3, 3>> edge;  ///< per face, edge k: the sum of its two faces' normals
};

Pseudonormals make_pseudonormals(const Mesh& mesh) {
  Pseudonormals pn;
  const std::size_t n_faces = mesh.faces.size();
  // Directed edges by undirected key: an oriented surface uses each exactly twice, once each way.
  struct Use {
    std::uint64_t key;
    bool forward;   // a < b as wound
    std::uint32_t face, k;
    bool operator<(const Use& o) const {
      return key != o.key ? key < o.key : (face != o.face ? face < o.face : k < o.k);
    }
  };
  std::vector<Use> uses;
  uses.reserve(3 * n_faces);
  for (std::size_t f = 0; f < n_faces; ++f) {
    const auto& fc = mesh.faces[f];
    for (std::uint32_t k = 0; k < 3; ++k) {
      const auto a = static_cast<std::uint64_t>(fc[k]), b = static_cast<std::uint64_t>(fc[(k + 1) % 3]);
      if (a == b) return pn;   // a repeated vertex: no consistent orientation to speak of
      uses.push_back({(std::min(a, b) << 32) | std::max(a, b), a < b, static_cast<std::uint32_t>(f), k});
    }
  }
  std::sort(uses.begin(), uses.end());
  pn.face.resize(n_faces);
  for (std::size_t f = 0; f < n_faces; ++f) pn.face[f] = make_tri(mesh, static_cast<int>(f)).normal;
  pn.edge.assign(n_faces, {Vec3::Zero(), Vec3::Zero(), Vec3::Zero()});
  for (std::size_t u = 0; u < uses.size(); u += 2) {
    if (u + 1 >= uses.size() || uses[u + 1].key != uses[u].key || uses[u + 1].forward == uses[u].forward ||
        (u + 2 < uses.size() && uses[u + 2].key == uses[u].key))
      return Pseudonormals{};   // open, non-manifold or inconsistently wound
    const Vec3 n = pn.face[uses[u].face] + pn.face[uses[u + 1].face];
    pn.edge[uses[u].face][uses[u].k] = n;
    pn.edge[uses[u + 1].face][uses[u + 1].k] = n;
  }
  // Every connected part must enclose a positive volume: a closed part wound inward next to one
  // wound outward passes the edge test, and its pseudonormals would point into the solid.
  {
    std::vector<std::size_t> parent(mesh.vertices.size());
    for (std::size_t v = 0; v < parent.size(); ++v) parent[v] = v;
    const auto root = [&](std::size_t x) {
      while (parent[x] != x) x = parent[x] = parent[parent[x]];
      return x;
    };
    for (const auto& fc : mesh.faces)
      for (int k = 1; k < 3; ++k) {
        const std::size_t x = root(static_cast<std::size_t>(fc[0])), y = root(static_cast<std::size_t>(fc[k]));
        if (x != y) parent[std::max(x, y)] = std::min(x, y);
      }
    Eigen::AlignedBox3d box;
    for (const Vec3& v : mesh.vertices) box.extend(v);
    const Vec3 o = box.center();
    std::unordered_map<std::size_t, double> six_volume;   // by part (its root vertex)
    for (const auto& fc : mesh.faces)
      six_volume[root(static_cast<std::size_t>(fc[0]))] +=
          (mesh.vertices[fc[0]] - o).dot((mesh.vertices[fc[1]] - o).cross(mesh.vertices[fc[2]] - o));
    for (const auto& [part, v] : six_volume)
      if (!(v > 0.0)) return Pseudonormals{};
  }
  pn.vertex.assign(mesh.vertices.size(), Vec3::Zero());
  for (std::size_t f = 0; f < n_faces; ++f) {
    const auto& fc = mesh.faces[f];
    for (int k = 0; k < 3; ++k) {
      const Vec3& v = mesh.vertices[fc[k]];
      const Vec3 e1 = mesh.vertices[fc[(k + 1) % 3]] - v, e2 = mesh.vertices[fc[(k + 2) % 3]] - v;
      pn.vertex[fc[k]] += std::atan2(e1.cross(e2).norm(), e1.dot(e2)) * pn.face[f];
    }
  }
  pn.oriented = true;
  return pn;
}

}  // namespace

struct MeshIndex::Impl {
  Mesh mesh;
  std::vector<Node> nodes;
  std::vector<SearchNode4> search_nodes;   ///< nodes, as the closest-point search reads them
  float root_lo[3] = {0, 0, 0}, root_hi[3] = {0, 0, 0};   ///< the whole tree's box, outward
  int collapse(int node);
  void closest_search(const Vec3& p, Best& best) const;
  std::vector<Tri> tris;
  std::once_flag pseudonormals_once;
  Pseudonormals pseudonormals_;

  const Pseudonormals& pseudonormals() {
    std::call_once(pseudonormals_once, [&] { pseudonormals_ = make_pseudonormals(mesh); });
    return pseudonormals_;
  }

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
  for (int i = 0; i < n_refs; ++i) tris[i] = make_tri(mesh, ref_face[order[i]]);
  search_nodes.reserve(nodes.size() / 2 + 1);
  outward(nodes[0].lo, nodes[0].hi, root_lo, root_hi);
  collapse(0);
}

int MeshIndex::Impl::collapse(int node) {
  // The node's children, each inner one replaced by its own two (the one with the largest box
  // surface first) while there is room for four.
  std::vector<int> kids;
  if (nodes[node].count > 0) kids = {node};   // a leaf root: one leaf child
  else kids = {node + 1, nodes[node].start};
  auto area = [&](int k) {
    const Vec3 e = nodes[k].hi - nodes[k].lo;
    return e.x() * e.y() + e.y() * e.z() + e.z() * e.x();
  };
  while (kids.size() < 4) {
    int pick = -1;
    for (int c = 0; c < static_cast<int>(kids.size()); ++c)
      if (nodes[kids[c]].count == 0 && (pick < 0 || area(kids[c]) > area(kids[pick]))) pick = c;
    if (pick < 0) break;
    const int k = kids[pick];
    kids[pick] = k + 1;
    kids.insert(kids.begin() + pick + 1, nodes[k].start);
  }
  const int index = static_cast<int>(search_nodes.size());
  search_nodes.emplace_back();
  for (int c = 0; c < 4; ++c) {
    SearchNode4& n = search_nodes[index];
    if (c >= static_cast<int>(kids.size())) {   // no child: a box no point is near
      for (int k = 0; k < 3; ++k) {
        n.lo[k][c] = std::numeric_limits<float>::infinity();
        n.hi[k][c] = -std::numeric_limits<float>::infinity();
      }
      n.start[c] = 0;
      n.count[c] = -1;
      continue;
    }
    const Node& kid = nodes[kids[c]];
    float lo[3], hi[3];
    outward(kid.lo, kid.hi, lo, hi);
    for (int k = 0; k < 3; ++k) {
      n.lo[k][c] = lo[k];
      n.hi[k][c] = hi[k];
    }
    n.count[c] = kid.count;
    n.start[c] = kid.count > 0 ? kid.start : 0;
  }
  for (int c = 0; c < static_cast<int>(kids.size()); ++c)
    if (nodes[kids[c]].count == 0) {
      const int child = collapse(kids[c]);   // (search_nodes may move meanwhile)
      search_nodes[index].start[c] = child;
    }
  return index;
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
  const auto& nodes = impl_->search_nodes;
  if (nodes.empty() || box_entry(impl_->nodes[0], r, t_min, t_max) == kInf()) return false;
  struct Entry {
    std::int32_t start, count;   // as SearchNode4's child
  };
  Entry stack[3 * kStackSize];
  int top = 0;
  stack[top++] = {0, 0};
  while (top > 0) {
    const Entry e = stack[--top];
    if (e.count > 0) {
      for (int i = e.start; i < e.start + e.count; ++i) {
        const double t = intersect(tris[i], r.o, r.d, 1e-9);
        if (t > t_min && t <= t_max && t != kInf()) return true;
      }
      continue;
    }
    const SearchNode4& n = nodes[e.start];
    const int hits = box_hits(n, r, t_min, t_max);
    for (int c = 3; c >= 0; --c)
      if (hits & (1 << c)) stack[top++] = {n.start[c], n.count[c]};
  }
  return false;
}

void MeshIndex::Impl::closest_search(const Vec3& p, Best& best) const {
  const std::vector<SearchNode4>& nodes = search_nodes;
  if (nodes.empty()) return;
  {
    double d2 = 0.0;
    for (int k = 0; k < 3; ++k) {
      const double e = std::max(std::max(double(root_lo[k]) - p[k], 0.0), p[k] - double(root_hi[k]));
      d2 += e * e;
    }
    if (d2 > best.d2) return;
  }
  // Depth first, nearest child first. A child's box distance is computed once, by its parent,
  // and kept on the stack with it: a child is entered while that distance is <= best.d2. The
  // answer does not depend on the order (ties go to the smaller face index).
  struct Entry {
    std::int32_t start, count;   // as SearchNode4's child
    double d2;
  };
  Entry stack[3 * kStackSize];
  int top = 0;
  Entry cur{0, 0, 0.0};
  for (;;) {
    if (cur.count > 0) {
      for (int i = cur.start; i < cur.start + cur.count; ++i) {
        // The distance to the triangle's plane bounds the distance from below: a triangle whose
        // plane is clearly farther than the best is skipped (the margin covers the rounding of
        // the two computations, so the answer is the one without the test).
        const double h = tris[i].normal.dot(p - tris[i].a);
        if (h * h > best.d2 * (1.0 + 1e-6) + 1e-24) continue;
        const Vec3 q = closest_on_triangle(p, tris[i]);
        const double d2 = (q - p).squaredNorm();
        if (d2 < best.d2 || (d2 == best.d2 && (best.tri < 0 || tris[i].face < tris[best.tri].face))) {
          best.d2 = d2;
          best.tri = i;
          best.point = q;
        }
      }
    } else {
      const SearchNode4& n = nodes[cur.start];
      double d2[4];
      box_sq_distances(n, p, d2);
      // The children within the best distance, nearest first (insertion sort of at most 4).
      int order[4], m = 0;
      for (int c = 0; c < 4; ++c) {
        if (n.count[c] < 0 || d2[c] > best.d2) continue;
        int at = m++;
        while (at > 0 && d2[order[at - 1]] > d2[c]) {
          order[at] = order[at - 1];
          --at;
        }
        order[at] = c;
      }
      if (m > 0) {
        for (int k = m - 1; k > 0; --k) stack[top++] = {n.start[order[k]], n.count[order[k]], d2[order[k]]};
        cur = {n.start[order[0]], n.count[order[0]], d2[order[0]]};
        continue;
      }
    }
    // The next stacked child still within the best distance, if any.
    for (;;) {
      if (top == 0) return;
      const Entry& e = stack[--top];
      if (e.d2 <= best.d2) {
        cur = e;
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
  impl_->closest_search(p, best);
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
  impl_->closest_search(p, best);
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

bool MeshIndex::oriented() const { return impl_->pseudonormals().oriented; }

double MeshIndex::side(const Vec3& p, const ClosestPoint& c) const {
  const Pseudonormals& pn = impl_->pseudonormals();
  if (!pn.oriented || c.face < 0 || c.face >= static_cast<int>(impl_->mesh.faces.size())) return 0.0;
  // The feature holding c.point, by the computation that found it.
  int region = kFace;
  closest_on_triangle(p, make_tri(impl_->mesh, c.face), &region);
  const auto& fc = impl_->mesh.faces[c.face];
  Vec3 n;
  switch (region) {
    case kVertexA: n = pn.vertex[fc[0]]; break;
    case kVertexB: n = pn.vertex[fc[1]]; break;
    case kVertexC: n = pn.vertex[fc[2]]; break;
    case kEdgeAB: n = pn.edge[c.face][0]; break;
    case kEdgeBC: n = pn.edge[c.face][1]; break;
    case kEdgeCA: n = pn.edge[c.face][2]; break;
    default: n = pn.face[c.face];
  }
  return (p - c.point).dot(n);
}

std::vector<ShellVoxel> MeshIndex::shell(double voxel, double radius) const {
  if (!(voxel > 0.0) || !std::isfinite(voxel) || !(radius >= 0.0) || !std::isfinite(radius))
    throw Error("MeshIndex::shell: the voxel must be positive and the radius non-negative", "", "voxel");
  const Mesh& mesh = impl_->mesh;
  const int n_faces = static_cast<int>(mesh.faces.size());
  const double r2 = radius * radius;
  // Lattice points are candidates of a face when they lie in the box of a piece of it grown by
  // the radius (a hair more: the pieces' corners are rounded midpoints); a face is cut into
  // quarters until a piece's box holds at most kPiece points or the piece is a voxel long, so
  // large or long faces cost in proportion to their area. Each candidate is tested against the
  // whole face.
  constexpr double kPiece = 512.0;
  const double grow = radius * (1.0 + 1e-9) + 1e-9 * voxel;
  struct Candidate {
    std::array<std::int32_t, 3> ijk;
    double d2;
    int face;
  };
  constexpr int kChunk = 256;   // faces per task; a task's candidates in face order
  const int chunks = (n_faces + kChunk - 1) / kChunk;
  std::vector<std::vector<Candidate>> found(static_cast<std::size_t>(chunks));
  tbb::parallel_for(0, chunks, [&](int chunk) {
    auto& out = found[static_cast<std::size_t>(chunk)];
    std::vector<std::array<Vec3, 3>> pieces;
    for (int f = chunk * kChunk; f < std::min(n_faces, (chunk + 1) * kChunk); ++f) {
      const Tri tri = make_tri(mesh, f);
      const auto& fc = mesh.faces[f];
      pieces.assign(1, {mesh.vertices[fc[0]], mesh.vertices[fc[1]], mesh.vertices[fc[2]]});
      while (!pieces.empty()) {
        const std::array<Vec3, 3> t = pieces.back();
        pieces.pop_back();
        const Vec3 lo = t[0].cwiseMin(t[1]).cwiseMin(t[2]).array() - grow;
        const Vec3 hi = t[0].cwiseMax(t[1]).cwiseMax(t[2]).array() + grow;
        const Vec3 l = (lo / voxel).array().ceil(), h = (hi / voxel).array().floor();
        if (!(l.allFinite() && h.allFinite()) || l.cwiseAbs().maxCoeff() > 2e9 || h.cwiseAbs().maxCoeff() > 2e9)
          throw Error("MeshIndex::shell: lattice coordinates beyond 32 bits (voxel too small for the mesh)", "", "voxel");
        const Vec3 count = (h - l).array() + 1.0;
        if ((count.array() <= 0.0).any()) continue;
        // Split while the piece itself is longer than a voxel: its box then holds at most
        // (2 + 2 radius / voxel)^3 points, whatever the radius, and splitting ends.
        const double extent = (t[0].cwiseMax(t[1]).cwiseMax(t[2]) - t[0].cwiseMin(t[1]).cwiseMin(t[2])).maxCoeff();
        if (count.prod() > kPiece && extent > voxel) {
          const Vec3 ab = 0.5 * (t[0] + t[1]), bc = 0.5 * (t[1] + t[2]), ca = 0.5 * (t[2] + t[0]);
          pieces.push_back({t[0], ab, ca});
          pieces.push_back({ab, t[1], bc});
          pieces.push_back({ca, bc, t[2]});
          pieces.push_back({ab, bc, ca});
          continue;
        }
        for (auto i = static_cast<std::int32_t>(l.x()); i <= static_cast<std::int32_t>(h.x()); ++i)
          for (auto j = static_cast<std::int32_t>(l.y()); j <= static_cast<std::int32_t>(h.y()); ++j)
            for (auto k = static_cast<std::int32_t>(l.z()); k <= static_cast<std::int32_t>(h.z()); ++k) {
              const Vec3 p = Vec3(i, j, k) * voxel;
              // The plane bounds the distance from below (closest_search's test and margin).
              const double dh = tri.normal.dot(p - tri.a);
              if (dh * dh > r2 * (1.0 + 1e-6) + 1e-24) continue;
              const double d2 = (closest_on_triangle(p, tri) - p).squaredNorm();
              if (d2 <= r2) out.push_back({{i, j, k}, d2, f});
            }
      }
    }
  });
  std::vector<Candidate> all;
  std::size_t total = 0;
  for (const auto& v : found) total += v.size();
  all.reserve(total);
  for (auto& v : found) {
    all.insert(all.end(), v.begin(), v.end());
    std::vector<Candidate>().swap(v);
  }
  // By point, then distance, then face: the first of each point is closest()'s answer. The
  // order is total (a face gives a point once per piece, the same entry), so the result does
  // not depend on the tasks.
  const auto same = [](const Candidate& a, const Candidate& b) {
    return a.ijk[0] == b.ijk[0] && a.ijk[1] == b.ijk[1] && a.ijk[2] == b.ijk[2];
  };
  tbb::parallel_sort(all.begin(), all.end(), [](const Candidate& a, const Candidate& b) {
    for (int k = 0; k < 3; ++k)
      if (a.ijk[k] != b.ijk[k]) return a.ijk[k] < b.ijk[k];
    if (a.d2 != b.d2) return a.d2 < b.d2;
    return a.face < b.face;
  });
  std::vector<ShellVoxel> out;
  for (std::size_t n = 0; n < all.size(); ++n) {
    if (n > 0 && same(all[n], all[n - 1])) continue;
    const Candidate& c = all[n];
    const Vec3 p = Vec3(c.ijk[0], c.ijk[1], c.ijk[2]) * voxel;
    out.push_back({c.ijk, c.d2, closest_on_triangle(p, make_tri(mesh, c.face)), c.face});
  }
  return out;
}

}  // namespace geometry
}  // namespace ts
