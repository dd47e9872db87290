#include "datasets/db_builder.hpp"
#include "engine/detail.hpp"

#include "datasets/archive.hpp"
#include "datasets/manifest.hpp"
#include "io/atomic_file.hpp"
#include "io/sha256.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <fstream>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <tuple>

namespace ts::datasets {

namespace {

using detail::Clock;
using detail::seconds_since;

void check_exists(const MeshInput& in) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(in.path, ec)) {
    const std::string what = in.member.empty() ? "mesh file does not exist: " : "archive does not exist: ";
    if (in.origin.empty()) throw Error(what.substr(0, what.size() - 2), in.path.string());
    throw Error(what + in.path.string(), in.origin, in.origin_field);
  }
}

struct Imported {
  io::ImportedMesh mesh;
  double import_s = 0.0;
};

Imported import_input(const MeshInput& in, const DatabaseSettings& settings, const std::string* bytes) {
  const auto t0 = Clock::now();
  const io::MeshImportSettings s{
      .scale = settings.scale, .max_extent = settings.max_extent, .units = in.units > 0.0 ? in.units : 1.0};
  Imported out;
  try {
    if (bytes) out.mesh = io::import_mesh_from_memory(*bytes, in.display(), s);
    else if (!in.member.empty()) out.mesh = io::import_mesh_from_memory(read_archive_member(in.path, in.member), in.display(), s);
    else out.mesh = io::import_mesh(in.path, s);
  } catch (const Error& e) {
    // A wrong size at true scale is the declaration's mistake: name where the units came from.
    if (e.field() != "units" || in.origin.empty()) throw;
    throw Error(e.message() + " (" + in.display() + ")", in.origin, in.origin_field + ", units");
  }
  out.import_s = seconds_since(t0);
  return out;
}

BuildResult build_imported(const MeshInput& in, Imported&& imported, const DatabaseSettings& settings,
                           std::uint64_t seed) {
  ObjectInfo info;
  info.name = in.name;
  info.source = in.source;
  info.mesh_sha256 = imported.mesh.sha256;
  info.scale = imported.mesh.scale;
  info.centre = imported.mesh.centre;
  info.extent = imported.mesh.extent;
  info.closed = imported.mesh.closed;
  BuildResult r;
  r.seed = seed;
  r.flipped = imported.mesh.flipped;
  r.warnings = std::move(imported.mesh.warnings);
  r.import_s = imported.import_s;
  r.object = build_object(imported.mesh.mesh, std::move(info), settings, seed);
  return r;
}

/// Run body(i) for every i in parallel; rethrow the error of the smallest failing index.
/// With stop_early, tasks not yet started are skipped once one has failed.
template <class F>
void parallel_each(std::size_t n, bool stop_early, F&& body) {
  std::vector<std::exception_ptr> errors(n);
  std::atomic<bool> failed{false};
  tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) {
    if (stop_early && failed.load(std::memory_order_relaxed)) return;
    try {
      body(i);
    } catch (...) {
      errors[i] = std::current_exception();
      failed.store(true, std::memory_order_relaxed);
    }
  });
  for (const auto& e : errors)
    if (e) std::rethrow_exception(e);
}

}  // namespace

std::string MeshInput::display() const { return member.empty() ? path.string() : path.string() + ":" + member; }

std::vector<MeshInput> inputs_from_manifest(const std::filesystem::path& manifest) {
  std::vector<MeshInput> out;
  for (const auto& e : read_manifest(manifest)) {
    MeshInput in;
    in.name = e.name;
    in.units = e.units;
    in.path = e.path;
    in.member = e.member;
    in.source = e.source + ": " + e.path.filename().string() + (e.member.empty() ? "" : ":" + e.member);
    in.origin = manifest.string();
    in.origin_field = "line " + std::to_string(e.line);
    out.push_back(std::move(in));
  }
  return out;
}

std::vector<MeshInput> inputs_from_folder(const std::filesystem::path& folder) {
  std::error_code ec;
  if (!std::filesystem::is_directory(folder, ec)) throw Error("mesh folder does not exist", folder.string());
  std::vector<std::filesystem::path> files;
  for (const auto& entry : std::filesystem::directory_iterator(folder, ec)) {
    const auto name = entry.path().filename().string();
    if (name.empty() || name[0] == '.' || !entry.is_regular_file()) continue;
    if (io::is_mesh_extension(entry.path().extension().string())) files.push_back(entry.path());
  }
  if (ec) throw Error("cannot list the mesh folder: " + ec.message(), folder.string());
  if (files.empty()) throw Error("no mesh files in the folder", folder.string());
  std::sort(files.begin(), files.end());
  std::vector<MeshInput> out;
  std::map<std::string, std::string> seen;
  for (const auto& f : files) {
    MeshInput in;
    in.name = f.stem().string();
    io::check_object_name(in.name, f.string());
    if (auto it = seen.find(in.name); it != seen.end())
      throw Error("two meshes would be named '" + in.name + "' (" + it->second + " and " + f.filename().string() + ")",
                  folder.string());
    seen.emplace(in.name, f.filename().string());
    in.path = f;
    in.source = "file: " + f.filename().string();
    out.push_back(std::move(in));
  }
  return out;
}

MeshInput input_from_path(const std::string& path, const std::string& name) {
  auto [file, member] = split_archive_path(path);
  MeshInput in;
  in.path = file;
  in.member = member;
  in.name = name.empty() ? std::filesystem::path(member.empty() ? file : member).stem().string() : name;
  io::check_object_name(in.name, path, name.empty() ? "" : "--name");
  in.source = member.empty() ? "file: " + in.path.filename().string()
                             : "archive: " + in.path.filename().string() + ":" + member;
  return in;
}

namespace {

void check_congruence_settings(const CongruenceSettings& s, const std::string& file) {
  if (!(s.tolerance > 0.0) || !std::isfinite(s.tolerance))
    throw Error("the congruence tolerance must be a positive number (a fraction of the object size, e.g. 0.01), not " +
                    std::to_string(s.tolerance),
                file, "--congruence-tolerance");
}

}  // namespace

CongruenceOutcome database_congruence(const io::DbReader& db, const std::vector<const Mesh*>& added,
                                      const CongruenceSettings& settings, bool reuse) {
  check_congruence_settings(settings, db.path());
  const std::size_t old_n = db.size(), n = old_n + added.size();
  auto mesh_of = [&](std::size_t i) { return i < old_n ? db.load_mesh(i) : *added[i - old_n]; };
  CongruenceOutcome out;
  out.record.settings = settings;
  const io::CongruenceRecord* old = db.congruence();
  out.reused = reuse && old && old->settings.tolerance == settings.tolerance &&
               old->settings.samples == settings.samples && old->settings.seed == settings.seed;
  const auto t0 = Clock::now();
  out.record.signatures.resize(n);
  const std::size_t first = out.reused ? old_n : 0;
  if (out.reused) std::copy(old->signatures.begin(), old->signatures.end(), out.record.signatures.begin());
  tbb::parallel_for(first, n, [&](std::size_t i) { out.record.signatures[i] = surface_signature(mesh_of(i)); });
  out.signature_s = seconds_since(t0);
  out.record.pairs = find_congruent_pairs(out.record.signatures, mesh_of, first, settings, &out.stats);
  if (out.reused) {
    std::vector<CongruentPair> all = old->pairs;
    all.insert(all.end(), out.record.pairs.begin(), out.record.pairs.end());
    std::sort(all.begin(), all.end(), [](const CongruentPair& x, const CongruentPair& y) {
      return std::tie(x.a, x.b) < std::tie(y.a, y.b);
    });
    out.record.pairs = std::move(all);
  }
  return out;
}

BuildResult build_one(const MeshInput& input, const DatabaseSettings& settings, std::uint64_t seed,
                      const std::string* bytes) {
  if (!bytes) check_exists(input);
  return build_imported(input, import_input(input, settings, bytes), settings, seed);
}

namespace {

/// What identifies a build: format, parameters, seed and every input (name, source, mesh bytes).
std::string build_fingerprint(const std::vector<MeshInput>& inputs, const std::vector<std::string>& mesh_sha256,
                              const BuildSettings& settings) {
  std::string text = "touchstone db build, schema " + std::to_string(io::kDbSchemaVersion) + "\n";
  const bool keep = settings.database.scale == ObjectScale::keep;
  if (keep) text += "scale keep\n";   // (fit builds: the text of the builds before keep existed)
  if (settings.database.descriptor != Descriptor::fpfh)   // (FPFH: the text before descriptors)
    text += "descriptor " + descriptor_name(settings.database.descriptor) + "\n";
  text += "seed " + std::to_string(settings.seed) + "\ndeflate " + std::to_string(settings.write.deflate) + "\n";
  char value[64];
  for (const auto& v : io::settings_values(settings.database)) {
    std::snprintf(value, sizeof value, "%.17g", v.value);
    text += v.group + "." + v.name + " " + value + "\n";
  }
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    text += inputs[i].name + "\t" + inputs[i].source + "\t" + mesh_sha256[i];
    if (keep) {
      std::snprintf(value, sizeof value, "\t%.17g", inputs[i].units);
      text += value;
    }
    text += "\n";
  }
  return io::sha256_hex(text);
}

std::string read_file_text(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

/// The parts folder of this build: created with the fingerprint, or checked against it.
void prepare_parts(const std::filesystem::path& dir, const std::string& fingerprint, const std::vector<MeshInput>& inputs) {
  std::error_code ec;
  const auto print = dir / "fingerprint";
  const std::string where = inputs.front().origin.empty() ? inputs.front().display() : inputs.front().origin;
  if (std::filesystem::exists(dir, ec)) {
    if (!std::filesystem::is_directory(dir, ec) || !std::filesystem::is_regular_file(print, ec))
      throw Error("the parts folder of this build exists but is not one (no fingerprint file): " + dir.string() +
                      "; remove it to start over",
                  where);
    if (read_file_text(print) != fingerprint + "\n")
      throw Error("the stopped build in " + dir.string() +
                      " was started with other inputs, parameters or seed; rerun it as it was, or remove the folder "
                      "to start over",
                  where, "fingerprint");
    for (const auto& entry : std::filesystem::directory_iterator(dir, ec))   // a killed part's temporary
      if (entry.path().filename().string().find(".tmp-") != std::string::npos) std::filesystem::remove(entry.path(), ec);
    return;
  }
  // Created whole or not at all: the folder and its fingerprint are made under a temporary name
  // and renamed into place, so that a build killed here leaves nothing that blocks the next one.
  const std::filesystem::path fresh = dir.string() + ".new";
  std::filesystem::remove_all(fresh, ec);   // a killed build's unfinished folder
  std::filesystem::create_directories(fresh, ec);
  if (ec) throw Error("cannot create the parts folder: " + ec.message(), fresh.string());
  {
    io::AtomicOutput out(fresh / "fingerprint");
    std::ofstream f(out.temp_path(), std::ios::binary);
    f << fingerprint << "\n";
    f.close();
    if (!f) throw Error("cannot write the fingerprint", print.string());
    out.commit();
  }
  std::filesystem::rename(fresh, dir, ec);
  if (ec) throw Error("cannot create the parts folder: " + ec.message(), dir.string());
}

/// The parts folder goes after the merge: the parts first and the fingerprint last, so that a
/// build killed while removing it leaves a folder the next build still recognizes.
void remove_parts(const std::filesystem::path& dir) {
  std::error_code ec;
  std::vector<std::filesystem::path> files;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec))
    if (entry.path().filename() != "fingerprint") files.push_back(entry.path());
  for (const auto& f : files) std::filesystem::remove_all(f, ec);
  std::filesystem::remove(dir / "fingerprint", ec);
  std::filesystem::remove(dir, ec);
}

/// A part left by an earlier run: one object of this name and mesh.
bool part_is_done(const std::filesystem::path& part, const std::string& name, const std::string& sha256) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(part, ec)) return false;
  try {
    io::DbReader db(part);
    return db.size() == 1 && db.info(0).name == name && db.info(0).mesh_sha256 == sha256;
  } catch (const Error&) {
    return false;   // unreadable: build it again
  }
}

std::string part_name(std::size_t i) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%07zu.h5", i);
  return buf;
}

}  // namespace

BuildReport build_database(const std::vector<MeshInput>& given, const std::filesystem::path& out,
                           const BuildSettings& settings) {
  const auto t_start = Clock::now();
  std::vector<MeshInput> inputs = given;
  if (!(settings.units > 0.0) || !std::isfinite(settings.units))
    throw Error("mesh units must be a positive number of metres", out.string(), "units");
  for (auto& in : inputs)
    if (!(in.units > 0.0)) in.units = settings.units;
  const std::size_t n = inputs.size();
  if (n == 0) throw Error("no objects to build", out.string());
  check_congruence_settings(settings.congruence, out.string());
  {
    std::set<std::string> names;
    for (const auto& in : inputs) {
      if (!names.insert(in.name).second) throw Error("duplicate object name '" + in.name + "'", in.origin, in.origin_field);
      check_exists(in);
    }
  }
  BuildReport report;

  // 1. Archive members: one pass (one decompression) per archive.
  auto t0 = Clock::now();
  std::map<std::filesystem::path, std::set<std::string>> wanted;
  for (const auto& in : inputs)
    if (!in.member.empty()) wanted[in.path].insert(in.member);
  std::map<std::filesystem::path, std::map<std::string, std::string>> members;
  for (const auto& [archive, names] : wanted) members[archive] = read_archive_members(archive, names);
  report.times.read_s = seconds_since(t0);
  auto bytes_of = [&](const MeshInput& in) -> const std::string* {
    return in.member.empty() ? nullptr : &members.at(in.path).at(in.member);
  };

  // 2. Import every mesh (fast; the meshes are not kept, so thousands fit): the first bad mesh
  //    in input order is the error, before anything is built. Checksums, warnings, flips.
  std::vector<std::string> sha(n);
  report.warnings.resize(n);
  report.flipped.resize(n);
  std::vector<double> import_s(n, 0.0);
  // One byte per mesh while the tasks run: report.flipped is a std::vector<bool>, whose
  // neighbouring bits share a word, so writing it from several tasks at once lost flags
  // (ThreadSanitizer, 2026-11-26).
  std::vector<std::uint8_t> flipped(n, 0);
  parallel_each(n, false, [&](std::size_t i) {
    Imported im = import_input(inputs[i], settings.database, bytes_of(inputs[i]));
    sha[i] = im.mesh.sha256;
    report.warnings[i] = im.mesh.warnings;
    flipped[i] = im.mesh.flipped ? 1 : 0;
    import_s[i] = im.import_s;
  });
  for (std::size_t i = 0; i < n; ++i) report.flipped[i] = flipped[i] != 0;

  // 3. The parts folder: new, or a stopped build of the same inputs to resume.
  const std::filesystem::path parts = settings.parts.empty() ? std::filesystem::path(out.string() + ".parts") : settings.parts;
  prepare_parts(parts, build_fingerprint(inputs, sha, settings), inputs);
  std::vector<std::size_t> todo;
  for (std::size_t i = 0; i < n; ++i)
    if (!part_is_done(parts / part_name(i), inputs[i].name, sha[i])) todo.push_back(i);
  report.resumed = n - todo.size();

  // 4. Build what is missing, each object written to its part as it finishes.
  std::vector<ShapeSignature> signatures(n);
  std::mutex progress_mutex;
  BuildProgress progress;
  progress.total = n;
  progress.resumed = progress.done = report.resumed;
  const auto t_build = Clock::now();
  try {
    parallel_each(todo.size(), true, [&](std::size_t k) {
      const std::size_t i = todo[k];
      Imported im = import_input(inputs[i], settings.database, bytes_of(inputs[i]));
      BuildResult r = build_imported(inputs[i], std::move(im), settings.database,
                                     io::object_seed(settings.seed, inputs[i].name));
      io::write_database(parts / part_name(i), {{&r.object, r.seed}}, settings.database, settings.seed, settings.write);
      signatures[i] = surface_signature(r.object.mesh);
      std::lock_guard<std::mutex> lock(progress_mutex);
      report.times.import_s += import_s[i];
      report.times.scan_s += r.object.timings.scan_s;
      report.times.features_s += r.object.timings.features_s;
      report.times.field_s += r.object.timings.field_s;
      ++progress.done;
      if (settings.progress) {
        progress.elapsed_s = seconds_since(t_build);
        progress.name = inputs[i].name;
        settings.progress(progress);
      }
    });
  } catch (const Error& e) {
    std::size_t kept = 0;
    for (std::size_t i = 0; i < n; ++i) kept += std::filesystem::exists(parts / part_name(i));
    throw Error(e.message() + " [" + std::to_string(kept) + " of " + std::to_string(n) + " objects finished, kept in " +
                    parts.string() + "; the same command resumes]",
                e.file(), e.field());
  }
  members.clear();

  // 5. Congruent objects: signatures of the resumed parts from their meshes, then the pairs
  //    (meshes read back from the parts as the geometric checks need them).
  std::vector<std::filesystem::path> files;
  for (std::size_t i = 0; i < n; ++i) files.push_back(parts / part_name(i));
  {
    auto mesh_of = [&](std::size_t i) { return io::DbReader(files[i]).load_mesh(0); };
    const auto tc = Clock::now();
    std::vector<bool> built(n, false);
    for (std::size_t i : todo) built[i] = true;
    tbb::parallel_for(std::size_t{0}, n, [&](std::size_t i) {
      if (!built[i]) signatures[i] = surface_signature(mesh_of(i));
    });
    auto& c = report.congruence;
    c.signature_s = seconds_since(tc);
    c.record.settings = settings.congruence;
    c.record.signatures = signatures;
    c.record.pairs = find_congruent_pairs(signatures, mesh_of, 0, settings.congruence, &c.stats);
  }

  // 6. Merge, in input order; then the parts go.
  t0 = Clock::now();
  io::merge_databases(files, out, settings.database, settings.seed, &report.congruence.record);
  {
    io::DbReader db(out);
    for (std::size_t i = 0; i < n; ++i) {
      report.names.push_back(inputs[i].name);
      report.coverage.push_back(db.info(i).coverage);
    }
  }
  remove_parts(parts);
  report.times.write_s = seconds_since(t0);
  report.times.wall_s = seconds_since(t_start);
  return report;
}

}  // namespace ts::datasets
