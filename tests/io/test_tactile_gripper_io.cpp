// Gripper description files: the shipped file equals the compiled-in default, serialization
// round-trips, and bad files give one clear error naming the file and the field.
#include "io/gripper_io.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <cmath>

#include <filesystem>
#include <fstream>

using namespace ts;

namespace {
void check_same(const GripperSpec& a, const GripperSpec& b) {
  CHECK(a.name == b.name);
  CHECK(a.single_pad == b.single_pad);
  CHECK(a.palm.radius == doctest::Approx(b.palm.radius));
  CHECK(a.palm.thickness == doctest::Approx(b.palm.thickness));
  CHECK(a.sensor.rows == b.sensor.rows);
  CHECK(a.sensor.cols == b.sensor.cols);
  CHECK(a.sensor.foam_thickness == doctest::Approx(b.sensor.foam_thickness));
  CHECK(a.sensor.peak_compression == doctest::Approx(b.sensor.peak_compression));
  CHECK(a.sensor.signal_peak == doctest::Approx(b.sensor.signal_peak));
  REQUIRE(a.fingers.size() == b.fingers.size());
  for (std::size_t f = 0; f < a.fingers.size(); ++f) {
    CHECK(a.fingers[f].name == b.fingers[f].name);
    CHECK(a.fingers[f].T_eef_base.isApprox(b.fingers[f].T_eef_base, 1e-9));
    REQUIRE(a.fingers[f].links.size() == b.fingers[f].links.size());
    for (std::size_t k = 0; k < a.fingers[f].links.size(); ++k) {
      const auto& x = a.fingers[f].links[k];
      const auto& y = b.fingers[f].links[k];
      CHECK(x.name == y.name);
      CHECK(x.length == doctest::Approx(y.length));
      CHECK(x.width == doctest::Approx(y.width));
      CHECK(x.thickness == doctest::Approx(y.thickness));
      CHECK((x.joint_origin - y.joint_origin).norm() < 1e-12);
      CHECK((x.joint_axis - y.joint_axis).norm() < 1e-12);
      CHECK(x.open == doctest::Approx(y.open));
      CHECK(x.min == doctest::Approx(y.min));
      CHECK(x.max == doctest::Approx(y.max));
      CHECK(x.has_pad == y.has_pad);
      if (x.has_pad) CHECK(x.T_link_pad.isApprox(y.T_link_pad, 1e-9));
    }
  }
}

void expect_gripper_error(const std::string& text, const std::string& field) {
  try {
    io::parse_gripper(text, "bad.json");
    FAIL("no error for field " << field);
  } catch (const Error& e) {
    CHECK(e.file() == "bad.json");
    INFO(e.what());
    CHECK(e.field().find(field) != std::string::npos);
  }
}

std::string default_text() { return io::gripper_to_json(default_gripper_spec()); }
}  // namespace

TEST_CASE("the shipped gripper file is the compiled-in default") {
  const auto path = std::filesystem::path(TS_SOURCE_DIR) / "datasets/grippers/touchstone-3f.json";
  const Gripper g = io::read_gripper(path);
  check_same(g.spec(), default_gripper_spec());
}

TEST_CASE("gripper JSON round trip") {
  GripperSpec spec = default_gripper_spec();
  spec.name = "custom";
  spec.fingers[1].links[0].has_pad = false;
  spec.fingers[2].T_eef_base.linear() =
      Eigen::AngleAxisd(0.3, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  spec.sensor.rows = 10;
  spec.sensor.foam_thickness = 0.005;
  const Gripper g = io::parse_gripper(io::gripper_to_json(spec));
  check_same(g.spec(), spec);
  CHECK(g.pads().size() == 5);
}

TEST_CASE("quaternion mounts and default joint origins are accepted") {
  auto j = nlohmann::json::parse(default_text());
  auto& pad = j["fingers"][0]["links"][1]["pad"];
  pad.erase("rpy_deg");
  pad["q_wxyz"] = {std::sqrt(0.5), 0.0, -std::sqrt(0.5), 0.0};  // -90° about y
  j["fingers"][0]["links"][1]["joint"].erase("origin_m");     // default: tip of the parent
  const Gripper g = io::parse_gripper(j.dump());
  check_same(g.spec(), default_gripper_spec());
}

TEST_CASE("gripper files that do not parse or are wrong name the field") {
  expect_gripper_error("{\"name\": \"x\", ", "byte");
  expect_gripper_error("[1, 2]", "");
  expect_gripper_error("{\"name\": \"x\"}", "fingers");
  const auto base = nlohmann::json::parse(default_text());
  auto edit = [&](auto&& f) {
    auto j = base;
    f(j);
    return j.dump();
  };
  expect_gripper_error(edit([](auto& j) { j["fingers"][0]["links"][0]["length_m"] = "long"; }),
               "fingers[0].links[0].length_m");
  expect_gripper_error(edit([](auto& j) { j["fingers"][0]["links"][0]["length_m"] = -1; }), "fingers[0].links[0]");
  expect_gripper_error(edit([](auto& j) { j["fingers"][0]["links"][0].erase("name"); }), "fingers[0].links[0].name");
  expect_gripper_error(edit([](auto& j) { j["fingers"][1]["links"][1]["joint"]["axis"] = {0, 0}; }),
               "fingers[1].links[1].joint.axis");
  expect_gripper_error(edit([](auto& j) { j["single_pad"] = "thumb.distal"; }), "single_pad");
  expect_gripper_error(edit([](auto& j) { j["sensor"]["rows"] = 12.5; }), "sensor.rows");
  expect_gripper_error(edit([](auto& j) { j["sensor"]["response"]["peak"] = 1.5; }), "sensor.response");
  expect_gripper_error(edit([](auto& j) { j["format"] = "urdf"; }), "format");
  CHECK_THROWS_AS(io::read_gripper("/nonexistent/gripper.json"), Error);
}
