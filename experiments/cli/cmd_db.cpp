// `touchstone db build|add|info|classes|export`: the object database (docs/database.md,
// io/FORMAT_DB.md).
#include "experiments/cli/cli_common.hpp"
#include "experiments/cli/progress.hpp"

#include "datasets/db_builder.hpp"
#include "engine/core.hpp"
#include "experiments/resources.hpp"
#include "io/cloud_io.hpp"
#include "io/db_store.hpp"
#include "io/mesh_import.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>

namespace ts::cli {

namespace {

using json = nlohmann::ordered_json;

// --- shared ----------------------------------------------------------------------------------
/// The build parameters a user may set; defaults from ts::DatabaseSettings.
void add_build_parameters(CLI::App* sub, DatabaseSettings& s, int& deflate) {
  const auto positive = CLI::PositiveNumber;
  sub->add_option("--scale", s.scale,
                  "Object size: fit (every mesh scaled to --max-extent; the paper's evaluation) or keep "
                  "(each mesh's own size in metres, after its units)")
      ->transform(CLI::CheckedTransformer(std::map<std::string, ObjectScale>{{"fit", ObjectScale::fit},
                                                                              {"keep", ObjectScale::keep}}))
      ->default_str("fit");
  sub->add_option("--max-extent", s.max_extent, "Largest bounding-box side of every object under --scale fit, m")
      ->check(positive)->capture_default_str();
  sub->add_option("--fine-spacing", s.scan.fine_spacing, "Scanner: fine cloud spacing (voxel filter), m")
      ->check(positive)->capture_default_str();
  sub->add_option("--coarse-voxel", s.scan.coarse_voxel, "Scanner: coarse (feature) cloud voxel, m")
      ->check(positive)->capture_default_str();
  sub->add_option("--max-views", s.scan.max_views, "Scanner: most viewpoints per object")
      ->check(CLI::Range(1, 100000))->capture_default_str();
  sub->add_option("--ray-pitch", s.scan.ray_pitch, "Scanner: raster pitch of a view, as a fraction of --fine-spacing")
      ->check(positive)->capture_default_str();
  sub->add_option("--target-coverage", s.scan.target_coverage, "Scanner: stop at this covered area fraction")
      ->check(CLI::Range(0.0, 1.0))->capture_default_str();
  sub->add_option("--descriptor", s.descriptor,
                  "Local descriptor of the keypoints (and of every query on this database): fpfh (the "
                  "paper's choice), pfh, shot or spin (docs/experiments.md, study 13)")
      ->transform(CLI::CheckedTransformer(std::map<std::string, Descriptor>{{"fpfh", Descriptor::fpfh},
                                                                            {"pfh", Descriptor::pfh},
                                                                            {"shot", Descriptor::shot},
                                                                            {"spin", Descriptor::spin}}))
      ->default_str("fpfh");
  sub->add_option("--normal-radius", s.fpfh.normal_radius, "Normal estimation radius, m (paper: 0.007)")
      ->check(positive)->capture_default_str();
  sub->add_option("--feature-radius", s.fpfh.feature_radius, "Descriptor (feature) radius, m (paper: 0.010)")
      ->check(positive)->capture_default_str();
  sub->add_option("--field-voxel", s.field.fine_voxel, "Distance field: narrow-band voxel, m")
      ->check(positive)->capture_default_str();
  sub->add_option("--field-band", s.field.fine_band_voxels, "Distance field: narrow-band half-width, voxels")
      ->check(CLI::Range(1, 1000))->capture_default_str();
  sub->add_option("--field-coarse-voxel", s.field.coarse_voxel, "Distance field: coarse grid voxel, m")
      ->check(positive)->capture_default_str();
  sub->add_option("--field-margin", s.field.coarse_margin, "Distance field: coarse grid margin around the object, m")
      ->check(CLI::NonNegativeNumber)->capture_default_str();
  sub->add_option("--compress", deflate, "zlib level 0-9 of the stored arrays (0: none, fastest to write and read)")
      ->check(CLI::Range(0, 9))->capture_default_str();
}

json params_json(const DatabaseSettings& s, std::uint64_t seed) {
  json p = json::object();
  for (const auto& v : io::settings_values(s)) {
    json value = v.integer ? json(static_cast<std::int64_t>(v.value)) : json(v.value);
    if (v.group.empty()) p[v.name] = value;
    else p[v.group][v.name] = value;
  }
  p["scale"] = to_string(s.scale);
  p["descriptor"] = descriptor_name(s.descriptor);
  p["seed"] = seed;
  return p;
}

void print_warnings(const std::string& name, const std::vector<std::string>& warnings, const std::string& where) {
  for (const auto& w : warnings) std::cerr << "touchstone: warning: " << name << ": " << w << " (" << where << ")\n";
}

std::string fixed(double v, int digits) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << v;
  return s.str();
}

// --- congruent objects -----------------------------------------------------------------------
/// The --congruence-tolerance option of db build, add and classes.
CLI::Option* add_congruence_option(CLI::App* sub, double& tolerance, bool with_default) {
  auto* opt = sub->add_option("--congruence-tolerance", tolerance,
                              "Congruent objects: largest surface distance after a rigid motion, as a fraction of the "
                              "object size (twice its largest distance from its surface centroid)");
  if (with_default) opt->capture_default_str();
  return opt;
}

/// One clear error for a tolerance that is not positive (CLI11 would print its own usage text).
void check_tolerance(double tolerance, const std::string& file) {
  if (!(tolerance > 0.0) || !std::isfinite(tolerance))
    throw Error("--congruence-tolerance must be a positive number (a fraction of the object size, e.g. 0.01), not " +
                    (std::ostringstream() << tolerance).str(),
                file, "--congruence-tolerance");
}

std::vector<std::string> names_of(const std::vector<std::size_t>& members, const std::vector<std::string>& names) {
  std::vector<std::string> out;
  for (std::size_t i : members) out.push_back(names.at(i));
  return out;
}

/// The largest distance of the congruent pairs within a class (relative to the size).
double largest_distance(const io::CongruenceRecord& c, const std::vector<std::size_t>& members) {
  double worst = 0.0;
  for (const auto& p : c.pairs)
    if (p.kind == Congruence::congruent && std::find(members.begin(), members.end(), p.a) != members.end())
      worst = std::max(worst, p.distance);
  return worst;
}

/// {"known", "tolerance", "classes": [[names]], "class_largest_distance": [...],
///  "mirror_pairs": [{"a", "b", "distance"}]}.
json congruence_json(const io::CongruenceRecord* c, const std::vector<std::string>& names) {
  json j;
  j["known"] = c != nullptr;
  if (!c) return j;
  j["tolerance"] = c->settings.tolerance;
  json classes = json::array(), largest = json::array();
  for (const auto& members : c->classes()) {
    classes.push_back(names_of(members, names));
    largest.push_back(largest_distance(*c, members));
  }
  j["classes"] = classes;
  j["class_largest_distance"] = largest;   // per class: its pairs' largest distance (of the size)
  json mirrors = json::array();
  for (const auto& p : c->mirrors())
    mirrors.push_back({{"a", names.at(p.a)}, {"b", names.at(p.b)}, {"distance", p.distance}});
  j["mirror_pairs"] = mirrors;
  return j;
}

/// Lines for people: the classes, the mirror pairs, or that none were found / none are known.
std::string congruence_text(const io::CongruenceRecord* c, const std::vector<std::string>& names) {
  if (!c) return "congruent objects: not known (a database written before they were recorded; `touchstone db classes` finds them)\n";
  std::ostringstream s;
  const auto classes = c->classes();
  const auto mirrors = c->mirrors();
  s << "congruent objects (tolerance " << c->settings.tolerance << " of the size): ";
  if (classes.empty()) s << "none\n";
  else s << classes.size() << (classes.size() == 1 ? " class\n" : " classes\n");
  for (const auto& members : classes) {
    s << " ";
    for (const auto& n : names_of(members, names)) s << " " << n;
    s << "  (largest surface distance " << fixed(100.0 * largest_distance(*c, members), 3) << " % of the size)\n";
  }
  s << "mirror images: " << (mirrors.empty() ? "none\n" : std::to_string(mirrors.size()) + "\n");
  for (const auto& p : mirrors)
    s << "  " << names.at(p.a) << " / " << names.at(p.b) << "  (" << fixed(100.0 * p.distance, 3) << " %)\n";
  return s.str();
}

std::vector<std::string> object_names(const io::DbReader& db) {
  std::vector<std::string> names;
  for (std::size_t i = 0; i < db.size(); ++i) names.push_back(db.info(i).name);
  return names;
}

json congruence_stats_json(const datasets::CongruenceOutcome& c) {
  return {{"candidates", c.stats.candidates}, {"shapes_prepared", c.stats.prepared}, {"signatures_s", c.signature_s},
          {"search_s", c.stats.seconds},    {"reused", c.reused}};
}

// --- db build --------------------------------------------------------------------------------
struct BuildOptions {
  CommonOptions common;
  std::string manifest, meshes, out, units = "m";
  bool units_given = false;
  DatabaseSettings settings;
  int deflate = io::DbWriteSettings{}.deflate;
  double congruence_tolerance = CongruenceSettings{}.tolerance;
  ProgressOptions progress;
};

/// The --units option (m, cm, mm, in) of db build and db add.
CLI::Option* add_units_option(CLI::App* sub, std::string& units) {
  return sub->add_option("--units", units,
                         "Length unit of the mesh files under --scale keep (a manifest's 4th column overrides it "
                         "per line)")
      ->check(CLI::IsMember({"m", "cm", "mm", "in"}))
      ->capture_default_str();
}

int run_build(const BuildOptions& o) {
  const auto inputs = o.manifest.empty() ? datasets::inputs_from_folder(o.meshes)
                                         : datasets::inputs_from_manifest(o.manifest);
  datasets::BuildSettings bs;
  bs.database = o.settings;
  bs.units = *io::metres_per_unit(o.units);
  if (o.units_given && o.settings.scale == ObjectScale::fit)
    std::cerr << "touchstone: warning: --units has no effect under --scale fit (every mesh is scaled to "
              << o.settings.max_extent << " m)\n";
  bs.seed = o.common.seed;
  bs.write.deflate = o.deflate;
  check_tolerance(o.congruence_tolerance, o.manifest.empty() ? o.meshes : o.manifest);
  bs.congruence.tolerance = o.congruence_tolerance;
  // Progress with the time left (progress.hpp): a line rewritten on a terminal, else a plain line
  // every 30 s and every 5 %, JSON lines, or nothing.
  ProgressReport progress(o.progress, "db build", "objects", stderr_is_terminal(), o.common.json, std::cerr);
  if (progress.active())
    bs.progress = [&progress](const datasets::BuildProgress& p) {
      const std::size_t built = p.done - p.resumed;
      progress.update(p.done, p.total, 60.0 * static_cast<double>(built) / std::max(1e-9, p.elapsed_s),
                      built ? std::optional<double>(p.remaining_s()) : std::nullopt);
    };
  const auto report = datasets::build_database(inputs, o.out, bs);
  progress.finish();
  if (report.resumed) std::cerr << "resumed a stopped build: " << report.resumed << " objects were already built\n";
  for (std::size_t i = 0; i < inputs.size(); ++i) print_warnings(report.names[i], report.warnings[i], inputs[i].display());

  const auto& t = report.times;
  const int threads = thread_count(o.common);
  std::cerr << "built " << report.names.size() << " objects into " << o.out << " in " << fixed(t.wall_s, 2) << " s ("
            << threads << (threads == 1 ? " thread; " : " threads; ") << experiments::machine_description() << ")\n"
            << "  per stage, seconds (import/scan/features/field summed over objects):\n"
            << "    read archives " << fixed(t.read_s, 2) << "\n"
            << "    import        " << fixed(t.import_s, 2) << "\n"
            << "    scan          " << fixed(t.scan_s, 2) << "\n"
            << "    features      " << fixed(t.features_s, 2) << "\n"
            << "    field         " << fixed(t.field_s, 2) << "\n"
            << "    write         " << fixed(t.write_s, 2) << "\n"
            << "  congruent objects: " << report.congruence.stats.candidates << " candidate pairs checked in "
            << fixed(report.congruence.signature_s + report.congruence.stats.seconds, 2) << " s\n"
            << congruence_text(&report.congruence.record, report.names);
  if (o.common.json) {
    json j;
    j["out"] = o.out;
    j["objects"] = report.names;
    j["resumed"] = report.resumed;
    json warnings = json::array();
    for (std::size_t i = 0; i < report.names.size(); ++i)
      for (const auto& w : report.warnings[i]) warnings.push_back({{"object", report.names[i]}, {"message", w}});
    j["warnings"] = warnings;
    j["times_s"] = {{"read", t.read_s},         {"import", t.import_s}, {"scan", t.scan_s}, {"features", t.features_s},
                    {"field", t.field_s},       {"write", t.write_s},   {"wall", t.wall_s}};
    j["congruence"] = congruence_json(&report.congruence.record, report.names);
    j["congruence"]["search"] = congruence_stats_json(report.congruence);
    j["threads"] = threads;
    j["machine"] = experiments::machine_description();
    std::cout << j.dump(2) << '\n';
  }
  return 0;
}

// --- db add ----------------------------------------------------------------------------------
struct AddOptions {
  CommonOptions common;
  bool seed_given = false;
  std::string db, mesh, name, units = "m";
  std::optional<double> congruence_tolerance;   ///< unset: the database's, else the default
};

int run_add(const AddOptions& o) {
  auto input = datasets::input_from_path(o.mesh, o.name);
  input.units = *io::metres_per_unit(o.units);
  DatabaseSettings settings;
  std::uint64_t seed = 0;
  std::size_t before = 0;
  if (o.congruence_tolerance) check_tolerance(*o.congruence_tolerance, o.db);
  {
    io::DbReader db(o.db);
    if (db.find(input.name) < db.size())
      throw Error("object '" + input.name + "' already exists in the database", o.db);
    settings = db.settings();
    // The database's own seed unless --seed is given: then `db add` builds the object exactly
    // as `db build` would have.
    seed = io::object_seed(o.seed_given ? o.common.seed : db.build_seed(), input.name);
    before = db.size();
  }
  auto result = datasets::build_one(input, settings, seed);
  print_warnings(input.name, result.warnings, input.display());
  datasets::CongruenceOutcome congruence;
  std::vector<std::string> names;
  {
    io::DbReader db(o.db);
    CongruenceSettings cs;
    if (db.congruence()) cs = db.congruence()->settings;
    if (o.congruence_tolerance) cs.tolerance = *o.congruence_tolerance;
    congruence = datasets::database_congruence(db, {&result.object.mesh}, cs, true);
    names = object_names(db);
    names.push_back(input.name);
  }
  io::append_to_database(o.db, {{&result.object, seed}}, {}, &congruence.record);
  if (o.common.json) {
    json j;
    j["db"] = o.db;
    j["object"] = input.name;
    j["objects"] = before + 1;
    j["fine_points"] = result.object.fine.size();
    j["coarse_points"] = result.object.features.coarse.size();
    j["congruence"] = congruence_json(&congruence.record, names);
    j["congruence"]["search"] = congruence_stats_json(congruence);
    std::cout << j.dump(2) << '\n';
  } else {
    std::cout << "added " << input.name << " to " << o.db << " (" << before + 1 << " objects): "
              << result.object.fine.size() << " fine points, " << result.object.features.coarse.size()
              << " coarse points, coverage " << fixed(100.0 * result.object.info.coverage, 1) << " %\n"
              << congruence_text(&congruence.record, names);
  }
  return 0;
}

// --- db classes ------------------------------------------------------------------------------
struct ClassesOptions {
  CommonOptions common;
  std::string db;
  double congruence_tolerance = CongruenceSettings{}.tolerance;
  bool dry_run = false;
};

int run_classes(const ClassesOptions& o) {
  check_tolerance(o.congruence_tolerance, o.db);
  datasets::CongruenceOutcome c;
  std::vector<std::string> names;
  {
    io::DbReader db(o.db);
    CongruenceSettings cs;
    cs.tolerance = o.congruence_tolerance;
    c = datasets::database_congruence(db, {}, cs, false);
    names = object_names(db);
  }
  const auto t0 = std::chrono::steady_clock::now();
  if (!o.dry_run) io::write_congruence(o.db, c.record);
  const double write_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (o.common.json) {
    json j;
    j["db"] = o.db;
    j["written"] = !o.dry_run;
    j["objects"] = names.size();
    j["congruence"] = congruence_json(&c.record, names);
    j["congruence"]["search"] = congruence_stats_json(c);
    j["congruence"]["search"]["write_s"] = write_s;
    j["threads"] = thread_count(o.common);
    j["machine"] = experiments::machine_description();
    std::cout << j.dump(2) << '\n';
  } else {
    std::cout << names.size() << " objects, " << c.stats.candidates << " candidate pairs checked: signatures "
              << fixed(c.signature_s, 2) << " s, pairs " << fixed(c.stats.seconds, 2) << " s"
              << (o.dry_run ? " (dry run: nothing written)" : ", written in " + fixed(write_s, 2) + " s") << "\n"
              << congruence_text(&c.record, names);
  }
  return 0;
}

// --- db info ---------------------------------------------------------------------------------
struct InfoOptions {
  CommonOptions common;
  std::string db;
};

int run_info(const InfoOptions& o) {
  io::DbReader db(o.db);
  if (o.common.json) {
    json j;
    j["schema_version"] = db.schema_version();
    json objects = json::array();
    for (std::size_t i = 0; i < db.size(); ++i) {
      const auto& info = db.info(i);
      objects.push_back({{"name", info.name},
                         {"extent_m", {info.extent.x(), info.extent.y(), info.extent.z()}},
                         {"fine_points", info.fine_points},
                         {"coarse_points", info.coarse_points},
                         {"feature_dim", db.feature_dim()},
                         {"source", info.source},
                         {"mesh_sha256", info.mesh_sha256},
                         {"scale", info.scale},
                         {"closed", info.closed},
                         {"coverage", info.coverage},
                         {"mesh_faces", db.mesh_faces(i)}});
    }
    j["objects"] = objects;
    j["params"] = params_json(db.settings(), db.build_seed());
    j["congruence"] = congruence_json(db.congruence(), object_names(db));
    std::cout << j.dump(2) << '\n';
    return 0;
  }
  const auto& s = db.settings();
  std::size_t fine = 0, coarse = 0, open = 0;
  std::size_t width = 4;
  for (std::size_t i = 0; i < db.size(); ++i) width = std::max(width, db.info(i).name.size());
  std::ostringstream table;
  table << std::left << std::setw(static_cast<int>(width)) << "name" << std::right << "  " << std::setw(20)
        << "extent (mm)" << std::setw(9) << "fine" << std::setw(8) << "coarse" << std::setw(8) << "closed"
        << std::setw(10) << "coverage" << '\n';
  for (std::size_t i = 0; i < db.size(); ++i) {
    const auto& info = db.info(i);
    fine += info.fine_points;
    coarse += info.coarse_points;
    open += info.closed ? 0 : 1;
    const std::string extent = fixed(1000 * info.extent.x(), 0) + " x " + fixed(1000 * info.extent.y(), 0) + " x " +
                               fixed(1000 * info.extent.z(), 0);
    table << std::left << std::setw(static_cast<int>(width)) << info.name << std::right << "  " << std::setw(20)
          << extent << std::setw(9) << info.fine_points << std::setw(8) << info.coarse_points << std::setw(8)
          << (info.closed ? "yes" : "no") << std::setw(9) << fixed(100.0 * info.coverage, 1) << "%\n";
  }
  std::cout << o.db << ": object database, schema " << db.schema_version() << ", " << db.size() << " objects ("
            << open << " open meshes), " << fine << " fine and " << coarse << " coarse points\n"
            << "params: " << (s.scale == ObjectScale::keep ? "real sizes (scale keep)" : "max extent " + fixed(s.max_extent, 3) + " m") << "; scan: fine spacing " << s.scan.fine_spacing
            << " m, coarse voxel " << s.scan.coarse_voxel << " m; descriptor " << descriptor_name(s.descriptor)
            << ": normal radius " << s.fpfh.normal_radius << " m, feature radius " << s.fpfh.feature_radius << " m ("
            << db.feature_dim() << " bins); field: voxel " << s.field.fine_voxel << " m, coarse voxel " << s.field.coarse_voxel
            << " m; seed " << db.build_seed() << "\n"
            << congruence_text(db.congruence(), object_names(db)) << "\n"
            << table.str();
  return 0;
}

// --- db export -------------------------------------------------------------------------------
struct ExportOptions {
  CommonOptions common;
  std::string db, object, out, cloud = "fine";
  bool ascii = false;
};

int run_export(const ExportOptions& o) {
  std::string ext = std::filesystem::path(o.out).extension().string();
  for (auto& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext != ".ply" && ext != ".pcd") throw Error("the output must end in .ply or .pcd", o.out, "--out");
  io::DbReader db(o.db);
  const std::size_t i = db.find(o.object);
  if (i == db.size()) {
    std::string names;
    for (std::size_t k = 0; k < db.size() && k < 12; ++k) names += (k ? ", " : "") + db.info(k).name;
    if (db.size() > 12) names += ", ...";
    throw Error("no object '" + o.object + "' in the database (it holds: " + names + ")", o.db, "--object");
  }
  const PointCloud cloud = o.cloud == "fine" ? db.load_fine(i) : db.load_features(i).coarse;
  io::write_cloud(o.out, cloud,
                  {o.ascii ? io::CloudEncoding::ascii : io::CloudEncoding::binary, io::CloudPrecision::automatic});
  if (o.common.json) {
    json j;
    j["db"] = o.db;
    j["object"] = o.object;
    j["cloud"] = o.cloud;
    j["out"] = o.out;
    j["points"] = cloud.size();
    std::cout << j.dump(2) << '\n';
  } else {
    std::cout << "wrote " << cloud.size() << " " << o.cloud << " points of " << o.object << " (object frame, with normals) to "
              << o.out << '\n';
  }
  return 0;
}

}  // namespace

void register_db(CLI::App& app) {
  auto* db = app.add_subcommand("db", "Object database: build, add, info, classes, export");
  db->require_subcommand(1);

  {
    auto o = std::make_shared<BuildOptions>();
    auto* sub = db->add_subcommand("build", "Build an object database from a manifest or a folder of meshes");
    auto* src = sub->add_option_group("source", "Where the meshes come from (one of)");
    src->add_option("--manifest", o->manifest, "Manifest: source<TAB>path<TAB>name per line (path may be ARCHIVE:MEMBER)");
    src->add_option("--meshes", o->meshes, "Folder of mesh files (any format Assimp reads); names from file names");
    src->require_option(1);
    sub->add_option("--out", o->out, "Output database (HDF5)")->required();
    add_build_parameters(sub, o->settings, o->deflate);
    add_congruence_option(sub, o->congruence_tolerance, true);
    auto* units = add_units_option(sub, o->units);
    add_common(sub, o->common);
    add_progress(sub, o->progress);
    sub->callback([o, units] {
      o->units_given = units->count() > 0;
      run_command(o->common, [o] { return run_build(*o); });
    });
  }
  {
    auto o = std::make_shared<AddOptions>();
    auto* sub = db->add_subcommand("add", "Append one mesh to a database (built with the database's parameters)");
    sub->add_option("db,--db", o->db, "Database (HDF5)")->required();
    sub->add_option("mesh,--mesh", o->mesh, "Mesh file, or ARCHIVE:MEMBER")->required();
    sub->add_option("--name", o->name, "Object name (default: the file name without extension)");
    add_units_option(sub, o->units);
    sub->add_option("--congruence-tolerance", o->congruence_tolerance,
                    "Congruent objects: as db build (default: the database's own, else 0.01); another value than the "
                    "database's searches every pair again");
    add_common(sub, o->common);
    sub->callback([o, sub] {
      o->seed_given = sub->get_option("--seed")->count() > 0;
      run_command(o->common, [o] { return run_add(*o); });
    });
  }
  {
    auto o = std::make_shared<InfoOptions>();
    auto* sub = db->add_subcommand("info", "Summary of a database (reads no point data)");
    sub->add_option("db,--db", o->db, "Database (HDF5)")->required();
    add_common(sub, o->common, kJson);
    sub->callback([o] { run_command(o->common, [o] { return run_info(*o); }); });
  }
  {
    auto o = std::make_shared<ClassesOptions>();
    auto* sub = db->add_subcommand("classes",
                                   "Find congruent objects and mirror images (every pair) and store them in the database "
                                   "(written to a copy that replaces it when complete)");
    sub->add_option("db,--db", o->db, "Database (HDF5)")->required();
    add_congruence_option(sub, o->congruence_tolerance, true);
    sub->add_flag("--dry-run", o->dry_run, "Report the classes without writing them");
    add_common(sub, o->common, kThreads | kJson);
    sub->callback([o] { run_command(o->common, [o] { return run_classes(*o); }); });
  }
  {
    auto o = std::make_shared<ExportOptions>();
    auto* sub = db->add_subcommand("export", "Write an object's cloud (object frame, with normals) as PLY or PCD");
    sub->add_option("db,--db", o->db, "Database (HDF5)")->required();
    sub->add_option("--object", o->object, "Object name")->required();
    sub->add_option("--out", o->out, "Output .ply or .pcd")->required();
    sub->add_option("--cloud", o->cloud, "Which cloud: fine (default) or coarse (the feature points)")
        ->check(CLI::IsMember({"fine", "coarse"}))
        ->capture_default_str();
    sub->add_flag("--ascii", o->ascii, "Write ascii instead of binary");
    add_common(sub, o->common, kJson);
    sub->callback([o] { run_command(o->common, [o] { return run_export(*o); }); });
  }
}

}  // namespace ts::cli
