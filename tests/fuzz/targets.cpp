#include "fuzz/targets.hpp"

#include "fuzz/h5_edits.hpp"

#include "datasets/archive.hpp"
#include "datasets/manifest.hpp"
#include "engine/core.hpp"
#include "engine/recognition/answer_set.hpp"
#include "experiments/analysis/calibration.hpp"
#include "experiments/params/config.hpp"
#include "io/cloud_io.hpp"
#include "io/db_store.hpp"
#include "io/gripper_io.hpp"
#include "io/log_store.hpp"
#include "io/mcap.hpp"
#include "io/mesh_import.hpp"
#include "io/result_store.hpp"
#include "io/run_store.hpp"

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <limits>

namespace ts::fuzz {
namespace {

namespace fs = std::filesystem;

/// This process's folder for the inputs (removed at exit).
const fs::path& scratch() {
  struct Dir {
    fs::path path;
    Dir() {
      const fs::path shm = "/dev/shm";
      std::error_code ec;
      const fs::path base = fs::is_directory(shm, ec) ? shm : fs::temp_directory_path();
      path = base / ("ts_fuzz_" + std::to_string(::getpid()));
      fs::create_directories(path);
    }
    ~Dir() {
      std::error_code ec;
      fs::remove_all(path, ec);
    }
  };
  static const Dir dir;
  return dir.path;
}

/// The bytes as a file `name` of the scratch folder.
fs::path as_file(std::span<const std::uint8_t> bytes, const std::string& name) {
  const fs::path p = scratch() / name;
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  return p;
}

/// The first byte chooses among `choices` (a format hint such as an extension); the rest is the
/// input. Empty input: the first choice and no bytes.
std::pair<std::string, std::span<const std::uint8_t>> choose(std::span<const std::uint8_t> bytes,
                                                             const std::vector<std::string>& choices) {
  if (bytes.empty()) return {choices.front(), bytes};
  return {choices[bytes[0] % choices.size()], bytes.subspan(1)};
}

/// Run `read`; ts::Error is a refusal, the expected answer to a bad input. Other exceptions
/// propagate (findings).
template <class F>
bool refusal_ok(F&& read) {
  try {
    read();
    return true;
  } catch (const ts::Error&) {
    return false;
  }
}

/// A ROS 2 recording (MCAP): every record of the data section streamed, its bytes touched.
bool mcap(std::span<const std::uint8_t> b) {
  const auto p = as_file(b, "in.mcap");
  return refusal_ok([&] {
    std::uint64_t sum = 0;
    io::McapHandlers h;
    h.schema = [&](const io::McapSchema& x) { sum += x.data.size() + x.name.size(); };
    h.channel = [&](const io::McapChannel& x) { sum += x.topic.size() + x.metadata.size(); };
    h.message = [&](const io::McapMessage& m) {
      for (std::uint8_t v : m.data) sum += v;
    };
    h.attachment = [&](const io::McapAttachment& a) {
      for (std::uint8_t v : a.data) sum += v;
    };
    (void)io::read_mcap(p, h);
    (void)sum;
  });
}

bool pcd(std::span<const std::uint8_t> b) {
  const auto p = as_file(b, "in.pcd");
  return refusal_ok([&] { (void)io::read_pcd(p); });
}

bool ply(std::span<const std::uint8_t> b) {
  const auto p = as_file(b, "in.ply");
  return refusal_ok([&] { (void)io::read_ply(p); });
}

bool mesh(std::span<const std::uint8_t> b) {
  const auto [hint, rest] = choose(b, {"off", "obj", "stl", "ply"});
  const std::string bytes(reinterpret_cast<const char*>(rest.data()), rest.size()), ext = hint;
  return refusal_ok([&] { (void)io::import_mesh_from_memory(bytes, "fuzz." + ext); });
}

bool tar(std::span<const std::uint8_t> b) {
  const auto [ext, rest] = choose(b, {"tar", "tar.gz"});
  const fs::path p = as_file(rest, "in." + ext);
  return refusal_ok([&] {
    const auto members = datasets::list_archive(p);
    (void)datasets::read_archive_members(p, std::set<std::string>(members.begin(), members.end()));
  });
}

bool manifest(std::span<const std::uint8_t> b) {
  const auto p = as_file(b, "in.tsv");
  return refusal_ok([&] { (void)datasets::read_manifest(p); });
}

bool gripper(std::span<const std::uint8_t> b) {
  const std::string text(reinterpret_cast<const char*>(b.data()), b.size());
  return refusal_ok([&] { (void)io::parse_gripper(text, "fuzz.json"); });
}

bool config(std::span<const std::uint8_t> b) {
  const auto [ext, rest] = choose(b, {"toml", "ini"});
  const fs::path p = as_file(rest, "in." + ext);
  return refusal_ok([&] {
    experiments::ExperimentConfig c;
    experiments::load_config_file(c, p);
    experiments::validate(c, p.string());
  });
}

/// A calibration file (confidence models, open-set threshold, answer sets), read for no
/// particular database, then used: a confidence and a set answer at a few steps.
bool calibration(std::span<const std::uint8_t> b) {
  const auto p = as_file(b, "in.json");
  return refusal_ok([&] {
    const experiments::Calibration c = experiments::read_calibration(p, "");
    const std::vector<double> features(c.features.size(), 0.5);
    for (int step : {1, 7, 1000}) {
      (void)c.object_confidence(step, features);
      (void)c.in_database(step, features);
      for (const auto& a : c.answer_sets) {
        const std::vector<double> gaps{0.0, 1e-5, 0.01, std::numeric_limits<double>::infinity()};
        (void)conformal_set(gaps, a.at(step), a.alpha);
      }
    }
  });
}

/// The HDF5 readers. Each takes a file path.
void read_database(const fs::path& p) {
  io::DbReader db(p);
  for (std::size_t i = 0; i < db.size() && i < 4; ++i) {
    (void)db.load_features(i);
    (void)db.load_coarse(i);
    (void)db.load_fine(i);
    (void)db.load_field(i);
    (void)db.load_mesh(i);
  }
}
void read_log(const fs::path& p) { (void)io::read_log(p); }
void read_runs(const fs::path& p) { (void)io::RunStore::read(p); }
void read_result(const fs::path& p) { (void)io::read_result(p); }

/// A store Touchstone wrote, the base of a target's edit scripts (tests/fuzz/base/).
fs::path base_file(const std::string& name) { return fs::path(TS_SOURCE_DIR) / "tests/fuzz/base" / name; }

/// An HDF5 target in edit mode: the script applied to the base file, then read.
template <void (*Read)(const fs::path&)>
bool edited(std::span<const std::uint8_t> script, const char* base) {
  const fs::path p = scratch() / "in.h5";
  apply_h5_edits(base_file(base), p, script);
  return refusal_ok([&] { Read(p); });
}

bool database(std::span<const std::uint8_t> b) { return edited<read_database>(b, "box_db.h5"); }
// Each script edits a pad log and a fingertip log (format_version 3, with normals).
bool log(std::span<const std::uint8_t> b) {
  const bool pads = edited<read_log>(b, "box_3_grasps.h5");
  return edited<read_log>(b, "box_3_fingertips.h5") && pads;
}
bool runs(std::span<const std::uint8_t> b) { return edited<read_runs>(b, "box_1_run.h5"); }
// Each script edits a result without and one with set answers (/answer_sets).
bool result(std::span<const std::uint8_t> b) {
  const bool plain = edited<read_result>(b, "box_3_steps.h5");
  return edited<read_result>(b, "box_3_steps_sets.h5") && plain;
}

/// Raw bytes as an HDF5 file (first byte: which reader): what libhdf5 itself makes of damaged
/// metadata. Debian's libhdf5 1.10.8 crashes on some (docs/testing.md, Hardening): not in "all".
bool hdf5(std::span<const std::uint8_t> b) {
  const auto [reader, rest] = choose(b, {"database", "log", "runs", "result"});
  const fs::path p = as_file(rest, "raw.h5");
  const std::string r = reader;
  return refusal_ok([&] {
    if (r == "database") read_database(p);
    else if (r == "log") read_log(p);
    else if (r == "runs") read_runs(p);
    else read_result(p);
  });
}

}  // namespace

const std::vector<Target>& targets() {
  static const std::vector<Target> all = {
      {"pcd", "PCD point cloud (read_pcd)", pcd},
      {"ply", "PLY point cloud (read_ply)", ply},
      {"mesh", "mesh import (Assimp; first byte: OFF, OBJ, STL or PLY)", mesh},
      {"tar", "tar archive members (first byte: .tar or .tar.gz)", tar},
      {"manifest", "mesh manifest (TSV)", manifest},
      {"gripper", "gripper description (JSON)", gripper},
      {"config", "study configuration (first byte: TOML or INI), validated", config},
      {"calibration", "calibration file (JSON: confidence models, answer sets), read and used", calibration},
      {"database", "object database (HDF5 edit script on a database: summary, first objects' data)", database},
      {"log", "tactile log (HDF5 edit script on a log)", log},
      {"runs", "experiment run store (HDF5 edit script on a store)", runs},
      {"result", "recognition result (HDF5 edit script on a result)", result},
      {"mcap", "ROS 2 recording (MCAP: chunks plain, lz4, zstd)", mcap},
      {"hdf5", "raw bytes as any HDF5 store (first byte: database, log, runs, result): libhdf5's own parsing", hdf5},
  };
  return all;
}

const Target* find_target(const std::string& name) {
  for (const Target& t : targets())
    if (t.name == name) return &t;
  return nullptr;
}

}  // namespace ts::fuzz
