#include "datasets/catalogue/catalogue.hpp"

#include "engine/geometry/mesh.hpp"
#include "io/mesh_export.hpp"

#include <Eigen/Eigenvalues>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <numeric>
#include <sstream>
#include <cerrno>
#include <csignal>
#include <unistd.h>

namespace ts::catalogue {

namespace fs = std::filesystem;

namespace {

constexpr std::uint64_t kStream = 0xCA7A1065ull;  // random stream tag of the catalogue draws

std::string object_error(const Family& family, const Params& params, const std::string& what) {
  return "family '" + family.name + "' (" + params.text() + "): " + what;
}

/// Smooth weighted round robin: proportional, deterministic, spread out.
std::vector<std::size_t> assign_families(const std::vector<Family>& families, std::size_t count) {
  std::vector<double> current(families.size(), 0.0);
  double total = 0.0;
  for (const auto& f : families) total += f.weight;
  std::vector<std::size_t> out(count);
  for (std::size_t i = 0; i < count; ++i) {
    std::size_t best = families.size();
    for (std::size_t f = 0; f < families.size(); ++f) {
      if (families[f].weight <= 0.0) continue;
      current[f] += families[f].weight;
      if (best == families.size() || current[f] > current[best] + 1e-12) best = f;
    }
    current[best] -= total;
    out[i] = best;
  }
  return out;
}

void check_spec(const Family& f, const ParamSpec& s, const std::string& file) {
  const std::string field = f.name + "." + s.name;
  if (!std::isfinite(s.lo) || !std::isfinite(s.hi))
    throw Error("range of family '" + f.name + "' parameter '" + s.name + "' is not finite", file, field);
  if (s.lo > s.hi) {
    char text[200];
    std::snprintf(text, sizeof text, "family '%s' parameter '%s': minimum %g is greater than maximum %g", f.name.c_str(),
                  s.name.c_str(), s.lo, s.hi);
    throw Error(text, file, field);
  }
  if (s.positive() && s.lo <= 0.0)
    throw Error("family '" + f.name + "' parameter '" + s.name + "': sizes must be positive", file, field);
  if (s.unit == "1" && s.lo <= 0.0 && s.name != "tangent_ratio")
    throw Error("family '" + f.name + "' parameter '" + s.name + "': ratios must be positive", file, field);
  if (s.draw == Draw::Choice && (s.lo < 0 || s.hi > double(s.choices.size() - 1) || s.lo != std::floor(s.lo) ||
                                 s.hi != std::floor(s.hi)))
    throw Error("family '" + f.name + "' parameter '" + s.name + "': choice indices must lie in 0.." +
                    std::to_string(s.choices.size() - 1),
                file, field);
  if (s.draw == Draw::Integer && (s.lo < 1 || s.lo != std::floor(s.lo) || s.hi != std::floor(s.hi)))
    throw Error("family '" + f.name + "' parameter '" + s.name + "': counts must be whole numbers >= 1", file, field);
}

std::string width_name(const std::string& family, std::size_t i, std::size_t count) {
  std::size_t digits = 1;
  for (std::size_t n = count > 0 ? count - 1 : 0; n >= 10; n /= 10) ++digits;
  std::string num = std::to_string(i);
  const std::size_t width = std::max<std::size_t>(4, digits);
  if (num.size() < width) num.insert(0, width - num.size(), '0');
  return family + "_" + num;
}

/// Removes a folder on destruction unless released.
struct FolderGuard {
  fs::path path;
  ~FolderGuard() {
    if (path.empty()) return;
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

/// Remove "<out>.tmp-<pid>" folders of catalogue runs that died (a kill, Ctrl-C: the signal
/// handler can only unlink files): their process no longer exists. Folders of live runs stay.
void remove_stale_temporaries(const fs::path& out) {
  const fs::path parent = out.has_parent_path() ? out.parent_path() : fs::path(".");
  const std::string prefix = out.filename().string() + ".tmp-";
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(parent, ec)) {
    const std::string name = e.path().filename().string();
    if (name.rfind(prefix, 0) != 0 || !e.is_directory(ec)) continue;
    const std::string digits = name.substr(prefix.size());
    if (digits.empty() || digits.size() > 9 || digits.find_first_not_of("0123456789") != std::string::npos) continue;
    const auto pid = static_cast<pid_t>(std::stol(digits));
    if (pid == ::getpid() || ::kill(pid, 0) == 0 || errno != ESRCH) continue;   // alive, or not ours to judge
    fs::remove_all(e.path(), ec);
  }
}

void write_text_file(const fs::path& file, const std::string& text) {
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  out << text;
  out.close();
  if (!out) throw Error("cannot write", file.string());
}

}  // namespace

// --- one object ------------------------------------------------------------------------------
BuiltObject build_object(const Family& family, const Params& params, const BuildSettings& bs) {
  // Preview at a coarse voxel: sizes, and the triangle count, which scales as 1 / voxel^2.
  const Construction c0 = family.build(params, 1e-3);
  if (!(c0.extent > 0.0) || !(c0.min_feature > 0.0))
    throw Error(object_error(family, params, "impossible dimensions (non-positive extent or feature size)"));
  const double v0 = c0.extent * bs.preview_voxel_fraction;
  const double tris0 = static_cast<double>(mesh_shape(family.build(params, v0).shape, v0, bs.half_width).mesh.faces.size());
  const double v_triangles = v0 * std::sqrt(std::max(tris0, 1.0) / bs.target_triangles);
  const double v_feature = std::min(c0.min_feature / bs.feature_voxels, c0.extent * bs.max_voxel_fraction);
  double voxel = std::max({v_triangles, v_feature, c0.extent * bs.min_voxel_fraction}) * bs.coarsen;

  // Mesh; coarser when over the triangle cap; finer (x 0.8, twice at most) when the mesh fails
  // its check, which happens when a wall is thinner than about a voxel.
  BuiltObject out;
  int finer = 0;
  for (int pass = 0;; ++pass) {
    const Construction c = family.build(params, voxel);
    MeshedShape meshed = mesh_shape(c.shape, voxel, bs.half_width);
    const double tris = static_cast<double>(meshed.mesh.faces.size());
    if (tris > bs.max_triangles && pass < 3 && finer == 0) {
      voxel *= std::sqrt(tris / bs.target_triangles) * 1.02;
      continue;
    }
    out.mesh = std::move(meshed.mesh);
    out.check = check_mesh(out.mesh);
    if (!out.check.valid() && finer < bs.finer_retries) {
      voxel *= 0.8;
      ++finer;
      continue;
    }
    break;
  }
  out.voxel = voxel;
  out.remeshed = finer;
  if (!out.check.valid()) {
    char v[64];
    std::snprintf(v, sizeof v, "%.4g mm", voxel * 1e3);
    throw Error(object_error(family, params, "invalid mesh at voxel " + std::string(v) + ": " + out.check.describe()));
  }
  out.extent = mesh_bounds(out.mesh).sizes().maxCoeff();
  return out;
}

// --- signature -------------------------------------------------------------------------------
Signature shape_signature(const Mesh& mesh) {
  // Volume, first and second moments of the solid by signed tetrahedra from the bounding-box
  // centre (exact for a closed mesh): for a tetrahedron (0, a, b, c) of volume v,
  // integral of x = v (a + b + c) / 4 and integral of x x^T = v / 20 (sum p p^T + s s^T), s = a + b + c.
  const Vec3 o = mesh_bounds(mesh).center();
  double V = 0.0, A = 0.0;
  Vec3 m1 = Vec3::Zero();
  Mat3 m2 = Mat3::Zero();
  for (const auto& f : mesh.faces) {
    const Vec3 a = mesh.vertices[f[0]] - o, b = mesh.vertices[f[1]] - o, c = mesh.vertices[f[2]] - o;
    const Vec3 n = (b - a).cross(c - a);
    A += 0.5 * n.norm();
    const double v = a.dot(b.cross(c)) / 6.0;
    const Vec3 s = a + b + c;
    V += v;
    m1 += v * s / 4.0;
    m2 += v / 20.0 * (a * a.transpose() + b * b.transpose() + c * c.transpose() + s * s.transpose());
  }
  Signature sig{};
  if (!(V > 0.0)) return sig;
  const Vec3 centroid = m1 / V;
  const Mat3 cov = m2 / V - centroid * centroid.transpose();
  Eigen::SelfAdjointEigenSolver<Mat3> eig(cov, Eigen::EigenvaluesOnly);
  const Vec3 ev = eig.eigenvalues();  // ascending
  sig[0] = std::cbrt(V);
  sig[1] = std::sqrt(A);
  for (int k = 0; k < 3; ++k) sig[2 + k] = std::sqrt(std::max(ev[k], 0.0));
  return sig;
}

double signature_distance(const Signature& a, const Signature& b) {
  double d = 0.0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    if (a[k] <= 0.0 || b[k] <= 0.0) {
      if (a[k] != b[k]) return std::numeric_limits<double>::infinity();
      continue;
    }
    d = std::max(d, std::abs(std::log(a[k] / b[k])));
  }
  return d;
}

std::vector<ClosePair> closest_pairs(const std::vector<Signature>& sigs, std::size_t k) {
  const std::size_t n = sigs.size();
  auto better = [](const ClosePair& x, const ClosePair& y) {
    if (x.distance != y.distance) return x.distance < y.distance;
    return std::tie(x.a, x.b) < std::tie(y.a, y.b);
  };
  // Per row i: its k best partners j > i (own slot), merged serially in row order.
  std::vector<std::vector<ClosePair>> rows(n);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      auto& row = rows[i];
      for (std::size_t j = i + 1; j < n; ++j) {
        const ClosePair p{i, j, signature_distance(sigs[i], sigs[j])};
        if (row.size() < k) {
          row.push_back(p);
          std::sort(row.begin(), row.end(), better);
        } else if (k > 0 && better(p, row.back())) {
          row.back() = p;
          std::sort(row.begin(), row.end(), better);
        }
      }
    }
  });
  std::vector<ClosePair> all;
  for (const auto& row : rows) all.insert(all.end(), row.begin(), row.end());
  std::sort(all.begin(), all.end(), better);
  if (all.size() > k) all.resize(k);
  return all;
}

std::vector<long> congruent_to_earlier(const std::vector<Signature>& sigs, double tolerance) {
  // Sort by ln(sig[0]); only neighbours within the tolerance on that component can match.
  const std::size_t n = sigs.size();
  std::vector<double> key(n);
  for (std::size_t i = 0; i < n; ++i) key[i] = sigs[i][0] > 0.0 ? std::log(sigs[i][0]) : -1e300;
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return key[a] != key[b] ? key[a] < key[b] : a < b; });
  std::vector<long> out(n, -1);
  for (std::size_t oi = 0; oi < n; ++oi) {
    const std::size_t i = order[oi];
    auto consider = [&](std::size_t oj) {
      const std::size_t j = order[oj];
      if (j < i && signature_distance(sigs[i], sigs[j]) <= tolerance && (out[i] < 0 || long(j) < out[i])) out[i] = long(j);
    };
    for (std::size_t oj = oi; oj-- > 0 && key[i] - key[order[oj]] <= tolerance;) consider(oj);
    for (std::size_t oj = oi + 1; oj < n && key[order[oj]] - key[i] <= tolerance; ++oj) consider(oj);
  }
  return out;
}

// --- families --------------------------------------------------------------------------------
FamilySet FamilySet::select(const std::string& names) {
  FamilySet set;
  if (names.empty() || names == "all") {
    set.families = all_families();
    return set;
  }
  std::vector<std::string> wanted;
  std::stringstream ss(names);
  for (std::string n; std::getline(ss, n, ',');) {
    n.erase(0, n.find_first_not_of(" \t"));
    n.erase(n.find_last_not_of(" \t") + 1);
    if (n.empty()) continue;
    if (!find_family(n)) {
      std::string known;
      for (const auto& f : all_families()) known += (known.empty() ? "" : ", ") + f.name;
      throw Error("unknown family '" + n + "' (families: " + known + ")", "", "--families");
    }
    if (std::find(wanted.begin(), wanted.end(), n) == wanted.end()) wanted.push_back(n);
  }
  if (wanted.empty()) throw Error("no family selected", "", "--families");
  for (const auto& f : all_families())  // catalogue order, whatever the order given
    if (std::find(wanted.begin(), wanted.end(), f.name) != wanted.end()) set.families.push_back(f);
  return set;
}

void FamilySet::set_range(const std::string& family, const std::string& param, double lo, double hi,
                          const std::string& file) {
  const std::string field = family + "." + param;
  auto it = std::find_if(families.begin(), families.end(), [&](const Family& f) { return f.name == family; });
  if (it == families.end()) {
    const Family* known = find_family(family);
    if (!known) throw Error("unknown family '" + family + "'", file, field);
    FamilySet other;  // a family not selected: checked all the same, then ignored
    other.families = {*known};
    other.set_range(family, param, lo, hi, file);
    return;
  }
  if (param == "weight") {
    if (!(lo >= 0.0) || !std::isfinite(lo) || lo != hi)
      throw Error("family '" + family + "': weight must be one number >= 0", file, field);
    it->weight = lo;
    return;
  }
  auto spec = std::find_if(it->params.begin(), it->params.end(), [&](const ParamSpec& s) { return s.name == param; });
  if (spec == it->params.end()) {
    std::string known;
    for (const auto& s : it->params) known += (known.empty() ? "" : ", ") + s.name;
    throw Error("family '" + family + "' has no parameter '" + param + "' (parameters: " + known + ", weight)", file, field);
  }
  ParamSpec changed = *spec;
  changed.lo = lo;
  changed.hi = hi;
  check_spec(*it, changed, file);
  *spec = changed;
}

void FamilySet::validate(const std::string& file) const {
  if (families.empty()) throw Error("no family selected", file, "families");
  double total = 0.0;
  for (const auto& f : families) {
    for (const auto& s : f.params) check_spec(f, s, file);
    total += f.weight;
  }
  if (!(total > 0.0)) throw Error("every selected family has weight 0", file, "weight");
}

// --- the catalogue ---------------------------------------------------------------------------
CatalogueReport generate_catalogue(const fs::path& out, const CatalogueSettings& s) {
  const auto t0 = std::chrono::steady_clock::now();
  if (s.count < 1 || s.count > 100000)
    throw Error("count must lie in 1..100000, not " + std::to_string(s.count), "", "--count");
  if (!(s.tolerance >= 0.0)) throw Error("tolerance must be >= 0", "", "tolerance");
  s.families.validate();
  const auto& families = s.families.families;
  if (out.empty()) throw Error("no output folder given", "", "--out");
  std::error_code ec;
  if (fs::exists(out, ec)) {
    if (!fs::is_directory(out, ec)) throw Error("output exists and is not a folder", out.string());
    if (!s.force) throw Error("output folder exists (use --force to replace it)", out.string());
  }
  const fs::path parent = out.has_parent_path() ? out.parent_path() : fs::path(".");
  if (!fs::is_directory(parent, ec)) throw Error("parent folder does not exist", out.string());

  // Everything goes into a temporary sibling folder, renamed onto `out` when complete.
  remove_stale_temporaries(out);
  fs::path tmp = out;
  tmp += ".tmp-" + std::to_string(::getpid());
  fs::remove_all(tmp, ec);
  FolderGuard guard{tmp};
  fs::create_directories(tmp / "meshes", ec);
  if (ec) throw Error("cannot create the output folder: " + ec.message(), tmp.string());

  const std::size_t n = s.count;
  const auto family_of = assign_families(families, n);
  CatalogueReport report;
  report.objects.resize(n);
  std::vector<int> attempt(n, 0);
  std::vector<std::string> errors(n);
  std::atomic<std::size_t> done{0};

  auto make = [&](std::size_t i) {
    const Family& fam = families[family_of[i]];
    CatalogueObject& o = report.objects[i];
    o.name = width_name(fam.name, i, n);
    o.family = fam.name;
    Rng rng(s.seed, kStream, i, static_cast<std::uint64_t>(attempt[i]));
    o.params = draw_params(fam, rng);
    o.attempts = attempt[i] + 1;
    const BuiltObject b = build_object(fam, o.params, s.build);
    o.voxel = b.voxel;
    o.remeshed = b.remeshed;
    o.extent = b.extent;
    o.volume = b.check.volume;
    o.vertices = b.mesh.vertices.size();
    o.triangles = b.mesh.faces.size();
    o.signature = shape_signature(b.mesh);
    const std::string comment = std::string("touchstone ") + kGeneratorVersion + " " + o.name + ": " + o.params.text();
    const std::string bytes = io::ply_bytes(b.mesh, comment);
    o.bytes = bytes.size();
    const fs::path file = tmp / "meshes" / (o.name + ".ply");
    std::ofstream f(file, std::ios::binary | std::ios::trunc);
    f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    f.close();
    if (!f) throw Error("cannot write the mesh file (disk full?)", file.string());
  };
  auto run = [&](const std::vector<std::size_t>& todo) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, todo.size(), 1), [&](const tbb::blocked_range<std::size_t>& r) {
      for (std::size_t k = r.begin(); k != r.end(); ++k) {
        const std::size_t i = todo[k];
        try {
          make(i);
        } catch (const std::exception& e) {
          errors[i] = e.what();
        }
        if (s.progress) s.progress(++done, n);
      }
    });
    for (std::size_t i : todo)  // the first failure in index order, whatever the scheduling
      if (!errors[i].empty()) throw Error(report.objects[i].name + ": " + errors[i]);
  };

  std::vector<std::size_t> todo(n);
  std::iota(todo.begin(), todo.end(), 0);
  run(todo);
  for (;;) {
    std::vector<Signature> sigs(n);
    for (std::size_t i = 0; i < n; ++i) sigs[i] = report.objects[i].signature;
    const auto twin = congruent_to_earlier(sigs, s.tolerance);
    todo.clear();
    for (std::size_t i = 0; i < n; ++i)
      if (twin[i] >= 0) {
        if (attempt[i] + 1 >= s.max_attempts)
          throw Error(report.objects[i].name + ": still congruent to " + report.objects[twin[i]].name + " after " +
                      std::to_string(s.max_attempts) + " draws: widen the family's ranges");
        ++attempt[i];
        todo.push_back(i);
      }
    if (todo.empty()) break;
    report.redraws += todo.size();
    done = n - todo.size();
    run(todo);
  }

  std::vector<Signature> sigs(n);
  for (std::size_t i = 0; i < n; ++i) sigs[i] = report.objects[i].signature;
  report.closest = closest_pairs(sigs, s.report_pairs);

  // manifest.tsv, catalogue.tsv, closest_pairs.tsv.
  std::map<std::string, std::size_t> per_family;
  for (const auto& o : report.objects) ++per_family[o.family];
  std::string family_list;
  for (const auto& f : families) family_list += (family_list.empty() ? "" : ",") + f.name;
  char head[512];
  std::snprintf(head, sizeof head, "# touchstone catalogue: count=%zu seed=%llu generator=%s families=%s\n", n,
                static_cast<unsigned long long>(s.seed), kGeneratorVersion, family_list.c_str());
  std::string manifest = head;
  manifest += "# source\tpath\tname\tunits (meshes in metres at true size; see catalogue.tsv)\n";
  std::string cat = head;
  cat += "name\tfamily\tattempts\tremeshed\tvoxel_m\textent_m\tvolume_m3\tvertices\ttriangles\tparameters\n";
  for (const auto& o : report.objects) {
    manifest += "catalogue\tmeshes/" + o.name + ".ply\t" + o.name + "\tm\n";
    char nums[256];
    std::snprintf(nums, sizeof nums, "%d\t%d\t%.6g\t%.6g\t%.6g\t%zu\t%zu", o.attempts, o.remeshed, o.voxel, o.extent, o.volume, o.vertices,
                  o.triangles);
    cat += o.name + "\t" + o.family + "\t" + nums + "\t" + o.params.text() + "\n";
    report.bytes += o.bytes;
  }
  std::string pairs = head;
  pairs += "rank\ta\tb\tfamily_a\tfamily_b\tsignature_distance\n";
  for (std::size_t r = 0; r < report.closest.size(); ++r) {
    const auto& p = report.closest[r];
    char d[64];
    std::snprintf(d, sizeof d, "%.6g", p.distance);
    pairs += std::to_string(r + 1) + "\t" + report.objects[p.a].name + "\t" + report.objects[p.b].name + "\t" +
             report.objects[p.a].family + "\t" + report.objects[p.b].family + "\t" + d + "\n";
  }
  write_text_file(tmp / "manifest.tsv", manifest);
  write_text_file(tmp / "catalogue.tsv", cat);
  write_text_file(tmp / "closest_pairs.tsv", pairs);

  // Into place: the old folder (with --force) is removed only after the new one is complete.
  fs::path old;
  if (fs::exists(out, ec)) {
    old = out;
    old += ".old-" + std::to_string(::getpid());
    fs::remove_all(old, ec);
    fs::rename(out, old, ec);
    if (ec) throw Error("cannot move the existing folder aside: " + ec.message(), out.string());
  }
  fs::rename(tmp, out, ec);
  if (ec) {
    if (!old.empty()) fs::rename(old, out);
    throw Error("cannot move the catalogue into place: " + ec.message(), out.string());
  }
  guard.path.clear();
  if (!old.empty()) fs::remove_all(old, ec);
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return report;
}

}  // namespace ts::catalogue
