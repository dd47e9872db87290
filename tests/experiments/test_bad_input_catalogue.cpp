// The bad-input catalogue: crafted inputs for every reader, each given to the command a user
// would run on it. Every case must end with exactly one error line ("touchstone: error: ...")
// naming the file and the field or place, exit code 1, and every file in the folder as it was
// before (an existing output untouched, a database given to `db add` byte for byte the same,
// nothing half-written left behind).
#include "fuzz/h5_edits.hpp"
#include "io/db_store.hpp"

#include "cli_run.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <filesystem>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using ts::test::TempDir;

namespace {

struct Case {
  std::string what;    ///< the reader and what is wrong
  std::string name;    ///< the crafted file's name in the folder
  std::string bytes;   ///< its content (ignored when `make` is set)
  std::function<void(const fs::path&)> make;  ///< or: edits of a copied store (the path is given)
  std::string base;    ///< for `make`: which store to copy first (tests/fuzz/base/<base>)
  std::string args;    ///< the command: {in} the crafted file, {db} a good database, {out} an output
  std::string field;   ///< what the error must name besides the file
};

fs::path base(const std::string& name) { return fs::path(TS_SOURCE_DIR) / "tests/fuzz/base" / name; }

std::string replace_all(std::string s, const std::string& from, const std::string& to) {
  for (std::size_t at = s.find(from); at != std::string::npos; at = s.find(from, at + to.size())) s.replace(at, from.size(), to);
  return s;
}

/// Every file under `dir` with its bytes.
std::map<std::string, std::string> snapshot(const fs::path& dir) {
  std::map<std::string, std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    out[fs::relative(e.path(), dir).string()] = e.is_regular_file() ? ts::test::read_bytes(e.path()) : "(dir)";
  return out;
}

const std::string kPcdHead = "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n";
const std::string kPlyHead = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
const std::string kOff = "OFF\n4 4 6\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n";
const std::string kFaces = "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";

/// A congruence record (no pairs) added to a copied database, for edits of /congruence.
void with_congruence(const fs::path& f) {
  ts::io::CongruenceRecord rec;
  rec.signatures.resize(ts::io::DbReader(f).size());
  ts::io::write_congruence(f, rec);
}

std::vector<Case> catalogue() {
  const std::string cloud = "recognize --db {db} --cloud {in} --out {out}";
  const std::string add = "db add {db} {in}";
  const std::string build = "db build --manifest {in} --out {out}";
  const std::string sim = "simulate --db {db} --object box --grasps 1 --gripper {in} --out {out}";
  const std::string exp = "experiment --db {db} --config {in} --out {out}";
  std::vector<Case> c = {
      // --- PCD ---------------------------------------------------------------------------------
      {"PCD: POINTS near 2^62 with binary_compressed (wrapped size)", "a.pcd",
       kPcdHead + "WIDTH 4611686018427387905\nHEIGHT 1\nPOINTS 4611686018427387905\nDATA binary_compressed\n\x10\x01\x02\x03", {}, "", cloud, "POINTS"},
      {"PCD: COUNT near 2^64", "b.pcd",
       "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 18446744073709551615\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA binary\n0000000000000", {}, "", cloud, "COUNT"},
      {"PCD: fewer ascii points than declared", "c.pcd", kPcdHead + "WIDTH 3\nHEIGHT 1\nPOINTS 3\nDATA ascii\n0 0 0\n1 0 0\n", {}, "", cloud, "line"},
      {"PCD: no z field", "d.pcd", "# .PCD v0.7\nVERSION 0.7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n0 0\n", {}, "", cloud, "z"},
      {"PCD: SIZE lists fewer entries than FIELDS", "e.pcd", "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n0 0 0\n", {}, "", cloud, "SIZE"},
      {"PCD: unknown TYPE letter", "f.pcd", "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F Q F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n0 0 0\n", {}, "", cloud, "field type Q4 for 'y'"},
      {"PCD: WIDTH x HEIGHT differs from POINTS", "g.pcd", kPcdHead + "WIDTH 2\nHEIGHT 2\nPOINTS 3\nDATA ascii\n0 0 0\n1 0 0\n0 1 0\n", {}, "", cloud, "POINTS"},
      {"PCD: a value that is not a number", "h.pcd", kPcdHead + "WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n0 zero 0\n", {}, "", cloud, "line 11"},
      {"PCD: binary data cut short", "i.pcd", kPcdHead + "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary\n012345678901234567", {}, "", cloud, "DATA"},
      {"PCD: unknown DATA kind", "j.pcd", kPcdHead + "WIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA zipped\n", {}, "", cloud, "DATA"},
      // --- PLY clouds ---------------------------------------------------------------------------
      {"PLY: no end_header", "a.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n", {}, "", cloud, "end_header"},
      {"PLY: element count not a number", "b.ply", "ply\nformat ascii 1.0\nelement vertex -3\nproperty float x\nend_header\n", {}, "", cloud, "line 3"},
      {"PLY: list count of float type", "c.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty list float int ids\nend_header\n0 0 0 1 1\n", {}, "", cloud, "line 7"},
      {"PLY: binary vertices cut short", "d.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n01234567890123456789", {}, "", cloud, "vertex"},
      {"PLY: no z property", "e.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n0 0\n", {}, "", cloud, "z"},
      {"PLY: a value that is not a number", "f.ply", kPlyHead + "0 0 0\n1 x 0\n0 1 0\n", {}, "", cloud, "line 9"},
      {"PLY: unknown format", "g.ply", "ply\nformat utf16 1.0\nelement vertex 0\nend_header\n", {}, "", cloud, "line 2"},
      {"PLY: NaN coordinate", "h.ply", kPlyHead + "0 0 0\nnan 0 0\n0 1 0\n", {}, "", cloud, "non-finite"},
      // --- meshes (db add: the database must stay byte for byte as it was) --------------------
      {"OFF mesh: face count beyond the file", "a.off", "OFF\n4 1111111111111111476 6\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n", {}, "", add, "header, faces"},
      {"OFF mesh: face names a missing vertex", "b.off", kOff + "3 0 2 1\n3 0 1 7\n3 0 3 2\n3 1 2 3\n", {}, "", add, "face 1"},
      {"OFF mesh: face line shorter than its count", "c.off", kOff + "3 0 2 1\n3 2 1\n3 0 3 2\n3 1 2 3\n", {}, "", add, "face 1"},
      {"OFF mesh: vertex with two numbers", "d.off", "OFF\n4 4 6\n0 0 0\n1 0\n0 1 0\n0 0 1\n" + kFaces, {}, "", add, "vertex 1"},
      {"PLY mesh: face list longer than its line", "e.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n200 0 1 2\n", {}, "", add, "line 13"},
      {"OFF mesh: no faces", "f.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", {}, "", add, "f.off"},
      {"OFF mesh: NaN vertex", "g.off", "OFF\n4 4 6\n0 0 0\nnan 0 0\n0 1 0\n0 0 1\n" + kFaces, {}, "", add, "vertex 1"},
      {"STL mesh: binary header declaring more triangles than stored", "h.stl", std::string(80, ' ') + std::string("\xff\xff\xff\x0f", 4) + std::string(50, '\0'), {}, "", add, "h.stl"},
      // --- manifests (db build) -----------------------------------------------------------------
      {"manifest: unknown unit", "a.tsv", "test\tnone.off\tthing\tfurlongs\n", {}, "", build, "line 1"},
      {"manifest: missing name column", "b.tsv", "test\tnone.off\n", {}, "", build, "line 1"},
      {"manifest: a name given twice", "c.tsv", "test\tx.off\tthing\ttest\ty.off\tthing\n", {}, "", build, "line"},
      {"manifest: a mesh that does not exist", "d.tsv", "test\tnowhere.off\tthing\n", {}, "", build, "nowhere.off"},
      // --- gripper descriptions (simulate) ------------------------------------------------------
      {"gripper: JSON cut short", "a.json", "{\"name\": \"g\", \"fingers\": [", {}, "", sim, "byte"},
      {"gripper: a number beyond double", "b.json", "{\"name\": \"g\", \"fingers\": 1e999}", {}, "", sim, "b.json"},
      {"gripper: unknown format", "c.json", "{\"format\": \"robotiq\"}", {}, "", sim, "format"},
      {"gripper: fingers is not a list", "d.json", "{\"format\": \"touchstone-gripper\", \"version\": 1, \"name\": \"g\", \"fingers\": 3}", {}, "", sim, "fingers"},
      // --- study configurations (experiment) ---------------------------------------------------
      {"config: unknown key", "a.toml", "objects = [\"box\"]\nruns = 1\nsteps = 2\nbananas = 3\n", {}, "", exp, "bananas"},
      {"config: runs is text", "b.toml", "objects = [\"box\"]\nruns = \"many\"\nsteps = 2\n", {}, "", exp, "runs"},
      {"config: the same key twice", "c.toml", "objects = [\"box\"]\nruns = 1\nruns = 2\nsteps = 2\n", {}, "", exp, "runs"},
      {"config: an object the database lacks", "d.toml", "objects = [\"teapot\"]\nruns = 1\nsteps = 2\n", {}, "", exp, "objects"},
      {"config: steps zero", "e.toml", "objects = [\"box\"]\nruns = 1\nsteps = 0\n", {}, "", exp, "steps"},
      // --- HDF5 stores --------------------------------------------------------------------------
      {"log: 10^9 grasps declared", "a.h5", "", [](const fs::path& f) { ts::fuzz::h5_redeclare(f, "/grasps/tactile", {1000000000, 1, 12, 6}); },
       "box_3_grasps.h5", "log export {in} --out {out}.ply", "/grasps"},
      {"log: arm poses missing", "b.h5", "", [](const fs::path& f) { ts::fuzz::h5_remove(f, "/grasps/arm_pose"); },
       "box_3_grasps.h5", "recognize --db {db} --log {in} --out {out}", "/grasps/arm_pose"},
      {"log: format attribute of another tool", "c.h5", "", [](const fs::path& f) { ts::fuzz::h5_set_text(f, "/", "format", "matlab-v7"); },
       "box_3_grasps.h5", "log info {in}", "format"},
      {"log: object pose with 2^40 rows", "d.h5", "", [](const fs::path& f) { ts::fuzz::h5_redeclare(f, "/ground_truth/object_pose", {std::uint64_t{1} << 40}); },
       "box_3_grasps.h5", "log info {in}", "/ground_truth/object_pose"},
      {"fingertip log: two fingers where the gripper has three", "fa.h5", "",
       [](const fs::path& f) { ts::fuzz::h5_redeclare(f, "/grasps/fingertip_touched", {3, 2}); },
       "box_3_fingertips.h5", "recognize --db {db} --log {in} --out {out}", "/grasps/fingertip_touched"},
      {"fingertip log: 2^40 grasps of points declared", "fb.h5", "",
       [](const fs::path& f) { ts::fuzz::h5_redeclare(f, "/grasps/fingertip_point", {std::uint64_t{1} << 40, 3, 3}); },
       "box_3_fingertips.h5", "log export {in} --out {out}.ply", "/grasps/fingertip_point"},
      {"fingertip log: normals announced, none stored", "fc.h5", "",
       [](const fs::path& f) { ts::fuzz::h5_remove(f, "/grasps/fingertip_normal"); },
       "box_3_fingertips.h5", "log info {in}", "fingertip_normal"},
      {"fingertip log: a version-1 pad log that says fingertips", "fd.h5", "",
       [](const fs::path& f) { ts::fuzz::h5_set_text(f, "/", "sensing", "fingertips"); },
       "box_3_grasps.h5", "log info {in}", "/format_version"},
      {"database: an object's fine cloud with 2^40 points", "e.h5", "", [](const fs::path& f) { ts::fuzz::h5_redeclare(f, "/objects/box/fine/points", {std::uint64_t{1} << 40, 3}); },
       "box_db.h5", "db export {in} --object box --out {out}.ply", "/objects/box/fine/points"},
      {"database: feature_dim of 10^12", "f.h5", "", [](const fs::path& f) { ts::fuzz::h5_set_number(f, "/", "feature_dim", 1e12); },
       "box_db.h5", "db info {in}", "feature_dim"},
      {"database: object order names a missing object", "g.h5", "", [](const fs::path& f) { ts::fuzz::h5_remove(f, "/objects/box"); },
       "box_db.h5", "simulate --db {in} --object box --grasps 1 --out {out}", "box"},
      {"database: congruence tolerance of 0", "j.h5", "", [](const fs::path& f) { with_congruence(f); ts::fuzz::h5_set_number(f, "/congruence", "tolerance", 0.0); },
       "box_db.h5", "db info {in}", "/congruence@tolerance"},
      {"database: 2^40 congruent pairs declared", "k.h5", "", [](const fs::path& f) { with_congruence(f); ts::fuzz::h5_redeclare(f, "/congruence/pairs", {std::uint64_t{1} << 40, 2}); },
       "box_db.h5", "db info {in}", "/congruence/"},
      {"run store: 2^40 steps declared", "h.h5", "", [](const fs::path& f) { ts::fuzz::h5_redeclare(f, "/steps/weight", {std::uint64_t{1} << 40}); },
       "box_1_run.h5", "report {in}", "/steps/weight"},
      {"run store: runs table missing", "i.h5", "", [](const fs::path& f) { ts::fuzz::h5_remove(f, "/runs/object"); },
       "box_1_run.h5", "report {in}", "/runs/object"},
  };
  return c;
}

}  // namespace

TEST_CASE("bad-input catalogue: one error naming the file and the field, exit 1, every file as it was") {
  const auto cases = catalogue();
  CHECK(cases.size() >= 40);
  for (const Case& k : cases) {
    INFO(k.what);
    TempDir dir("bad");
    const fs::path in = dir / k.name, db = dir / "db.h5", out = dir / "out.h5";
    fs::copy_file(base("box_db.h5"), db);
    ts::test::write_text(out, "an earlier output, to be left as it is\n");
    if (k.make) {
      fs::copy_file(base(k.base), in);
      k.make(in);
    } else {
      ts::test::write_text(in, k.bytes);
    }
    std::string args = replace_all(replace_all(replace_all(k.args, "{in}", in.string()), "{db}", db.string()), "{out}", out.string());
    const auto before = snapshot(dir.path());
    const auto r = ts::test::touchstone(dir, args);
    const std::string said = "touchstone " + args + "\n  said: " + r.err;
    CHECK_MESSAGE(r.code == 1, said);
    CHECK_MESSAGE(r.err.rfind("touchstone: error: ", 0) == 0, said);
    CHECK_MESSAGE(std::count(r.err.begin(), r.err.end(), '\n') == 1, said);
    CHECK_MESSAGE(r.err.find(k.name) != std::string::npos, said);
    CHECK_MESSAGE(r.err.find(k.field) != std::string::npos, said);
    CHECK_MESSAGE(snapshot(dir.path()) == before, said);
  }
}
