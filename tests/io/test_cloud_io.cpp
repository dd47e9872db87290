#include "engine/core.hpp"
#include "io/cloud_io.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <cstring>
#include <limits>

namespace fs = std::filesystem;
using ts::io::CloudEncoding;
using ts::io::CloudPrecision;
using ts::io::CloudWriteSettings;
using ts::test::TempDir;

namespace {

ts::PointCloud sample_cloud(std::size_t n, bool normals, double offset = 0.0) {
  ts::Rng rng(7);
  ts::PointCloud c;
  for (std::size_t i = 0; i < n; ++i) {
    c.points.push_back(ts::Vec3(rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1)) +
                       ts::Vec3::Constant(offset));
    if (normals) c.normals.push_back(rng.unit_vector());
  }
  return c;
}

double max_diff(const std::vector<ts::Vec3>& a, const std::vector<ts::Vec3>& b) {
  REQUIRE(a.size() == b.size());
  double d = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) d = std::max(d, (a[i] - b[i]).cwiseAbs().maxCoeff());
  return d;
}

template <class T>
void put(std::string& s, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  s.append(b, sizeof(T));
}

}  // namespace

TEST_CASE("cloud io: PLY and PCD round trips, ascii and binary, with and without normals") {
  TempDir dir("cloud");
  for (const char* ext : {".ply", ".pcd"})
    for (auto enc : {CloudEncoding::ascii, CloudEncoding::binary})
      for (bool normals : {false, true}) {
        CAPTURE(ext);
        CAPTURE(static_cast<int>(enc));
        CAPTURE(normals);
        const auto cloud = sample_cloud(257, normals);
        const auto p = dir / (std::string("c") + ext);
        // float64: exact round trip.
        ts::io::write_cloud(p, cloud, {enc, CloudPrecision::float64});
        auto back = ts::io::read_cloud(p);
        CHECK(back.points == cloud.points);
        CHECK(back.normals == cloud.normals);
        // automatic (float32 near the origin): within float precision.
        ts::io::write_cloud(p, cloud, {enc, CloudPrecision::automatic});
        back = ts::io::read_cloud(p);
        CHECK(max_diff(back.points, cloud.points) < 1e-8);
        CHECK(back.has_normals() == normals);
        if (normals) CHECK(max_diff(back.normals, cloud.normals) < 1e-7);
      }
}

TEST_CASE("cloud io: far from the origin the automatic precision keeps float64") {
  TempDir dir("cloud");
  const auto cloud = sample_cloud(20, false, 1.0e5);  // a dive log 100 km away
  for (const char* name : {"far.ply", "far.pcd"}) {
    ts::io::write_cloud(dir / name, cloud);
    CHECK(ts::io::read_cloud(dir / name).points == cloud.points);
  }
  // Forcing float32 there loses millimetres: the reason for the rule.
  ts::io::write_cloud(dir / "f32.ply", cloud, {CloudEncoding::binary, CloudPrecision::float32});
  CHECK(max_diff(ts::io::read_cloud(dir / "f32.ply").points, cloud.points) > 1e-4);
}

TEST_CASE("cloud io: files written by the headers other tools use") {
  TempDir dir("cloud");
  // A mesh PLY with colours and faces (MeshLab / CloudCompare style), faces after vertices.
  ts::test::write_text(dir / "mesh.ply",
                       "ply\r\nformat ascii 1.0\r\ncomment made elsewhere\r\nelement vertex 3\r\n"
                       "property float x\r\nproperty float y\r\nproperty float z\r\n"
                       "property uchar red\r\nproperty uchar green\r\nproperty uchar blue\r\n"
                       "element face 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n"
                       "0 0 0 255 0 0\r\n1 0 0 0 255 0\r\n0 +1 0.5e0 0 0 255\r\n3 0 1 2\r\n");
  auto m = ts::io::read_cloud(dir / "mesh.ply");
  REQUIRE(m.size() == 3);
  CHECK(m.points[2] == ts::Vec3(0, 1, 0.5));
  CHECK_FALSE(m.has_normals());

  // Binary big endian, a face element *before* the vertices, double coordinates.
  std::string be = "ply\nformat binary_big_endian 1.0\nelement face 1\nproperty list uchar int vertex_indices\n"
                   "element vertex 2\nproperty double x\nproperty double y\nproperty double z\n"
                   "property float nx\nproperty float ny\nproperty float nz\nend_header\n";
  auto put_be = [&](auto v) {
    char b[sizeof(v)];
    std::memcpy(b, &v, sizeof(v));
    std::reverse(b, b + sizeof(v));
    be.append(b, sizeof(v));
  };
  be += '\3';
  for (std::int32_t i : {0, 1, 1}) put_be(i);
  for (int k = 0; k < 2; ++k) {
    for (double c : {1.5 + k, -2.0, 3.25}) put_be(c);
    for (float c : {0.0f, 0.0f, 1.0f}) put_be(c);
  }
  ts::test::write_text(dir / "be.ply", be);
  auto b = ts::io::read_cloud(dir / "be.ply");
  REQUIRE(b.size() == 2);
  CHECK(b.points[1] == ts::Vec3(2.5, -2.0, 3.25));
  CHECK(b.normals[0] == ts::Vec3(0, 0, 1));

  // PCL's PointNormal layout: x y z _ normal_x normal_y normal_z _ curvature, with padding.
  std::string pcd = "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
                    "FIELDS x y z _ normal_x normal_y normal_z _ curvature\n"
                    "SIZE 4 4 4 1 4 4 4 1 4\nTYPE F F F U F F F U F\nCOUNT 1 1 1 4 1 1 1 4 1\n"
                    "WIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA binary\n";
  for (int k = 0; k < 2; ++k) {
    for (float c : {0.5f * static_cast<float>(k), 1.0f, 2.0f}) put(pcd, c);
    pcd.append(4, '\0');
    for (float c : {1.0f, 0.0f, 0.0f}) put(pcd, c);
    pcd.append(4, '\0');
    put(pcd, 0.25f);
  }
  ts::test::write_text(dir / "pcl.pcd", pcd);
  auto c = ts::io::read_cloud(dir / "pcl.pcd");
  REQUIRE(c.size() == 2);
  CHECK(c.points[1] == ts::Vec3(0.5, 1, 2));
  CHECK(c.normals[1] == ts::Vec3(1, 0, 0));
}

TEST_CASE("cloud io: PCL binary_compressed (LZF) data") {
  TempDir dir("cloud");
  // Four points, x = 1 for all, y = 0..3, z = 2. Fields are stored one after another.
  std::string soa;
  std::string xs;
  for (int i = 0; i < 4; ++i) put(xs, 1.0f);
  std::string rest;
  for (int i = 0; i < 4; ++i) put(rest, static_cast<float>(i));
  for (int i = 0; i < 4; ++i) put(rest, 2.0f);
  // LZF: x as a 4-byte literal then a back reference of 12 bytes at distance 4; the rest as
  // one 32-byte literal run.
  std::string lzf;
  lzf += '\x03';
  lzf += xs.substr(0, 4);
  lzf += static_cast<char>(7 << 5);  // length 7 + extra byte, distance high bits 0
  lzf += static_cast<char>(12 - 2 - 7);
  lzf += static_cast<char>(4 - 1);
  lzf += static_cast<char>(31);
  lzf += rest;
  std::string pcd = "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 4\nHEIGHT 1\n"
                    "POINTS 4\nDATA binary_compressed\n";
  put(pcd, static_cast<std::uint32_t>(lzf.size()));
  put(pcd, static_cast<std::uint32_t>(48));
  pcd += lzf;
  ts::test::write_text(dir / "z.pcd", pcd);
  const auto c = ts::io::read_cloud(dir / "z.pcd");
  REQUIRE(c.size() == 4);
  for (int i = 0; i < 4; ++i) CHECK(c.points[static_cast<std::size_t>(i)] == ts::Vec3(1, i, 2));

  // A corrupt stream (back reference before the start) is refused.
  std::string bad = "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA binary_compressed\n";
  put(bad, std::uint32_t{3});
  put(bad, std::uint32_t{12});
  bad += std::string("\x40\x05\x00", 3);
  ts::test::write_text(dir / "bad.pcd", bad);
  CHECK_THROWS_WITH_AS(ts::io::read_cloud(dir / "bad.pcd"), doctest::Contains("corrupt"), ts::Error);
}

namespace {
/// Writes `text` to dir/name; reading it must throw one error with `message` and the path.
void expect_refused(const fs::path& dir, const char* name, const std::string& text, const char* message) {
  const std::string label = name;
  CAPTURE(label);
  const auto p = dir / name;
  ts::test::write_text(p, text);
  CHECK_THROWS_WITH_AS(ts::io::read_cloud(p), doctest::Contains(message), ts::Error);
  CHECK_THROWS_WITH_AS(ts::io::read_cloud(p), doctest::Contains(p.string().c_str()), ts::Error);
}
}  // namespace

TEST_CASE("cloud io: malformed headers and data name the file and the line") {
  TempDir dir("cloud");
  auto expect = [&](const char* name, const std::string& text, const char* message) {
    expect_refused(dir.path(), name, text, message);
  };
  expect("a.ply", "plx\n", "not a PLY file");
  expect("b.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n", "no end_header");
  expect("c.ply", "ply\nformat binary_middle_endian 1.0\nend_header\n", "line 2");
  expect("d.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
         "no x, y and z fields");
  expect("e.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
                  "end_header\n1 2 3\n1 2\n",
         "too few values on the line (2) (" );
  expect("e2.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
                   "end_header\n1 2 3\n1 2\n",
         "line 9");
  expect("f.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                  "end_header\n1 nan 3\n",
         "non-finite coordinate");
  expect("g.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                  "end_header\n1 zwei 3\n",
         "cannot read 'zwei' as a number");
  expect("h.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
                  "property float z\nend_header\n0123456789",
         "truncated");
  expect("i.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                  "property float nx\nend_header\n1 2 3 4\n",
         "only some of the nx ny nz");
  expect("a.pcd", "VERSION 0.7\nFIELDS x y z\nSIZE 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n",
         "different lengths");
  expect("b.pcd", "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA lzma\n", "line 7");
  expect("c.pcd", "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nPOINTS 2\nDATA ascii\n1 2 3\n",
         "ends after 1 of 2 points");
  expect("d.pcd", "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 inf\n",
         "non-finite coordinate (NaN or infinity) (");
  expect("e.pcd", "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 3\nPOINTS 3\nDATA binary\n12345678",
         "truncated");
  expect("f.pcd", "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 2\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3\n",
         "unsupported field type F2");
  expect("g.pcd", "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\n", "no DATA line");
  expect("h.pcd", "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 2\nHEIGHT 2\nPOINTS 3\nDATA ascii\n",
         "differs from WIDTH*HEIGHT");
  expect("i.pcd", "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 1\nPOINTS 1\nDATA ascii\n1 2 3 4\n",
         "line 8");
  expect("x.xyz", "1 2 3\n", "unknown point-cloud format");
  CHECK_THROWS_WITH_AS(ts::io::read_cloud(dir / "missing.ply"), doctest::Contains("does not exist"), ts::Error);
}

TEST_CASE("cloud io: crafted counts are refused before anything is computed from them") {
  TempDir dir("cloud");
  auto expect = [&](const char* name, const std::string& text, const char* message) {
    expect_refused(dir.path(), name, text, message);
  };
  // The review's 100-byte file: POINTS * record wrapped around to 4 bytes, which the compressed
  // header then matched; reading the points ran off the buffer (a segmentation fault).
  std::string lzf = std::string("\x05\x00\x00\x00\x04\x00\x00\x00", 8) + std::string("\x03\x01\x02\x03\x04\x00", 6);
  expect("wrap.pcd",
         "VERSION 0.7\nFIELDS x y z\nSIZE 1 1 2\nTYPE U U U\nCOUNT 1 1 1\nPOINTS 4611686018427387905\n"
         "DATA binary_compressed\n" + lzf,
         "is beyond any real cloud");
  expect("count.pcd",
         "VERSION 0.7\nFIELDS x y z w\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 18446744073709551615\nPOINTS 1\n"
         "DATA binary\n0123456789abcdef",
         "has COUNT 18446744073709551615 (at most 2^20)");
  expect("wh.pcd",
         "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 9223372036854775808\nHEIGHT 4\nDATA binary\n",
         "WIDTH*HEIGHT overflows");
  expect("record.pcd",
         "VERSION 0.7\nFIELDS x y z w\nSIZE 4 4 4 8\nTYPE F F F F\nCOUNT 1 1 1 1048576\nPOINTS 1099511627776\n"
         "DATA binary\n0123",
         "truncated");
  expect("float_count.ply",
         "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
         "property float z\nelement face 1\nproperty list float int vertex_indices\nend_header\n",
         "a list's count type must be an integer type, not 'float'");
  expect("long_list.ply",
         "ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar int idx\nproperty float x\n"
         "property float y\nproperty float z\nend_header\n200 1 2 3\n",
         "the list holds 200 values, the line only 3 more");
  expect("huge_list.ply",
         "ply\nformat ascii 1.0\nelement vertex 1\nproperty list uint int idx\nproperty float x\n"
         "property float y\nproperty float z\nend_header\n18446744073709551615 1 2 3\n",
         "the list holds 18446744073709551615 values");
}

TEST_CASE("cloud io: writing rejects non-finite values and unknown extensions, leaving no file") {
  TempDir dir("cloud");
  auto cloud = sample_cloud(5, true);
  cloud.points[3].y() = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH_AS(ts::io::write_cloud(dir / "n.ply", cloud), doctest::Contains("point 3"), ts::Error);
  CHECK_FALSE(fs::exists(dir / "n.ply"));
  cloud = sample_cloud(5, true);
  cloud.normals[1].x() = std::numeric_limits<double>::infinity();
  CHECK_THROWS_WITH_AS(ts::io::write_cloud(dir / "n.pcd", cloud), doctest::Contains("non-finite normal"), ts::Error);
  CHECK_THROWS_WITH_AS(ts::io::write_cloud(dir / "n.xyz", sample_cloud(2, false)),
                       doctest::Contains("use .ply or .pcd"), ts::Error);
  CHECK(fs::is_empty(dir.path()));
}
