#include "io/db_store.hpp"

#include "io/atomic_file.hpp"
#include "io/h5.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <optional>
#include <set>

namespace ts::io {

namespace {

static_assert(sizeof(Vec3) == 3 * sizeof(double), "Vec3 arrays are written as [n,3] doubles");
static_assert(sizeof(Eigen::Vector3i) == 3 * sizeof(std::int32_t), "faces are written as [n,3] int32");
static_assert(sizeof(std::array<std::int32_t, 3>) == 3 * sizeof(std::int32_t));

// --- build parameters ------------------------------------------------------------------------
// One table per settings struct, so writing, reading and `db info` list the same fields.
// The size checks below fail to compile when a settings struct gains (or loses) a field: add it
// to its table (and to io/FORMAT_DB.md) so that every build parameter is stored.
static_assert(sizeof(ScanSettings) == 88,  // 8 doubles, 5 ints, padding
              "ScanSettings changed: update scan_fields() in io/db_store.cpp");
static_assert(sizeof(FpfhSettings) == 2 * sizeof(double),
              "FpfhSettings changed: update fpfh_fields() in io/db_store.cpp");
static_assert(sizeof(DistanceFieldSettings) == 32,  // 3 doubles, 1 int, padding
              "DistanceFieldSettings changed: update field_fields() in io/db_store.cpp");
/// A stored build parameter: its name, its member, and the range set_setting_value takes (`db
/// build`'s flags' checks; for the parameters without a flag, what the scanner can use: counts
/// at least 1, angles in (0, 90] degrees). Lengths are positive: (0, inf).
template <class S>
struct Field {
  const char* name;
  double S::*real = nullptr;
  int S::*integer = nullptr;
  double lo = 0.0, hi = std::numeric_limits<double>::infinity();
  bool lo_open = true;
};

const std::vector<Field<ScanSettings>>& scan_fields() {
  static const std::vector<Field<ScanSettings>> f = {
      {"fine_spacing", &ScanSettings::fine_spacing},
      {"coarse_voxel", &ScanSettings::coarse_voxel},
      {"ray_pitch", &ScanSettings::ray_pitch},
      {"max_views", nullptr, &ScanSettings::max_views, 1, 100000, false},
      {"candidate_views", nullptr, &ScanSettings::candidate_views, 1, 100000, false},
      {"target_coverage", &ScanSettings::target_coverage, nullptr, 0, 1, false},
      {"random_every", nullptr, &ScanSettings::random_every, 1, 100000, false},
      {"stall_views", nullptr, &ScanSettings::stall_views, 1, 100000, false},
      {"min_gain", &ScanSettings::min_gain, nullptr, 0, 1, false},
      {"coverage_radius", &ScanSettings::coverage_radius},
      {"max_incidence_deg", &ScanSettings::max_incidence_deg, nullptr, 0, 90},
      {"grazing_incidence_deg", &ScanSettings::grazing_incidence_deg, nullptr, 0, 90},
      {"coverage_samples", nullptr, &ScanSettings::coverage_samples, 1, 1e7, false}};
  return f;
}
const std::vector<Field<FpfhSettings>>& fpfh_fields() {
  static const std::vector<Field<FpfhSettings>> f = {{"normal_radius", &FpfhSettings::normal_radius},
                                                     {"feature_radius", &FpfhSettings::feature_radius}};
  return f;
}
const std::vector<Field<DistanceFieldSettings>>& field_fields() {
  static const std::vector<Field<DistanceFieldSettings>> f = {
      {"fine_voxel", &DistanceFieldSettings::fine_voxel},
      {"fine_band_voxels", nullptr, &DistanceFieldSettings::fine_band_voxels, 1, 1000, false},
      {"coarse_voxel", &DistanceFieldSettings::coarse_voxel},
      {"coarse_margin", &DistanceFieldSettings::coarse_margin, nullptr, 0, std::numeric_limits<double>::infinity(), false}};
  return f;
}

template <class S>
void write_fields(h5::Group g, const S& s, const std::vector<Field<S>>& fields) {
  for (const auto& f : fields) {
    if (f.real) g.set_attribute(f.name, s.*f.real);
    else g.set_attribute(f.name, static_cast<std::int64_t>(s.*f.integer));
  }
}

template <class S>
void read_fields(const h5::Group& g, S& s, const std::vector<Field<S>>& fields) {
  for (const auto& f : fields) {
    if (f.real) {
      s.*f.real = g.double_attribute(f.name);
      if (!std::isfinite(s.*f.real))
        throw Error("parameter is not a finite number", g.file(), g.path() + "@" + f.name);
    } else {
      s.*f.integer = static_cast<int>(g.int_attribute(f.name));
    }
  }
}

void write_params(h5::Group root, const DatabaseSettings& s, std::uint64_t seed) {
  auto p = root.create_group("params");
  p.set_attribute("max_extent", s.max_extent);
  p.set_attribute("scale", std::string(to_string(s.scale)));
  p.set_attribute("descriptor", descriptor_name(s.descriptor));
  p.set_attribute("seed", static_cast<std::int64_t>(seed));
  write_fields(p.create_group("scan"), s.scan, scan_fields());
  write_fields(p.create_group("fpfh"), s.fpfh, fpfh_fields());
  write_fields(p.create_group("field"), s.field, field_fields());
}

// --- arrays ----------------------------------------------------------------------------------
void write_vec3(h5::Group g, const std::string& name, const std::vector<Vec3>& v, const h5::Storage& st) {
  g.write(name, v.empty() ? nullptr : v.data()->data(), {v.size(), 3}, st);
}

std::vector<Vec3> read_vec3(const h5::Group& g, const std::string& name, std::size_t n);

/// PREFIX/points and PREFIX/normals, n rows each.
PointCloud read_cloud(const h5::Group& g, const std::string& prefix, std::size_t n) {
  PointCloud out;
  out.points = read_vec3(g, prefix + "/points", n);
  out.normals = read_vec3(g, prefix + "/normals", n);
  return out;
}

std::vector<Vec3> read_vec3(const h5::Group& g, const std::string& name, std::size_t n) {
  const auto raw = g.read<double>(name, {static_cast<std::int64_t>(n), 3});
  std::vector<Vec3> out(n);
  for (std::size_t i = 0; i < n; ++i) {
    out[i] = Vec3(raw[3 * i], raw[3 * i + 1], raw[3 * i + 2]);
    if (!finite(out[i]))
      throw Error("non-finite value in row " + std::to_string(i), g.file(), g.child_path(name));
  }
  return out;
}

std::int64_t count_attribute(const h5::Group& g, const std::string& name) {
  const auto v = g.int_attribute(name);
  if (v < 0) throw Error("negative count", g.file(), g.path() + "@" + name);
  return v;
}

Vec3 vec3_attribute(const h5::Group& g, const std::string& name) {
  const auto v = g.doubles_attribute(name, 3);
  const Vec3 out(v[0], v[1], v[2]);
  if (!finite(out)) throw Error("non-finite value", g.file(), g.path() + "@" + name);
  return out;
}

/// The stored form of schema 1 (read only).
SparseGrid read_sparse(const h5::Group& g, const std::string& prefix) {
  SparseGrid grid;
  grid.voxel = g.double_attribute(prefix + "_voxel");
  if (!(grid.voxel > 0.0) || !std::isfinite(grid.voxel))
    throw Error("voxel size must be positive", g.file(), g.path() + "@" + prefix + "_voxel");
  h5::Shape shape;
  const auto ijk = g.read<std::int32_t>(prefix + "_ijk", {h5::kAny, 3}, &shape);
  grid.value = g.read<float>(prefix + "_value", {static_cast<std::int64_t>(shape[0])});
  grid.ijk.resize(shape[0]);
  for (std::size_t i = 0; i < grid.ijk.size(); ++i) grid.ijk[i] = {ijk[3 * i], ijk[3 * i + 1], ijk[3 * i + 2]};
  for (std::size_t i = 0; i < grid.value.size(); ++i)
    if (!std::isfinite(grid.value[i]))
      throw Error("non-finite value in row " + std::to_string(i), g.file(), g.child_path(prefix + "_value"));
  return grid;
}

void write_compact(h5::Group g, const std::string& prefix, const CompactGrid& grid, const h5::Storage& st,
                   const std::string& file) {
  if (grid.values.size() != grid.bricks.size() * CompactGrid::kBrickVoxels)
    throw Error("distance field has " + std::to_string(grid.bricks.size()) + " bricks but " +
                    std::to_string(grid.values.size()) + " values",
                file, g.child_path(prefix));
  g.write(prefix + "_bricks", grid.bricks.empty() ? nullptr : grid.bricks.data()->data(), {grid.bricks.size(), 3}, st);
  g.write(prefix + "_values", grid.values.data(),
          {grid.bricks.size(), static_cast<std::uint64_t>(CompactGrid::kBrickVoxels)}, st);
  g.set_attribute(prefix + "_voxel", grid.voxel);
  g.set_attribute(prefix + "_quantum", grid.quantum);
}

/// The stored form of schema 2; the level's own checks (order, sizes, span) run in
/// DistanceField::from_compact.
CompactGrid read_compact(const h5::Group& g, const std::string& prefix) {
  CompactGrid grid;
  grid.voxel = g.double_attribute(prefix + "_voxel");
  if (!(grid.voxel > 0.0) || !std::isfinite(grid.voxel))
    throw Error("voxel size must be positive", g.file(), g.path() + "@" + prefix + "_voxel");
  grid.quantum = g.double_attribute(prefix + "_quantum");
  if (!(grid.quantum > 0.0) || !std::isfinite(grid.quantum))
    throw Error("quantum must be positive", g.file(), g.path() + "@" + prefix + "_quantum");
  h5::Shape shape;
  const auto bricks = g.read<std::int32_t>(prefix + "_bricks", {h5::kAny, 3}, &shape);
  grid.values = g.read<std::int16_t>(prefix + "_values",
                                     {static_cast<std::int64_t>(shape[0]), CompactGrid::kBrickVoxels});
  grid.bricks.resize(shape[0]);
  for (std::size_t i = 0; i < grid.bricks.size(); ++i)
    grid.bricks[i] = {bricks[3 * i], bricks[3 * i + 1], bricks[3 * i + 2]};
  return grid;
}

void write_object(h5::Group objects, const StoredObject& stored, const DbWriteSettings& w, const std::string& file,
                  int feature_dim) {
  if (!stored.object) throw Error("no object to write", file);
  const BuiltObject& o = *stored.object;
  const ObjectInfo& info = o.info;
  const std::string where = "/objects/" + info.name;
  check_object_name(info.name, file, "/objects");
  // Consistency of what we are about to store.
  if (!o.fine.has_normals() && !o.fine.empty()) throw Error("fine cloud has no normals", file, where);
  if (!o.features.coarse.has_normals() && !o.features.coarse.empty())
    throw Error("coarse cloud has no normals", file, where);
  if (o.features.features.size() != o.features.coarse.size())
    throw Error("object has " + std::to_string(o.features.features.size()) + " features for " +
                    std::to_string(o.features.coarse.size()) + " coarse points",
                file, where);
  if (o.features.features.dim() != feature_dim)
    throw Error("object has features of " + std::to_string(o.features.features.dim()) +
                    " values per row; the database's descriptor has " + std::to_string(feature_dim),
                file, where + "/features");
  const h5::Storage st{.deflate = w.deflate};

  auto g = objects.create_group(info.name);
  g.set_attribute("name", info.name);
  g.set_attribute("source", info.source);
  g.set_attribute("mesh_sha256", info.mesh_sha256);
  g.set_attribute("scale", info.scale);
  g.set_attribute("centre", std::vector<double>{info.centre.x(), info.centre.y(), info.centre.z()});
  g.set_attribute("extent", std::vector<double>{info.extent.x(), info.extent.y(), info.extent.z()});
  g.set_attribute("closed", static_cast<std::int64_t>(info.closed ? 1 : 0));
  g.set_attribute("coverage", info.coverage);
  g.set_attribute("seed", static_cast<std::int64_t>(stored.seed));
  g.set_attribute("fine_points", static_cast<std::int64_t>(o.fine.size()));
  g.set_attribute("coarse_points", static_cast<std::int64_t>(o.features.coarse.size()));
  g.set_attribute("mesh_vertices", static_cast<std::int64_t>(o.mesh.vertices.size()));
  g.set_attribute("mesh_faces", static_cast<std::int64_t>(o.mesh.faces.size()));

  write_vec3(g, "mesh/vertices", o.mesh.vertices, st);
  g.write("mesh/faces", o.mesh.faces.empty() ? nullptr : o.mesh.faces.data()->data(), {o.mesh.faces.size(), 3}, st);
  write_vec3(g, "fine/points", o.fine.points, st);
  write_vec3(g, "fine/normals", o.fine.normals, st);
  write_vec3(g, "coarse/points", o.features.coarse.points, st);
  write_vec3(g, "coarse/normals", o.features.coarse.normals, st);
  g.write("features", o.features.features.empty() ? nullptr : o.features.features.values().data(),
          {o.features.features.size(), static_cast<std::uint64_t>(feature_dim)}, st);

  auto field = g.create_group("field");
  field.set_attribute("signed", static_cast<std::int64_t>(o.field.is_signed() ? 1 : 0));
  field.set_attribute("coarse_margin", o.field.coarse_margin());
  write_compact(field, "fine", o.field.fine_compact(), st, file);
  write_compact(field, "coarse", o.field.coarse_compact(), st, file);
}

// --- congruence ------------------------------------------------------------------------------
constexpr int kSignatureColumns = 4;   // size, spread[0..2]

/// Pair row k as the reader accepts it and the writer writes it (so that no database is written
/// that cannot be read back): objects a < b < objects, a non-negative distance, a rigid motion
/// (finite, its 3 x 3 orthogonal to 1e-6).
void check_pair(std::int64_t a, std::int64_t b, const CongruentPair& p, std::size_t k, std::size_t objects,
                const std::string& file, const h5::Group& g) {
  if (a < 0 || b <= a || b >= static_cast<std::int64_t>(objects))
    throw Error("row " + std::to_string(k) + " is not a pair of objects a < b < " + std::to_string(objects), file,
                g.child_path("pairs"));
  if (!(p.distance >= 0.0) || !std::isfinite(p.distance))
    throw Error("row " + std::to_string(k) + " is not a non-negative number", file, g.child_path("distance"));
  if (!p.linear.allFinite() || !finite(p.translation) || (p.linear * p.linear.transpose() - Mat3::Identity()).norm() > 1e-6)
    throw Error("row " + std::to_string(k) + " is not a rigid motion (orthogonal 3 x 3 and a finite translation)", file,
                g.child_path("motion"));
}

void write_congruence_group(h5::Group root, const CongruenceRecord& c, std::size_t objects, const std::string& file) {
  if (c.signatures.size() != objects)
    throw Error("congruence record has " + std::to_string(c.signatures.size()) + " signatures for " +
                    std::to_string(objects) + " objects",
                file, "/congruence/signatures");
  auto g = root.create_group("congruence");
  g.set_attribute("tolerance", c.settings.tolerance);
  g.set_attribute("samples", static_cast<std::int64_t>(c.settings.samples));
  g.set_attribute("seed", static_cast<std::int64_t>(c.settings.seed));
  std::vector<double> sig;
  for (const auto& x : c.signatures) sig.insert(sig.end(), {x.size, x.spread[0], x.spread[1], x.spread[2]});
  g.write("signatures", sig.data(), {c.signatures.size(), static_cast<std::uint64_t>(kSignatureColumns)});
  std::vector<std::int64_t> pairs, kind;
  std::vector<double> distance, motion;
  for (std::size_t k = 0; k < c.pairs.size(); ++k) {
    const auto& p = c.pairs[k];
    check_pair(p.a, p.b, p, k, objects, file, g);
    pairs.insert(pairs.end(), {static_cast<std::int64_t>(p.a), static_cast<std::int64_t>(p.b)});
    kind.push_back(static_cast<std::int64_t>(p.kind));
    distance.push_back(p.distance);
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) motion.push_back(p.linear(r, k));
    for (int r = 0; r < 3; ++r) motion.push_back(p.translation[r]);
  }
  g.write("pairs", pairs.data(), {c.pairs.size(), 2});
  g.write("kind", kind);
  g.write("distance", distance);
  g.write("motion", motion.data(), {c.pairs.size(), 12});
}

CongruenceRecord read_congruence_group(const h5::Group& root, std::size_t objects) {
  const auto g = root.open_group("congruence");
  const std::string& file = g.file();
  CongruenceRecord c;
  c.settings.tolerance = g.double_attribute("tolerance");
  if (!(c.settings.tolerance > 0.0) || !std::isfinite(c.settings.tolerance))
    throw Error("congruence tolerance must be a positive number", file, g.path() + "@tolerance");
  const auto samples = g.int_attribute("samples");
  if (samples < 1) throw Error("congruence samples must be positive", file, g.path() + "@samples");
  c.settings.samples = static_cast<std::size_t>(samples);
  c.settings.seed = static_cast<std::uint64_t>(g.int_attribute("seed"));
  const auto sig = g.read<double>("signatures", {static_cast<std::int64_t>(objects), kSignatureColumns});
  for (std::size_t i = 0; i < objects; ++i) {
    ShapeSignature x;
    x.size = sig[kSignatureColumns * i];
    for (std::size_t k = 0; k < 3; ++k) x.spread[k] = sig[kSignatureColumns * i + 1 + k];
    if (!std::isfinite(x.size) || !std::isfinite(x.spread[0]) || !std::isfinite(x.spread[1]) || !std::isfinite(x.spread[2]))
      throw Error("non-finite value in row " + std::to_string(i), file, g.child_path("signatures"));
    c.signatures.push_back(x);
  }
  h5::Shape shape;
  const auto pairs = g.read<std::int64_t>("pairs", {h5::kAny, 2}, &shape);
  const auto rows = static_cast<std::int64_t>(shape[0]);
  const auto kind = g.read<std::int64_t>("kind", {rows});
  const auto distance = g.read<double>("distance", {rows});
  const auto motion = g.read<double>("motion", {rows, 12});
  for (std::size_t k = 0; k < shape[0]; ++k) {
    const std::int64_t a = pairs[2 * k], b = pairs[2 * k + 1];
    if (kind[k] != static_cast<std::int64_t>(Congruence::congruent) && kind[k] != static_cast<std::int64_t>(Congruence::mirror))
      throw Error("row " + std::to_string(k) + " is neither 1 (congruent) nor 2 (mirror image)", file, g.child_path("kind"));
    CongruentPair p{static_cast<std::uint32_t>(a), static_cast<std::uint32_t>(b), static_cast<Congruence>(kind[k]), distance[k]};
    for (int r = 0; r < 3; ++r) {
      for (int q = 0; q < 3; ++q) p.linear(r, q) = motion[12 * k + 3 * r + q];
      p.translation[r] = motion[12 * k + 9 + r];
    }
    check_pair(a, b, p, k, objects, file, g);
    c.pairs.push_back(p);
  }
  return c;
}

void check_unique(const std::vector<StoredObject>& objects, std::set<std::string> names, const std::string& file) {
  for (const auto& s : objects) {
    if (!s.object) throw Error("no object to write", file);
    if (!names.insert(s.object->info.name).second)
      throw Error("object '" + s.object->info.name + "' already exists in the database", file);
  }
}

/// The descriptor a database was built with: /params@descriptor, or FPFH for databases written
/// before the attribute existed (FPFH was the only one).
Descriptor stored_descriptor(const h5::Group& root) {
  if (!root.has_group("params")) return Descriptor::fpfh;
  const auto params = root.open_group("params");
  if (!params.has_attribute("descriptor")) return Descriptor::fpfh;
  try {
    return parse_descriptor(params.string_attribute("descriptor"));
  } catch (const Error& e) {
    throw Error(e.what(), root.file(), "/params@descriptor");
  }
}

/// Root checks shared by the reader and append: format, schema, feature size (that of the
/// stored descriptor). `writing`: new objects are to be appended (they are written in this
/// program's schema, so the file must already have it); reading takes every schema since 1.
/// Returns the values per feature.
int check_root(const h5::Group& root, bool writing) {
  if (!root.has_attribute("schema_version"))
    throw Error("not a Touchstone object database (no schema_version attribute)", root.file(), "/");
  if (!root.has_attribute("format") || root.string_attribute("format") != kDbFormatName)
    throw Error("not a Touchstone object database (format attribute is not '" + std::string(kDbFormatName) + "')",
                root.file(), "/@format");
  const auto v = root.int_attribute("schema_version");
  if (v < 1 || v > kDbSchemaVersion)
    throw Error("database schema version " + std::to_string(v) + " is not supported (this program reads versions 1 to " +
                    std::to_string(kDbSchemaVersion) + "); rebuild the database",
                root.file(), "/@schema_version");
  if (writing && v != kDbSchemaVersion)
    throw Error("a database of schema version " + std::to_string(v) + " cannot take new objects (this program writes version " +
                    std::to_string(kDbSchemaVersion) + "); rebuild the database",
                root.file(), "/@schema_version");
  const Descriptor d = stored_descriptor(root);
  const int dim = descriptor_dim(d);
  if (root.int_attribute("feature_dim") != dim)
    throw Error("features have " + std::to_string(root.int_attribute("feature_dim")) + " bins, expected " +
                    std::to_string(dim) + " (" + descriptor_name(d) + ")",
                root.file(), "/@feature_dim");
  return dim;
}

}  // namespace

namespace {
template <class S>
void append_values(std::vector<SettingValue>& out, const char* group, const S& s, const std::vector<Field<S>>& fields) {
  for (const auto& f : fields)
    out.push_back({group, f.name, f.real ? s.*f.real : static_cast<double>(s.*f.integer), f.real == nullptr});
}
}  // namespace

namespace {
/// `value` for `key`, or an Error naming it: a finite number in [lo, hi] ((lo, hi] when lo_open),
/// whole for an integer.
void check_setting(double value, double lo, double hi, bool lo_open, bool integer, const std::string& key,
                   const std::string& origin) {
  char shown[64];
  std::snprintf(shown, sizeof shown, "%.17g", value);
  const bool below = lo_open ? !(value > lo) : !(value >= lo);
  if (!std::isfinite(value) || below || value > hi) {
    char bounds[96];
    std::snprintf(bounds, sizeof bounds, "%s%g, %s%s", lo_open ? "(" : "[", lo,
                  std::isinf(hi) ? "inf" : std::to_string(static_cast<long long>(hi)).c_str(), std::isinf(hi) ? ")" : "]");
    throw Error(std::string("expected a finite number in ") + bounds + ", got " + shown, origin, key);
  }
  if (integer && value != std::floor(value)) throw Error(std::string("expected a whole number, got ") + shown, origin, key);
}

template <class S>
bool set_field(S& s, const std::vector<Field<S>>& fields, const std::string& name, double value,
               const std::string& key, const std::string& origin) {
  for (const auto& f : fields) {
    if (name != f.name) continue;
    check_setting(value, f.lo, f.hi, f.lo_open, f.integer != nullptr, key, origin);
    if (f.real) s.*f.real = value;
    else s.*f.integer = static_cast<int>(value);
    return true;
  }
  return false;
}
}  // namespace

void set_setting_value(DatabaseSettings& s, const std::string& key, double value, const std::string& origin) {
  const auto dot = key.find('.');
  const std::string group = dot == std::string::npos ? "" : key.substr(0, dot);
  const std::string name = dot == std::string::npos ? key : key.substr(dot + 1);
  bool known = false;
  if (key == "max_extent") {
    check_setting(value, 0.0, std::numeric_limits<double>::infinity(), true, false, key, origin);
    s.max_extent = value;
    known = true;
  } else if (group == "scan") {
    known = set_field(s.scan, scan_fields(), name, value, key, origin);
  } else if (group == "fpfh") {
    known = set_field(s.fpfh, fpfh_fields(), name, value, key, origin);
  } else if (group == "field") {
    known = set_field(s.field, field_fields(), name, value, key, origin);
  }
  if (!known) {
    std::string names;
    for (const auto& v : settings_values(s)) names += (v.group.empty() ? v.name : v.group + "." + v.name) + ", ";
    throw Error("unknown build parameter (known: " + names + "descriptor)", origin, key);
  }
}

std::vector<SettingValue> settings_values(const DatabaseSettings& s) {
  std::vector<SettingValue> out{{"", "max_extent", s.max_extent, false}};
  append_values(out, "scan", s.scan, scan_fields());
  append_values(out, "fpfh", s.fpfh, fpfh_fields());
  append_values(out, "field", s.field, field_fields());
  return out;
}

std::vector<std::vector<std::size_t>> CongruenceRecord::classes() const {
  return congruence_classes(signatures.size(), pairs);
}

std::vector<CongruentPair> CongruenceRecord::mirrors() const {
  std::vector<CongruentPair> out;
  for (const auto& p : pairs)
    if (p.kind == Congruence::mirror) out.push_back(p);
  return out;
}

std::vector<std::size_t> CongruenceRecord::class_of(std::size_t i) const {
  for (auto& members : classes())
    if (std::find(members.begin(), members.end(), i) != members.end()) return members;
  return {i};
}

bool CongruenceRecord::same_class(std::size_t i, std::size_t j) const {
  if (i == j) return true;
  const auto members = class_of(i);
  return std::find(members.begin(), members.end(), j) != members.end();
}

std::optional<Eigen::Affine3d> CongruenceRecord::motion(std::size_t from, std::size_t to) const {
  for (const auto& p : pairs) {
    if (p.kind != Congruence::congruent) continue;
    Eigen::Affine3d T = Eigen::Affine3d::Identity();
    T.linear() = p.linear;
    T.translation() = p.translation;
    if (p.a == from && p.b == to) return T;
    if (p.a == to && p.b == from) return T.inverse(Eigen::Isometry);
  }
  if (from == to) return Eigen::Affine3d::Identity();
  return std::nullopt;
}

std::uint64_t object_seed(std::uint64_t build_seed, const std::string& name) {
  std::uint64_t h = 0xcbf29ce484222325ULL;  // FNV-1a of the name
  for (unsigned char c : name) h = (h ^ c) * 0x100000001b3ULL;
  return Rng(build_seed, h, 0x0b7ec7).next();
}

void check_object_name(const std::string& name, const std::string& file, const std::string& field) {
  auto bad = [&](const std::string& why) { throw Error("invalid object name '" + name + "': " + why, file, field); };
  if (name.empty()) bad("empty");
  if (name == "." || name == "..") bad("reserved");
  if (name.find('/') != std::string::npos) bad("contains '/'");
  for (unsigned char c : name)
    if (c < 0x20 || c == 0x7f) bad("contains a control character");
  if (name.front() == ' ' || name.back() == ' ') bad("leading or trailing blank");
}

namespace {
/// A new database's root attributes and /params.
void write_root(h5::Group& root, const DatabaseSettings& settings, std::uint64_t build_seed) {
  root.set_attribute("format", kDbFormatName);
  root.set_attribute("schema_version", kDbSchemaVersion);
  root.set_attribute("feature_dim", static_cast<std::int64_t>(descriptor_dim(settings.descriptor)));
  write_params(root, settings, build_seed);
}
}  // namespace

void write_database(const std::filesystem::path& path, const std::vector<StoredObject>& objects,
                    const DatabaseSettings& settings, std::uint64_t build_seed, const DbWriteSettings& write,
                    const CongruenceRecord* congruence) {
  const std::string file = path.string();
  check_unique(objects, {}, file);
  AtomicOutput out(path);
  {
    std::lock_guard<std::recursive_mutex> lock(h5::mutex());
    auto f = h5::File::create(out);
    auto root = f.root();
    write_root(root, settings, build_seed);
    std::vector<std::string> order;
    auto objs = root.create_group("objects");
    for (const auto& s : objects) {
      write_object(objs, s, write, file, descriptor_dim(settings.descriptor));
      order.push_back(s.object->info.name);
    }
    root.write_strings("order", order);
    if (congruence) write_congruence_group(root, *congruence, order.size(), file);
    f.close();
  }
  out.commit();
}

void merge_databases(const std::vector<std::filesystem::path>& parts, const std::filesystem::path& path,
                     const DatabaseSettings& settings, std::uint64_t build_seed, const CongruenceRecord* congruence) {
  const std::string file = path.string();
  AtomicOutput out(path);
  {
    std::lock_guard<std::recursive_mutex> lock(h5::mutex());
    auto f = h5::File::create(out);
    auto root = f.root();
    write_root(root, settings, build_seed);
    std::vector<std::string> order;
    std::set<std::string> names;
    auto objs = root.create_group("objects");
    for (const auto& part : parts) {
      auto pf = h5::File::open(part, h5::File::Access::read, part.string());
      const auto proot = pf.root();
      if (check_root(proot, true) != descriptor_dim(settings.descriptor) ||
          stored_descriptor(proot) != settings.descriptor)
        throw Error("the part was built with descriptor " + descriptor_name(stored_descriptor(proot)) + ", not " +
                        descriptor_name(settings.descriptor),
                    part.string(), "/params@descriptor");
      const auto names_in = proot.read_strings("order");
      if (names_in.size() != 1)
        throw Error("a part must hold one object, not " + std::to_string(names_in.size()), part.string(), "/order");
      if (!names.insert(names_in[0]).second)
        throw Error("object '" + names_in[0] + "' already exists", file, "/objects/" + names_in[0]);
      objs.copy_from(proot.open_group("objects"), names_in[0]);
      order.push_back(names_in[0]);
    }
    root.write_strings("order", order);
    if (congruence) write_congruence_group(root, *congruence, order.size(), file);
    f.close();
  }
  out.commit();
}

namespace {
/// Edit a copy of the database at `path` (under the HDF5 lock) that replaces it when `edit`
/// succeeded; any failure leaves the database as it was.
void edit_copy(const std::filesystem::path& path, const std::string& what, const std::function<void(h5::Group&)>& edit) {
  const std::string file = path.string();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) throw Error("database does not exist", file);
  AtomicOutput out(path);
  std::filesystem::copy_file(path, out.temp_path(), std::filesystem::copy_options::overwrite_existing, ec);
  if (ec) throw Error("cannot copy the database to " + what + ": " + ec.message(), file);
  {
    std::lock_guard<std::recursive_mutex> lock(h5::mutex());
    auto f = h5::File::open(out.temp_path(), h5::File::Access::read_write, file);
    auto root = f.root();
    edit(root);
    f.close();
  }
  out.commit();
}

void replace_congruence_group(h5::Group& root, const CongruenceRecord& congruence, std::size_t objects) {
  if (root.has_group("congruence")) root.remove("congruence");
  write_congruence_group(root, congruence, objects, root.file());
}
}  // namespace

void append_to_database(const std::filesystem::path& path, const std::vector<StoredObject>& objects,
                        const DbWriteSettings& write, const CongruenceRecord* congruence) {
  const std::string file = path.string();
  edit_copy(path, "append to it", [&](h5::Group& root) {
    const int dim = check_root(root, true);
    auto order = root.read_strings("order");
    check_unique(objects, std::set<std::string>(order.begin(), order.end()), file);
    auto objs = root.open_group("objects");
    for (const auto& s : objects) {
      write_object(objs, s, write, file, dim);
      order.push_back(s.object->info.name);
    }
    root.remove("order");
    root.write_strings("order", order);
    if (congruence) replace_congruence_group(root, *congruence, order.size());
  });
}

void write_congruence(const std::filesystem::path& path, const CongruenceRecord& congruence) {
  edit_copy(path, "update it", [&](h5::Group& root) {
    check_root(root, false);
    replace_congruence_group(root, congruence, root.read_strings("order").size());
  });
}

// --- reader ----------------------------------------------------------------------------------
struct DbReader::Impl {
  std::string path;
  h5::File file;
  std::int64_t schema = 0;
  int feature_dim = kFeatureDim;
  std::uint64_t seed = 0;
  DatabaseSettings settings;
  std::vector<ObjectInfo> infos;
  std::vector<std::uint64_t> seeds;
  std::vector<std::size_t> vertices, faces;
  std::vector<h5::Group> groups;
  std::optional<CongruenceRecord> congruence;

  const h5::Group& group(std::size_t i) const {
    if (i >= groups.size())
      throw Error("object index " + std::to_string(i) + " out of range (" + std::to_string(groups.size()) +
                      " objects)",
                  path);
    return groups[i];
  }
};

DbReader::DbReader(const std::filesystem::path& path) : impl_(std::make_unique<Impl>()) {
  std::lock_guard<std::recursive_mutex> lock(h5::mutex());
  Impl& d = *impl_;
  d.path = path.string();
  d.file = h5::File::open(path, h5::File::Access::read);
  const auto root = d.file.root();
  d.feature_dim = check_root(root, false);
  d.settings.descriptor = stored_descriptor(root);
  d.schema = root.int_attribute("schema_version");

  const auto params = root.open_group("params");
  d.settings.max_extent = params.double_attribute("max_extent");
  // Databases written before `keep` existed have no scale: every object was fitted.
  if (params.has_attribute("scale"))
    d.settings.scale = parse_object_scale(params.string_attribute("scale"), d.path, "/params@scale");
  d.seed = static_cast<std::uint64_t>(params.int_attribute("seed"));
  read_fields(params.open_group("scan"), d.settings.scan, scan_fields());
  read_fields(params.open_group("fpfh"), d.settings.fpfh, fpfh_fields());
  read_fields(params.open_group("field"), d.settings.field, field_fields());

  const auto order = root.read_strings("order");
  const auto objects = root.open_group("objects");
  std::set<std::string> seen;
  for (const auto& name : order) {
    if (!seen.insert(name).second) throw Error("object '" + name + "' is listed twice", d.path, "/order");
    auto g = objects.open_group(name);
    ObjectInfo info;
    info.name = g.string_attribute("name");
    if (info.name != name)
      throw Error("object group holds the name '" + info.name + "'", d.path, g.path() + "@name");
    info.source = g.string_attribute("source");
    info.mesh_sha256 = g.string_attribute("mesh_sha256");
    info.scale = g.double_attribute("scale");
    info.centre = vec3_attribute(g, "centre");
    info.extent = vec3_attribute(g, "extent");
    info.closed = g.int_attribute("closed") != 0;
    info.coverage = g.double_attribute("coverage");
    info.fine_points = static_cast<std::size_t>(count_attribute(g, "fine_points"));
    info.coarse_points = static_cast<std::size_t>(count_attribute(g, "coarse_points"));
    d.vertices.push_back(static_cast<std::size_t>(count_attribute(g, "mesh_vertices")));
    d.faces.push_back(static_cast<std::size_t>(count_attribute(g, "mesh_faces")));
    d.seeds.push_back(static_cast<std::uint64_t>(g.int_attribute("seed")));
    d.infos.push_back(std::move(info));
    d.groups.push_back(std::move(g));
  }
  if (objects.children().size() != order.size())
    throw Error("/objects holds " + std::to_string(objects.children().size()) + " objects but /order lists " +
                    std::to_string(order.size()),
                d.path, "/order");
  // Databases written before congruence was recorded have no group: no classes known.
  if (root.has_group("congruence")) d.congruence = read_congruence_group(root, order.size());
}

DbReader::~DbReader() {
  std::lock_guard<std::recursive_mutex> lock(h5::mutex());
  impl_.reset();
}

std::size_t DbReader::size() const { return impl_->infos.size(); }
const ObjectInfo& DbReader::info(std::size_t i) const {
  impl_->group(i);
  return impl_->infos[i];
}
const DatabaseSettings& DbReader::settings() const { return impl_->settings; }
const std::string& DbReader::path() const { return impl_->path; }
std::int64_t DbReader::schema_version() const { return impl_->schema; }
int DbReader::feature_dim() const { return impl_->feature_dim; }
std::uint64_t DbReader::build_seed() const { return impl_->seed; }
std::uint64_t DbReader::object_seed(std::size_t i) const {
  impl_->group(i);
  return impl_->seeds[i];
}
std::size_t DbReader::mesh_vertices(std::size_t i) const {
  impl_->group(i);
  return impl_->vertices[i];
}
std::size_t DbReader::mesh_faces(std::size_t i) const {
  impl_->group(i);
  return impl_->faces[i];
}

const CongruenceRecord* DbReader::congruence() const {
  return impl_->congruence ? &*impl_->congruence : nullptr;
}

std::size_t DbReader::find(const std::string& name) const {
  for (std::size_t i = 0; i < size(); ++i)
    if (impl_->infos[i].name == name) return i;
  return size();
}

// The loads below take no lock of their own: each h5 call takes the HDF5 lock, and the object
// groups are opened once, with the file, so threads loading different objects inflate their
// datasets at the same time (h5::Group::read).
ObjectFeatures DbReader::load_features(std::size_t i) const {
  const auto& g = impl_->group(i);
  const std::size_t n = impl_->infos[i].coarse_points;
  ObjectFeatures out;
  out.coarse = load_coarse(i);
  const int dim = impl_->feature_dim;
  auto raw = g.read<float>("features", {static_cast<std::int64_t>(n), dim});
  for (std::size_t k = 0; k < raw.size(); ++k)
    if (!std::isfinite(raw[k]))
      throw Error("non-finite value in row " + std::to_string(k / static_cast<std::size_t>(dim)), impl_->path,
                  g.child_path("features"));
  out.features = FeatureRows(dim);
  out.features.values() = std::move(raw);
  return out;
}

PointCloud DbReader::load_coarse(std::size_t i) const {
  return read_cloud(impl_->group(i), "coarse", impl_->infos[i].coarse_points);
}

PointCloud DbReader::load_fine(std::size_t i) const {
  return read_cloud(impl_->group(i), "fine", impl_->infos[i].fine_points);
}

DistanceField DbReader::load_field(std::size_t i) const {
  SparseGrid fine, coarse;            // schema 1
  CompactGrid fine_c, coarse_c;       // schema 2
  bool is_signed = false;
  double margin = 0.0;
  std::string where;
  {
    const auto field = impl_->group(i).open_group("field");
    where = field.path();
    is_signed = field.int_attribute("signed") != 0;
    margin = field.double_attribute("coarse_margin");
    if (!(margin >= 0.0) || !std::isfinite(margin))
      throw Error("coarse margin must be a non-negative number", impl_->path, field.path() + "@coarse_margin");
    if (impl_->schema >= 2) {
      fine_c = read_compact(field, "fine");
      coarse_c = read_compact(field, "coarse");
    } else {
      fine = read_sparse(field, "fine");
      coarse = read_sparse(field, "coarse");
    }
  }
  // Building the levels needs no HDF5.
  try {
    if (impl_->schema >= 2)
      return DistanceField::from_compact(std::move(fine_c), std::move(coarse_c), is_signed, margin);
    return DistanceField::from_sparse(std::move(fine), std::move(coarse), is_signed, margin);
  } catch (const Error& e) {
    throw Error(e.message(), impl_->path, where + "/" + e.field());
  }
}

Mesh DbReader::load_mesh(std::size_t i) const {
  // No lock of its own either (see above): meshes of different objects inflate in parallel
  // (the congruence search reads thousands).
  const auto& g = impl_->group(i);
  Mesh out;
  out.vertices = read_vec3(g, "mesh/vertices", impl_->vertices[i]);
  const auto nf = impl_->faces[i];
  const auto raw = g.read<std::int32_t>("mesh/faces", {static_cast<std::int64_t>(nf), 3});
  out.faces.resize(nf);
  const auto nv = static_cast<std::int32_t>(out.vertices.size());
  for (std::size_t k = 0; k < nf; ++k) {
    out.faces[k] = Eigen::Vector3i(raw[3 * k], raw[3 * k + 1], raw[3 * k + 2]);
    for (int c = 0; c < 3; ++c)
      if (out.faces[k][c] < 0 || out.faces[k][c] >= nv)
        throw Error("face " + std::to_string(k) + " refers to a missing vertex", impl_->path,
                    g.child_path("mesh/faces"));
  }
  return out;
}

}  // namespace ts::io
