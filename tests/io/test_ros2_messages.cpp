// io/ros2_messages.hpp: CDR decoding of the ROS 2 messages of a tactile recording, against a
// TFMessage serialized by ROS 2 itself, round trips, big-endian input and malformed messages.
#include "io/ros2_messages.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <string>

using namespace ts::io::ros2;

namespace {

std::vector<std::uint8_t> hex(const std::string& h) {
  std::vector<std::uint8_t> b;
  for (std::size_t i = 0; i + 1 < h.size(); i += 2) b.push_back(static_cast<std::uint8_t>(std::stoi(h.substr(i, 2), nullptr, 16)));
  return b;
}

ts::Pose pose(double x, double y, double z, double angle, ts::Vec3 axis) {
  ts::Pose T = ts::Pose::Identity();
  T.linear() = Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
  T.translation() = ts::Vec3(x, y, z);
  return T;
}

}  // namespace

TEST_CASE("ROS 2 CDR: a TFMessage serialized by ROS 2 (the MCAP project's test bytes)") {
  // tf2_msgs/msg/TFMessage from mcap's python/mcap-ros2-support/tests/test_cdr_reader.py: one
  // transform base_link -> radar, stamp 1490149580 s 117017840 ns, x = 3.835, no rotation.
  const auto b = hex(
      "0001000001000000cce0d158f08cf9060a000000626173655f6c696e6b00000006000000"
      "7261646172000000ae47e17a14ae0e400000000000000000000000000000000000000000"
      "0000000000000000000000000000000000000000000000000000f03f");
  const auto tf = decode_tf_message(b, "rec.mcap", "message 1 on /tf");
  REQUIRE(tf.size() == 1);
  CHECK(tf[0].stamp.sec == 1490149580);
  CHECK(tf[0].stamp.nanosec == 117017840u);
  CHECK(tf[0].frame_id == "base_link");
  CHECK(tf[0].child_frame_id == "radar");
  CHECK(tf[0].transform.translation() == ts::Vec3(3.835, 0.0, 0.0));
  CHECK(tf[0].transform.linear() == ts::Mat3::Identity());
  CHECK(encode_tf_message(tf) == b);   // the writer gives ROS 2's bytes back
}

TEST_CASE("ROS 2 CDR: every message round-trips, with the padding odd string lengths need") {
  PoseStamped p;
  p.stamp = {12, 345};
  p.frame_id = "ab";   // 3 bytes with its NUL: the doubles after it are padded to 8
  p.pose = pose(0.1, -2.5, 3e3, 0.7, ts::Vec3(1, 2, 3));
  const PoseStamped q = decode_pose_stamped(encode_pose_stamped(p), "f", "w");
  CHECK(q.stamp.sec == 12);
  CHECK(q.stamp.nanosec == 345u);
  CHECK(q.frame_id == "ab");
  CHECK((q.pose.matrix() - p.pose.matrix()).cwiseAbs().maxCoeff() < 1e-15);

  JointState j;
  j.stamp = {7, 8};
  j.name = {"f1.proximal", "f1.distal", "f2"};
  j.position = {0.1, 0.2, -0.3};
  j.velocity = {};
  j.effort = {1.0, NAN, 2.0};
  const JointState k = decode_joint_state(encode_joint_state(j), "f", "w");
  CHECK(k.name == j.name);
  CHECK(k.position == j.position);
  CHECK(k.velocity.empty());
  REQUIRE(k.effort.size() == 3);
  CHECK(std::isnan(k.effort[1]));

  Float32MultiArray a;
  a.dim = {{"pads", 2, 144}, {"sensels", 72, 72}};
  for (int i = 0; i < 144; ++i) a.data.push_back(0.5f * static_cast<float>(i));
  const Float32MultiArray c = decode_float32_multi_array(encode_float32_multi_array(a), "f", "w");
  REQUIRE(c.dim.size() == 2);
  CHECK(c.dim[1].label == "sensels");
  CHECK(c.dim[1].size == 72u);
  CHECK(c.data == a.data);
}

TEST_CASE("ROS 2 CDR: big-endian input") {
  // Float32MultiArray, big-endian: no dimensions, data_offset 0, data {1.5, -2}.
  const auto fixed = hex("00000000" "00000000" "00000000" "00000002" "3fc00000" "c0000000");
  const auto a = decode_float32_multi_array(fixed, "f", "w");
  CHECK(a.dim.empty());
  CHECK(a.data == std::vector<float>{1.5f, -2.0f});
}

TEST_CASE("ROS 2 CDR: malformed messages give one error naming the file, the message and the field") {
  PoseStamped p;
  p.frame_id = "world";
  p.pose = pose(1, 2, 3, 0.3, ts::Vec3(0, 0, 1));
  const auto good = encode_pose_stamped(p);
  // Cut at every length: refused, never read past the end.
  for (std::size_t n = 0; n < good.size(); ++n) {
    std::vector<std::uint8_t> cut(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(n));
    CHECK_THROWS_AS(decode_pose_stamped(cut, "f", "w"), ts::Error);
  }
  auto field_of = [](auto&& decode) -> std::string {
    try {
      decode();
    } catch (const ts::Error& e) {
      CHECK(e.file() == "rec.mcap");
      return e.field();
    }
    return "";
  };
  // A quaternion far from unit length.
  auto bad_q = good;
  bad_q[bad_q.size() - 1] = 0x40;   // w's exponent: |w| >= 2
  CHECK(field_of([&] { decode_pose_stamped(bad_q, "rec.mcap", "message 3 on /arm"); }) == "message 3 on /arm: pose");
  // A sequence declaring 2^31 elements in a few bytes.
  Float32MultiArray a;
  a.data = {1.0f, 2.0f};
  auto huge = encode_float32_multi_array(a);
  huge[12] = 0x00, huge[13] = 0x00, huge[14] = 0x00, huge[15] = 0x80;   // the data count
  CHECK(field_of([&] { decode_float32_multi_array(huge, "rec.mcap", "m"); }) == "m: data");
  // A string without its NUL.
  auto no_nul = good;
  no_nul[16 + 5] = 'x';   // frame_id "world\0" (its length at 12, its bytes from 16) -> "worldx"
  CHECK(field_of([&] { decode_pose_stamped(no_nul, "rec.mcap", "m"); }) == "m: header.frame_id");
  // Not CDR.
  auto xcdr2 = good;
  xcdr2[1] = 0x07;
  CHECK(field_of([&] { decode_pose_stamped(xcdr2, "rec.mcap", "m"); }) == "m: encapsulation");
  // Nanoseconds out of range.
  auto ns = good;
  ns[8] = 0xFF, ns[9] = 0xFF, ns[10] = 0xFF, ns[11] = 0xFF;
  CHECK(field_of([&] { decode_pose_stamped(ns, "rec.mcap", "m"); }) == "m: stamp.nanosec");
}
