#include "datasets/db_builder.hpp"

#include "datasets/archive.hpp"
#include "datasets/manifest.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <exception>
#include <map>
#include <mutex>
#include <optional>
#include <set>

namespace ts::datasets {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

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
  const io::MeshImportSettings s{.max_extent = settings.max_extent};
  Imported out;
  if (bytes) out.mesh = io::import_mesh_from_memory(*bytes, in.display(), s);
  else if (!in.member.empty()) out.mesh = io::import_mesh_from_memory(read_archive_member(in.path, in.member), in.display(), s);
  else out.mesh = io::import_mesh(in.path, s);
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

BuildResult build_one(const MeshInput& input, const DatabaseSettings& settings, std::uint64_t seed,
                      const std::string* bytes) {
  if (!bytes) check_exists(input);
  return build_imported(input, import_input(input, settings, bytes), settings, seed);
}

BuildReport build_database(const std::vector<MeshInput>& inputs, const std::filesystem::path& out,
                           const BuildSettings& settings) {
  const auto t_start = Clock::now();
  const std::size_t n = inputs.size();
  if (n == 0) throw Error("no objects to build", out.string());
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

  // 2. Import every mesh (fast); the first bad mesh in input order is the error.
  std::vector<std::optional<Imported>> imported(n);
  parallel_each(n, false, [&](std::size_t i) { imported[i] = import_input(inputs[i], settings.database, bytes_of(inputs[i])); });
  members.clear();

  // 3. Build every object into its own slot.
  std::vector<std::optional<BuildResult>> built(n);
  std::mutex progress_mutex;
  std::size_t done = 0;
  parallel_each(n, true, [&](std::size_t i) {
    built[i] = build_imported(inputs[i], std::move(*imported[i]), settings.database,
                              io::object_seed(settings.seed, inputs[i].name));
    imported[i].reset();
    if (settings.progress) {
      std::lock_guard<std::mutex> lock(progress_mutex);
      settings.progress(++done, n, inputs[i].name);
    }
  });

  // 4. Write, serially in input order.
  t0 = Clock::now();
  std::vector<io::StoredObject> stored;
  for (std::size_t i = 0; i < n; ++i) {
    const BuildResult& r = *built[i];
    stored.push_back({&r.object, r.seed});
    report.names.push_back(inputs[i].name);
    report.warnings.push_back(r.warnings);
    report.flipped.push_back(r.flipped);
    report.coverage.push_back(r.object.info.coverage);
    report.times.import_s += r.import_s;
    report.times.scan_s += r.object.timings.scan_s;
    report.times.features_s += r.object.timings.features_s;
    report.times.field_s += r.object.timings.field_s;
  }
  io::write_database(out, stored, settings.database, settings.seed, settings.write);
  report.times.write_s = seconds_since(t0);
  report.times.wall_s = seconds_since(t_start);
  return report;
}

}  // namespace ts::datasets
