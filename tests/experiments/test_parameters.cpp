// The vocabulary of method parameters (experiments/params/parameters.hpp): one declaration, its names,
// values that reach the settings, the presets, and docs/parameters.md's table generated from it.
#include "experiments/params/config.hpp"
#include "experiments/params/parameters.hpp"
#include "experiments/runs/grasp_pools.hpp"

#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

using namespace ts;
using namespace ts::experiments;

TEST_CASE("Parameters: unique keys and names, each resolving to its parameter") {
  std::set<std::string> names;
  for (const Parameter& p : parameters()) {
    CAPTURE(p.key);
    if (p.kind == Parameter::Kind::method) CHECK(p.key.find('.') != std::string::npos);   // a dotted key
    CHECK(p.key.find('-') == std::string::npos);
    CHECK(find_parameter(p.key) == &p);
    CHECK(find_parameter(p.flag()) == &p);
    CHECK(p.flag().find('_') == std::string::npos);    // the rule: '_' written '-'
    CHECK_FALSE(p.help.empty());
    CHECK(names.insert(p.key).second);
    for (const auto& a : p.aliases) {
      CAPTURE(a);
      CHECK(find_parameter(a) == &p);
      CHECK(names.insert(a).second);                   // no name for two parameters
    }
  }
  CHECK(find_parameter("ransac.tripletz") == nullptr);
  // The older names scripts use.
  CHECK(find_parameter("-N")->key == "ransac.triplets");
  CHECK(find_parameter("--prune-per-object")->key == "ransac.prune_per_object");
  CHECK(find_parameter("W_obj")->key == "ransac.prune_per_object");
  CHECK(find_parameter("--n-p")->key == "bricpsf.hypotheses");
  CHECK(find_parameter("--twins")->key == "twins.rivals");
  CHECK(find_parameter("--memory-budget")->key == "memory_budget_mb");
  CHECK(find_parameter("--signal-noise")->key == "noise.sensel_noise");
  CHECK(find_parameter("--joint-sigma")->key == "noise.joint_sigma_deg");
  CHECK(find_parameter("--lateral-sigma")->key == "noise.contact_sigma_m");
  CHECK(find_parameter("--contact-sigma")->key == "noise.contact_sigma_m");
  CHECK(find_parameter("--ball-radius")->key == "probe.ball_radius_m");
  CHECK(find_parameter("--probe-tilt")->key == "probe.tilt_deg");
  CHECK(find_parameter("--quantization")->key == "probe.quantization_m");
  // The method parameters are the method kind, a contiguous part of all.
  std::size_t method = 0;
  for (const Parameter& p : parameters()) method += p.kind == Parameter::Kind::method;
  CHECK(method == method_parameters().size());
  for (const Parameter& p : method_parameters()) CHECK(p.kind == Parameter::Kind::method);
}

TEST_CASE("Parameters: each simulator and experiment parameter sets the configuration field it reads") {
  const nlohmann::ordered_json defaults = to_json(ExperimentConfig{});
  std::size_t others = 0;
  for (const Parameter& p : parameters()) {
    if (p.kind == Parameter::Kind::method) continue;
    CAPTURE(p.key);
    ++others;
    CHECK(config_keys().end() != std::find(config_keys().begin(), config_keys().end(), p.key));
    if (!p.get_config) continue;   // ransac.samples: sets the method's keys (test_config.cpp)
    CHECK(p.get_config(ExperimentConfig{}) == defaults.at(p.key));
    // A value unlike the default, read back from the field the setter wrote.
    std::string value;
    if (p.type == Parameter::Type::choice) value = p.choices.back() == defaults.at(p.key).dump() ||
                                                           p.choices.back() == defaults.at(p.key)
                                                       ? p.choices.front()
                                                       : p.choices.back();
    else if (p.type == Parameter::Type::integer) value = "3";
    else if (p.type == Parameter::Type::real) value = p.hi < 0.25 ? "0.01" : "0.25";
    else value = "cube";
    ExperimentConfig c;
    set_key(c, p.key, {value}, "study.toml");
    const nlohmann::ordered_json now = to_json(c).at(p.key);
    CHECK(now != defaults.at(p.key));
    const nlohmann::ordered_json expect = p.type == Parameter::Type::names ? nlohmann::ordered_json({value})
                                          : p.type == Parameter::Type::text || p.key == "sensors"
                                              ? nlohmann::ordered_json(value)
                                              : p.type == Parameter::Type::choice ? nlohmann::ordered_json(value)
                                                                                  : nlohmann::ordered_json::parse(value);
    if (p.key == "sensors") CHECK(now == std::stoi(value));
    else CHECK(now == expect);
    // A bad value: one error naming the file and the key.
    if (p.type == Parameter::Type::integer || p.type == Parameter::Type::real || p.type == Parameter::Type::choice) {
      try {
        set_key(c, p.key, {"-7x"}, "study.toml");
        FAIL("no error");
      } catch (const Error& e) {
        CHECK(e.file() == "study.toml");
        CHECK(e.field() == p.key);
      }
    }
  }
  CHECK(others >= 20);
}

TEST_CASE("Parameters: a value set is the value read, and explicit extensions act on any database") {
  for (const Parameter& p : method_parameters()) {
    CAPTURE(p.key);
    MethodSettings m = MethodSettings::preset("improved");
    const double now = p.get(m);
    // Another value in range: the setter and the getter must address the same field.
    double other = p.type == Parameter::Type::boolean ? 1.0 - now
                   : now + 1.0 <= p.hi                ? now + 1.0
                   : p.type == Parameter::Type::real  ? 0.5 * (p.lo + p.hi)   // a range narrower than 1
                                                      : p.lo;
    if (p.type == Parameter::Type::real && now > p.lo) other = p.lo + 0.5 * (now - p.lo);
    REQUIRE(other != now);
    apply(m, p, other);
    CHECK(p.get(m) == other);
    if (p.min_database) CHECK(p.min_database(m) == 0);
    // The text of a value parses back to it.
    CHECK(parse_value(p, p.text(other)) == other);
    // Only this parameter changed among the stored ones.
    const auto before = stored_parameters(MethodSettings::preset("improved"));
    const auto after = stored_parameters(m);
    for (std::size_t i = 0; i < before.size(); ++i)
      if (before[i].first != p.key) CHECK_MESSAGE(before[i].second == after[i].second, before[i].first);
  }
  // The presets: the paper's values where the paper gives them.
  const MethodSettings paper = MethodSettings::preset("paper");
  CHECK(find_parameter("ransac.triplets")->get(paper) == 15);
  CHECK(find_parameter("ransac.registrations")->get(paper) == 200);
  CHECK(find_parameter("ransac.prune")->get(paper) == 3000);
  CHECK(find_parameter("bricpsf.hypotheses")->get(paper) == 100);
  CHECK(find_parameter("bricpsf.psi")->get(paper) == 0.8);
  CHECK(find_parameter("bricpsf.lambda")->get(paper) == 0.02);
  CHECK(find_parameter("ransac.d_outlier_m")->get(paper) == 0.2);
  CHECK(find_parameter("ransac.prune_per_object")->get(paper) == 0);
  CHECK(find_parameter("ransac.prune_per_object")->get(MethodSettings::preset("improved")) == 200);
  CHECK_THROWS_AS(MethodSettings::preset("fast"), Error);
}

TEST_CASE("Parameters: bad values are one error naming the key") {
  const Parameter& n = *find_parameter("ransac.triplets");
  auto message = [&](const std::string& text) {
    try {
      parse_value(n, text);
    } catch (const Error& e) {
      return e.message();
    }
    return std::string("no error");
  };
  CHECK(message("0") == "ransac.triplets must be at least 1 (got 0)");
  CHECK(message("1.5") == "ransac.triplets must be an integer (got '1.5')");
  CHECK_THROWS_AS(parse_value(*find_parameter("bricpsf.psi"), "1.5"), Error);
  CHECK_THROWS_AS(parse_value(*find_parameter("bricpsf.dedupe"), "maybe"), Error);
  CHECK(parse_value(*find_parameter("icp.metric"), "point_to_plane") == 1);
  CHECK_THROWS_AS(parse_value(*find_parameter("icp.metric"), "plane"), Error);
  // Through the configuration: the file and the key named.
  ExperimentConfig c;
  try {
    set_key(c, "bricpsf.psi", {"2"}, "study.toml");
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.file() == "study.toml");
    CHECK(e.field() == "bricpsf.psi");
  }
  set_key(c, "bricpsf.dedupe", {"false"});
  CHECK(c.params.at("bricpsf.dedupe") == 0.0);
  CHECK(to_json(c).at("bricpsf.dedupe") == false);
}

TEST_CASE("Parameters: the README's table is the declaration's (touchstone params --markdown)") {
  // The table lives in docs/parameters.md (the README was split into docs/; the test's name is
  // kept so that test filters and tier lists still find it).
  std::ifstream in(std::filesystem::path(TS_SOURCE_DIR) / "docs" / "parameters.md");
  REQUIRE(in);
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string readme = buffer.str();
  const std::string begin = "<!-- parameters: begin (touchstone params --markdown) -->\n";
  const std::string end = "<!-- parameters: end -->";
  const auto a = readme.find(begin);
  const auto b = readme.find(end);
  REQUIRE(a != std::string::npos);
  REQUIRE(b != std::string::npos);
  CHECK_MESSAGE(readme.substr(a + begin.size(), b - a - begin.size()) == parameters_markdown(),
                "docs/parameters.md's parameter table is stale: replace it by `touchstone params --markdown`");
}

TEST_CASE("Parameters: the noise overrides reach the simulator (simulate's flags and experiment keys alike)") {
  ExperimentConfig c;
  c.noise = "deepsea";
  const datasets::SimulatorSettings profile = simulation_settings(c);
  CHECK(profile.noise.lateral_sigma == 0.002);   // the deep-sea profile's
  CHECK(profile.noise.joint_sigma_deg == 0.0);
  set_key(c, "noise.joint_sigma_deg", {"0.5"}, "study.toml");
  set_key(c, "noise.contact_sigma_m", {"0.0007"}, "study.toml");
  const datasets::SimulatorSettings pads = simulation_settings(c);
  CHECK(pads.noise.joint_sigma_deg == 0.5);
  CHECK(pads.noise.lateral_sigma == 0.0007);      // pads: a sensel's lateral error
  CHECK(pads.probe.contact_sigma == 0.0);
  set_key(c, "sensing", {"probe"}, "study.toml");
  const datasets::SimulatorSettings probe = simulation_settings(c);
  CHECK(probe.probe.contact_sigma == 0.0007);     // a probe: its own noise, and no sensel error
  CHECK(probe.noise.lateral_sigma == 0.0);
  CHECK(probe.noise.joint_sigma_deg == 0.5);
}

TEST_CASE("Parameters: noise.arm_scale multiplies both arm errors, after the profile and their own keys") {
  ExperimentConfig c;   // underwater: 3 mm and 1 degree
  const datasets::SimulatorSettings profile = simulation_settings(c);
  REQUIRE(profile.noise.arm_position_sigma == 0.003);
  REQUIRE(profile.noise.arm_rotation_sigma_deg == 1.0);
  set_key(c, "noise.arm_scale", {"0.5"}, "study.toml");
  const datasets::SimulatorSettings half = simulation_settings(c);
  CHECK(half.noise.arm_position_sigma == doctest::Approx(0.0015).scale(0).epsilon(1e-12));
  CHECK(half.noise.arm_rotation_sigma_deg == doctest::Approx(0.5).scale(0).epsilon(1e-12));
  CHECK(half.noise.lateral_sigma == profile.noise.lateral_sigma);   // the sensors' noise stays
  CHECK(pool_key(half) != pool_key(profile));                      // its own grasp pools
  set_key(c, "noise.arm_position_sigma_m", {"0.002"}, "study.toml");
  const datasets::SimulatorSettings both = simulation_settings(c);
  CHECK(both.noise.arm_position_sigma == doctest::Approx(0.001).scale(0).epsilon(1e-12));
  CHECK(both.noise.arm_rotation_sigma_deg == doctest::Approx(0.5).scale(0).epsilon(1e-12));
  set_key(c, "noise.arm_scale", {"0"}, "study.toml");
  const datasets::SimulatorSettings none = simulation_settings(c);
  CHECK(none.noise.arm_position_sigma == 0.0);
  CHECK(none.noise.arm_rotation_sigma_deg == 0.0);
  try {
    set_key(c, "noise.arm_scale", {"-1"}, "study.toml");
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.field() == "noise.arm_scale");
  }
}

TEST_CASE("Parameters: the probe overrides reach the simulator; unset, its defaults stay") {
  ExperimentConfig c;
  c.sensing = "probe";
  const datasets::SimulatorSettings plain = simulation_settings(c);
  const datasets::ProbeSettings defaults;
  CHECK(plain.probe.spec.ball_radius == defaults.spec.ball_radius);
  CHECK(plain.probe.spec.shaft_radius == defaults.spec.shaft_radius);
  CHECK(plain.probe.max_tilt_deg == defaults.max_tilt_deg);
  CHECK(plain.probe.quantization == defaults.quantization);
  set_key(c, "probe.ball_radius_m", {"0.0015"}, "study.toml");
  set_key(c, "probe.tilt_deg", {"35"}, "study.toml");
  set_key(c, "probe.quantization_m", {"0.001"}, "study.toml");
  const datasets::SimulatorSettings s = simulation_settings(c);
  CHECK(s.probe.spec.ball_radius == 0.0015);
  CHECK(s.probe.spec.shaft_radius == 0.0015);   // the shaft is never wider than the ball
  CHECK(s.probe.max_tilt_deg == 35.0);
  CHECK(s.probe.quantization == 0.001);
  CHECK(pool_key(s) != pool_key(plain));         // different pools
  // Out of range: one error naming the key.
  try {
    set_key(c, "probe.tilt_deg", {"95"}, "study.toml");
    FAIL("no error");
  } catch (const Error& e) {
    CHECK(e.field() == "probe.tilt_deg");
  }
}
