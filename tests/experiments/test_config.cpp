// Experiment configuration: files, flags, sweeps and clear errors that name the key.
#include "datasets/catalogue/catalogue.hpp"
#include "datasets/manifest.hpp"
#include "experiments/params/config.hpp"

#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

using namespace ts;
using namespace ts::experiments;
namespace fs = std::filesystem;

namespace {
struct TempFile {
  fs::path path;
  explicit TempFile(const std::string& text, const std::string& ext = ".toml") {
    static int counter = 0;
    path = fs::temp_directory_path() /
           ("ts_config_" + std::to_string(::getpid()) + "_" + std::to_string(counter++) + ext);
    std::ofstream(path) << text;
  }
  ~TempFile() { fs::remove(path); }
};

/// The error of loading `text`, as (message, field).
std::pair<std::string, std::string> load_error(const std::string& text) {
  TempFile f(text);
  ExperimentConfig c;
  try {
    load_config_file(c, f.path);
  } catch (const Error& e) {
    CHECK(e.file() == f.path.string());
    return {e.message(), e.field()};
  }
  FAIL("no error for: " << text);
  return {};
}
}  // namespace

TEST_CASE("A TOML study file with sections, dotted keys and a sweep") {
  TempFile f(R"(# study 1
name = "batch-ransac-samples"
description = "Figure 12: Batch RANSAC alone, pitcher-like object"
objects = ["bunny", "cube"]
runs = 50
steps = 40
pool = 60
method = "batch-ransac"
noise = "underwater"
sensors = 6
seed = 7
noise.sensel_noise = 0.1

[ransac]
prune = 3000
d_outlier_m = 0.2

[bricpsf]
hypotheses = 100
psi = 0.8

[sweep]
ransac.samples = ["15x200", "50x200", "50x500", "100x1000"]
)");
  ExperimentConfig c;
  load_config_file(c, f.path);
  CHECK(c.name == "batch-ransac-samples");
  CHECK(c.description == "Figure 12: Batch RANSAC alone, pitcher-like object");
  REQUIRE(c.objects.size() == 2);
  CHECK(c.objects[1] == "cube");
  CHECK(c.runs == 50);
  CHECK(c.steps == 40);
  CHECK(c.pool == 60);
  CHECK(c.method == "batch-ransac");
  CHECK(c.sensors == 6);
  CHECK(c.seed == 7);
  CHECK(*c.noise_params.sensel_noise == 0.1);
  CHECK_FALSE(c.noise_params.force_noise.has_value());
  CHECK(c.params.at("ransac.prune") == 3000);
  CHECK(c.params.at("ransac.d_outlier_m") == 0.2);
  CHECK(c.params.at("bricpsf.hypotheses") == 100);
  CHECK(c.params.at("bricpsf.psi") == 0.8);
  REQUIRE(c.sweep.size() == 1);
  CHECK(c.sweep[0].key == "ransac.samples");

  const auto variants = expand_variants(c);
  REQUIRE(variants.size() == 4);
  CHECK(variants[0].label == "ransac.samples=15x200");
  CHECK(variants[0].config.params.at("ransac.triplets") == 15);
  CHECK(variants[0].config.params.at("ransac.registrations") == 200);
  CHECK(variants[3].config.params.at("ransac.triplets") == 100);
  CHECK(variants[3].config.params.at("ransac.registrations") == 1000);
  CHECK(variants[3].config.sweep.empty());
  CHECK(variants[3].config.runs == 50);
}

TEST_CASE("INI files and a two-axis sweep (first key slowest)") {
  TempFile f(
      "runs=3\nsteps=5\npool=5\n[sweep]\nnoise.arm_position_sigma_m = 0, 0.003, 0.006\n"
      "noise.sensel_noise = 0.0, 0.05\n",
      ".ini");
  ExperimentConfig c;
  load_config_file(c, f.path);
  const auto v = expand_variants(c);
  REQUIRE(v.size() == 6);
  CHECK(v[0].label == "noise.arm_position_sigma_m=0, noise.sensel_noise=0.0");
  CHECK(v[1].label == "noise.arm_position_sigma_m=0, noise.sensel_noise=0.05");
  CHECK(*v[5].config.noise_params.arm_position_sigma_m == 0.006);
  CHECK(*v[5].config.noise_params.sensel_noise == 0.05);
}

TEST_CASE("Impossible values and unknown keys name the key") {
  auto e = load_error("runs = -5\n");
  CHECK(e.second == "runs");
  CHECK(e.first.find("at least 1") != std::string::npos);
  CHECK(e.first.find("-5") != std::string::npos);

  CHECK(load_error("steps = 0\n").second == "steps");
  CHECK(load_error("runs = 2.5\n").second == "runs");
  CHECK(load_error("runs = many\n").second == "runs");
  CHECK(load_error("method = magic\n").second == "method");
  CHECK(load_error("preset = papr\n").second == "preset");
  CHECK(load_error("[ransac]\nprune_per_object = -1\n").second == "ransac.prune_per_object");
  CHECK(load_error("[evaluate]\ngrasp_offset_sigma_m = -0.001\n").second == "evaluate.grasp_offset_sigma_m");
  CHECK(load_error("noise = shallow\n").second == "noise");
  CHECK(load_error("sensors = 3\n").second == "sensors");
  CHECK(load_error("seed = -1\n").second == "seed");
  CHECK(load_error("[bricpsf]\npsi = 1.5\n").second == "bricpsf.psi");
  CHECK(load_error("noise.sensel_noise = -0.1\n").second == "noise.sensel_noise");
  CHECK(load_error("objects = [\"a\", \"a\"]\n").second == "objects");
  CHECK(load_error("runs = 3\nruns = 4\n").second == "runs");
  CHECK(load_error("steps = 60\n").second == "pool");  // default pool 50 < 60 steps
  auto pr = load_error("protocol = shared\n");
  CHECK(pr.second == "protocol");
  CHECK(pr.first.find("independent, shared_pool") != std::string::npos);
  CHECK(load_error("[sweep]\nprotocol = [\"independent\", \"shared_pool\"]\n").second == "sweep.protocol");

  auto u = load_error("[ransac]\ntriplet = 15\n");
  CHECK(u.second == "ransac.triplet");
  CHECK(u.first.find("unknown key") != std::string::npos);
  CHECK(u.first.find("did you mean 'ransac.triplets'") != std::string::npos);
  CHECK(load_error("colour = 3\n").second == "colour");

  auto s = load_error("[sweep]\nruns = [1, 2]\n");
  CHECK(s.second == "sweep.runs");
  CHECK(load_error("[sweep]\nmethod = [\"bricpsf\", \"nope\"]\n").second == "sweep.method");
  CHECK(load_error("[sweep]\nransac.samples = [\"15x0\"]\n").second == "sweep.ransac.samples");
  CHECK(load_error("[sweep]\nbogus = [1]\n").second == "sweep.bogus");

  ExperimentConfig c;
  CHECK_THROWS_AS(load_config_file(c, "/nonexistent/exp.toml"), Error);
}

TEST_CASE("Sizes that cannot fit in memory are refused from the configuration, naming the key") {
  // Issue 57: a sampling of 1e8 x 1e8, or runs and steps of 1e8, ended in std::bad_alloc after
  // the run store was made.
  auto e = load_error("ransac.samples = \"100000000x100000000\"\n");
  CHECK(e.second == "ransac.samples");
  CHECK(e.first.find("from 1 to 1000000 (ransac.triplets") != std::string::npos);
  e = load_error("ransac.samples = \"1000000x1000000\"\n");
  CHECK(e.second == "ransac.samples");
  CHECK(e.first.find("ransac.triplets x ransac.registrations = 1000000 x 1000000 registrations a step") != std::string::npos);
  CHECK(load_error("[sweep]\nransac.samples = [\"15x200\", \"1000000x1000000\"]\n").second == "sweep.ransac.samples");
  CHECK(load_error("runs = 100000000\nsteps = 1000000\npool = 1000000\n").second == "runs");
  CHECK(load_error("runs = 2\nsteps = 100000000\npool = 100000000\n").second == "steps");

  // The bounds, against a memory given: 45 objects x 20 runs x 40 steps x 4 variants of step
  // records fit in 1 GB, 1 000 runs do not; the objects count where the configuration lists
  // none (all of the database).
  ExperimentConfig c;
  set_key(c, "sweep.method", {"bricpsf", "batch-ransac", "ransac-icp", "ransac-icp-fs"});
  CHECK_NOTHROW(check_memory(c, 45, "exp.toml", 1e9));
  c.runs = 1000;
  try {
    check_memory(c, 45, "exp.toml", 1e9);
    FAIL("no error");
  } catch (const Error& x) {
    CHECK(x.file() == "exp.toml");
    CHECK(x.field() == "runs");
    CHECK(x.message().find("1000 x 40 x 4 x 45 step records") != std::string::npos);
  }
  c.runs = 20;
  CHECK_THROWS_WITH_AS(check_memory(c, 2000000, "exp.toml", 1e9), doctest::Contains("(exp.toml, objects)"), Error);
  c.pool = 10000000;   // 10^7 grasps of a pool: at least a few GB
  CHECK_THROWS_WITH_AS(check_memory(c, 1, "exp.toml", 1e9), doctest::Contains("(exp.toml, pool)"), Error);
}

TEST_CASE("Flags use the same setter as files") {
  ExperimentConfig c;
  set_key(c, "objects", {"sphere,cube , bunny"});
  REQUIRE(c.objects.size() == 3);
  CHECK(c.objects[1] == "cube");
  set_key(c, "objects", {"all"});
  CHECK(c.objects.empty());
  set_key(c, "ransac.samples", {"50x500"});
  CHECK(c.params.at("ransac.triplets") == 50);
  CHECK(c.params.at("ransac.registrations") == 500);
  CHECK(c.preset == "improved");  // the default: Touchstone's extensions
  set_key(c, "preset", {"paper"});
  CHECK(c.preset == "paper");
  set_key(c, "ransac.prune_per_object", {"0"});
  CHECK(c.params.at("ransac.prune_per_object") == 0);
  set_key(c, "evaluate.grasp_offset_sigma_m", {"0.004"});
  CHECK(c.params.at("evaluate.grasp_offset_sigma_m") == 0.004);
  set_key(c, "shortlist.objects", {"24"});
  set_key(c, "twins.rivals", {"0"});
  set_key(c, "ransac.object_draws", {"100"});
  set_key(c, "ransac.prune_blocks", {"3"});
  set_key(c, "memory_budget_mb", {"512"});
  CHECK(c.params.at("shortlist.objects") == 24);
  CHECK(c.params.at("twins.rivals") == 0);
  CHECK(c.params.at("ransac.object_draws") == 100);
  CHECK(c.params.at("ransac.prune_blocks") == 3);
  CHECK(*c.memory_budget_mb == 512.0);
  CHECK_THROWS_AS(set_key(c, "shortlist.objects", {"-1"}), Error);
  CHECK_THROWS_AS(set_key(c, "memory_budget_mb", {"-5"}), Error);
  try {
    set_key(c, "runs", {"-1"});
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.field() == "runs");
    CHECK(e.file().empty());
  }
  CHECK_THROWS_AS(set_key(c, "ransac.samples", {"50"}), Error);
  CHECK_THROWS_AS(set_key(c, "objects", {"all,cube"}), Error);
}

TEST_CASE("Objects resolve against the database; unknown names are errors") {
  const std::vector<std::string> db{"a", "b", "c", "d", "e"};
  ExperimentConfig c;
  auto all = resolve_objects(c, db);
  CHECK(all.explored == db);
  CHECK(all.database == db);

  set_key(c, "objects", {"d,b"});
  set_key(c, "database_size", {"3"});
  auto r = resolve_objects(c, db);
  CHECK(r.explored == std::vector<std::string>{"d", "b"});
  CHECK(r.database == std::vector<std::string>{"d", "b", "a"});

  set_key(c, "objects", {"d,zz"});
  try {
    resolve_objects(c, db);
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.field() == "objects");
    CHECK(e.message().find("zz") != std::string::npos);
  }
  ExperimentConfig big;
  set_key(big, "database_size", {"6"});
  CHECK_THROWS_AS(resolve_objects(big, db), Error);
  ExperimentConfig sub;
  set_key(sub, "objects", {"a"});
  set_key(sub, "database", {"b,c"});
  CHECK_THROWS_AS(resolve_objects(sub, db), Error);
}

TEST_CASE("Canonical JSON and the first result-determining difference") {
  ExperimentConfig a;
  ExperimentConfig b = a;
  b.name = "renamed";
  b.schedule = "steps";
  CHECK(first_difference(to_json(a), to_json(b)).empty());
  b.params["ransac.prune"] = 1000;
  CHECK(first_difference(to_json(a), to_json(b)) == "ransac.prune");
  ExperimentConfig c = a;
  set_key(c, "sweep.method", {"bricpsf", "ransac-icp"});
  CHECK(first_difference(to_json(a), to_json(c)) == "sweep");
  const auto j = to_json(a);
  CHECK(j.at("objects") == "all");
  CHECK(j.at("runs") == 20);
  CHECK(j.at("ransac.triplets").is_null());
  CHECK_FALSE(j.contains("ransac.samples"));  // derived key, not stored twice
  // Independent runs by default; the protocol determines results (a resumed store cannot mix).
  CHECK(j.at("protocol") == "independent");
  ExperimentConfig d = a;
  set_key(d, "protocol", {"shared_pool"});
  CHECK(d.protocol == "shared_pool");
  CHECK(first_difference(to_json(a), to_json(d)) == "protocol");
}

TEST_CASE("Every study configuration of experiments/studies parses") {
  const fs::path dir = fs::path(TS_SOURCE_DIR) / "experiments" / "studies";
  // Their objects must be in the default database (the manifest it is built from).
  std::vector<std::string> dev45;
  for (const auto& m : datasets::read_manifest(fs::path(TS_SOURCE_DIR) / "datasets" / "dev45.tsv"))
    dev45.push_back(m.name);
  REQUIRE(dev45.size() == 45);
  std::size_t n = 0;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.path().extension() != ".toml") continue;
    if (e.path().filename() == "registry.toml") continue;   // the study registry (scripts/results check)
    ++n;
    CAPTURE(e.path().string());
    ExperimentConfig c;
    load_config_file(c, e.path());
    CHECK_FALSE(c.name.empty());
    CHECK_NOTHROW(validate(c, e.path().string()));
    CHECK(expand_variants(c).size() >= 1);
    if (e.path().filename() == "study7_db450.toml") continue;   // its database is db450.h5
    // A catalogue database's objects are named family_<index>, the index of the catalogue's
    // round robin over its families, within the `count` objects its recipe builds.
    auto catalogue_names = [&](const std::string& families_wanted, std::size_t families_n, std::size_t explored,
                               std::size_t count) {
      const auto families = ts::catalogue::FamilySet::select(families_wanted).families;
      REQUIRE(families.size() == families_n);
      CHECK(c.objects.size() == explored);
      for (const std::string& name : c.objects) {
        CAPTURE(name);
        const auto cut = name.rfind('_');
        REQUIRE(cut != std::string::npos);
        const std::size_t index = std::stoul(name.substr(cut + 1));
        CHECK(index < count);
        CHECK(name.substr(0, cut) == families[index % families.size()].name);
      }
    };
    if (e.path().filename() == "study7_catalogue.toml" || e.path().filename() == "study14_fingertips_cat450.toml") {
      catalogue_names("", 18, 20, 450);   // all 18 families, the 450 the study builds
      continue;
    }
    if (e.path().filename() == "study16_near_twins.toml") {
      catalogue_names("flange_blind,flange_weld_neck,hex_nut", 3, 24, 120);   // registry recipe twins120
      continue;
    }
    const ResolvedObjects r = resolve_objects(c, dev45);
    CHECK_FALSE(r.explored.empty());
    if (c.objects.empty()) CHECK(r.explored.size() == 45);
  }
  CHECK(n >= 10);
}

TEST_CASE("Hidden objects (open set): out of the recognizer's database, still explored; bad names are errors") {
  const std::vector<std::string> db{"a", "b", "c", "d"};
  ExperimentConfig c;
  set_key(c, "objects", {"a,c"});
  set_key(c, "hidden", {"c,d"});
  auto r = resolve_objects(c, db);
  CHECK(r.explored == std::vector<std::string>{"a", "c"});
  CHECK(r.database == std::vector<std::string>{"a", "b"});
  CHECK(r.hidden == std::vector<std::string>{"c"});
  CHECK_FALSE(r.hide_each);
  CHECK(to_json(c).at("hidden") == nlohmann::ordered_json({"c", "d"}));

  ExperimentConfig each;
  set_key(each, "hidden", {"each"});
  auto e = resolve_objects(each, db);
  CHECK(e.hide_each);
  CHECK(e.database == db);   // masked per run, not removed
  CHECK(e.hidden == db);

  auto error_of = [&](const std::string& hidden) {
    ExperimentConfig x;
    set_key(x, "hidden", {hidden});
    try {
      resolve_objects(x, db);
    } catch (const Error& err) {
      return err.field() + ": " + err.message();
    }
    return std::string("no error");
  };
  CHECK(error_of("zz").find("hidden: hidden object 'zz' is not in the database") == 0);
  CHECK(error_of("each,a").rfind("hidden: ", 0) == 0);
  CHECK(error_of("a,b,c,d").rfind("hidden: every database object is hidden", 0) == 0);
  CHECK(load_error("hidden = [\"a\", \"a\"]\n").second == "hidden");
}
