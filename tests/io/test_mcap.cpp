// io/mcap.hpp: a file written by another writer (Python, tests/fuzz/corpus/mcap), the writer's
// round trip, compressed chunks, and malformed files.
#include "engine/core.hpp"
#include "io/mcap.hpp"
#include "temp_dir.hpp"

#include <doctest/doctest.h>
#include <lz4frame.h>
#include <nlohmann/json.hpp>
#include <zlib.h>
#include <zstd.h>

#include <algorithm>
#include <fstream>
#include <set>
#include <sstream>

namespace fs = std::filesystem;
using ts::test::TempDir;
using json = nlohmann::json;

namespace {

const fs::path kPlain = fs::path(TS_SOURCE_DIR) / "tests/fuzz/corpus/mcap/plain-attachment-metadata.mcap";

json bytes_json(std::span<const std::uint8_t> b) {
  json a = json::array();
  for (std::uint8_t x : b) a.push_back(std::to_string(x));
  return a;
}

json map_json(const std::map<std::string, std::string>& m) {
  json o = json::object();
  for (const auto& [k, v] : m) o[k] = v;
  return o;
}

/// A record as the conformance files write it: {"type", "fields": [[name, value], ...]} with the
/// fields sorted by name and numbers as decimal strings.
json record(const std::string& type, std::vector<std::pair<std::string, json>> fields) {
  std::sort(fields.begin(), fields.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  json f = json::array();
  for (auto& [k, v] : fields) f.push_back(json::array({k, v}));
  return {{"type", type}, {"fields", f}};
}

/// The data-section records the reader streams, in the conformance files' form.
json streamed(const fs::path& file) {
  json out = json::array();
  ts::io::McapHandlers h;
  h.header = [&](const ts::io::McapHeader& x) {
    out.push_back(record("Header", {{"library", x.library}, {"profile", x.profile}}));
  };
  h.schema = [&](const ts::io::McapSchema& x) {
    out.push_back(record("Schema", {{"data", bytes_json(x.data)}, {"encoding", x.encoding},
                                    {"id", std::to_string(x.id)}, {"name", x.name}}));
  };
  h.channel = [&](const ts::io::McapChannel& x) {
    out.push_back(record("Channel", {{"id", std::to_string(x.id)}, {"message_encoding", x.message_encoding},
                                     {"metadata", map_json(x.metadata)}, {"schema_id", std::to_string(x.schema_id)},
                                     {"topic", x.topic}}));
  };
  h.message = [&](const ts::io::McapMessage& x) {
    out.push_back(record("Message", {{"channel_id", std::to_string(x.channel_id)}, {"data", bytes_json(x.data)},
                                     {"log_time", std::to_string(x.log_time)},
                                     {"publish_time", std::to_string(x.publish_time)},
                                     {"sequence", std::to_string(x.sequence)}}));
  };
  h.attachment = [&](const ts::io::McapAttachment& x) {
    out.push_back(record("Attachment", {{"create_time", std::to_string(x.create_time)}, {"data", bytes_json(x.data)},
                                        {"log_time", std::to_string(x.log_time)}, {"media_type", x.media_type},
                                        {"name", x.name}}));
  };
  h.metadata = [&](const ts::io::McapMetadata& x) {
    out.push_back(record("Metadata", {{"metadata", map_json(x.metadata)}, {"name", x.name}}));
  };
  const auto s = ts::io::read_mcap(file, h);
  if (s.data_end) out.push_back(record("DataEnd", {{"data_section_crc", std::to_string(s.data_section_crc)}}));
  return out;
}

// ---- a small MCAP writer for the tests ------------------------------------------------------

struct Bytes {
  std::vector<std::uint8_t> b;
  Bytes& u8(std::uint8_t x) { b.push_back(x); return *this; }
  Bytes& le(std::uint64_t x, int n) {
    for (int i = 0; i < n; ++i) b.push_back(static_cast<std::uint8_t>(x >> (8 * i)));
    return *this;
  }
  Bytes& str(const std::string& s) {
    le(s.size(), 4);
    b.insert(b.end(), s.begin(), s.end());
    return *this;
  }
  Bytes& raw(const std::vector<std::uint8_t>& x) {
    b.insert(b.end(), x.begin(), x.end());
    return *this;
  }
  Bytes& rec(std::uint8_t op, const Bytes& content) {
    u8(op).le(content.b.size(), 8);
    return raw(content.b);
  }
};

std::uint32_t crc(const std::vector<std::uint8_t>& b) {
  return static_cast<std::uint32_t>(crc32(0, b.data(), static_cast<uInt>(b.size())));
}

const std::vector<std::uint8_t> kMagic = {0x89, 'M', 'C', 'A', 'P', 0x30, '\r', '\n'};

/// Schema 1, channel 1 ("/touch"), messages with payloads {i, i+1, i+2} for i < n.
Bytes chunk_records(int n, std::uint16_t channel = 1) {
  Bytes r;
  r.rec(0x03, Bytes().le(1, 2).str("std_msgs/msg/UInt8MultiArray").str("ros2msg").le(3, 4).raw({'u', '8', '!'}));
  r.rec(0x04, Bytes().le(1, 2).le(1, 2).str("/touch").str("cdr").le(0, 4));
  for (int i = 0; i < n; ++i)
    r.rec(0x05, Bytes().le(channel, 2).le(static_cast<std::uint64_t>(i), 4).le(100 + i, 8).le(90 + i, 8)
                    .raw({static_cast<std::uint8_t>(i), static_cast<std::uint8_t>(i + 1), static_cast<std::uint8_t>(i + 2)}));
  return r;
}

std::vector<std::uint8_t> compress(const std::string& how, const std::vector<std::uint8_t>& plain) {
  std::vector<std::uint8_t> out;
  if (how == "zstd") {
    out.resize(ZSTD_compressBound(plain.size()));
    out.resize(ZSTD_compress(out.data(), out.size(), plain.data(), plain.size(), 3));
  } else if (how == "lz4") {
    out.resize(LZ4F_compressFrameBound(plain.size(), nullptr));
    out.resize(LZ4F_compressFrame(out.data(), out.size(), plain.data(), plain.size(), nullptr));
  } else {
    out = plain;
  }
  return out;
}

/// A whole file: header, one chunk of `records` compressed with `how`, Data End with its CRC,
/// an empty footer. `declared` overrides the chunk's uncompressed size; `with_crc` its CRC.
std::vector<std::uint8_t> file_with_chunk(const Bytes& records, const std::string& how, std::uint64_t declared = 0,
                                          bool with_crc = true) {
  const std::vector<std::uint8_t> packed = compress(how, records.b);
  Bytes f;
  f.raw(kMagic);
  f.rec(0x01, Bytes().str("ros2").str("touchstone test"));
  f.rec(0x06, Bytes().le(100, 8).le(102, 8).le(declared ? declared : records.b.size(), 8)
                  .le(with_crc ? crc(records.b) : 0, 4).str(how).le(packed.size(), 8).raw(packed));
  const std::uint32_t data_crc = crc(f.b);
  f.rec(0x0F, Bytes().le(data_crc, 4));
  f.rec(0x02, Bytes().le(0, 8).le(0, 8).le(0, 4));
  f.raw(kMagic);
  return f.b;
}

fs::path write(const TempDir& dir, const std::string& name, const std::vector<std::uint8_t>& b) {
  const fs::path p = dir / name;
  std::ofstream(p, std::ios::binary).write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
  return p;
}

std::string error_of(const fs::path& p) {
  try {
    ts::io::read_mcap(p, {});
  } catch (const ts::Error& e) {
    CHECK(e.file() == p.string());
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("MCAP: a file of another writer streams record for record") {
  // Written by a few lines of Python (struct and zlib) outside this code: schema, channel with
  // metadata, four messages, an attachment with its CRC, metadata, a message index and a
  // private record (both skipped), Data End with the data section's CRC.
  const json got = streamed(kPlain);
  json want = json::array();
  want.push_back(record("Header", {{"library", "touchstone"}, {"profile", "ros2"}}));
  want.push_back(record("Schema", {{"data", json::array()}, {"encoding", "ros2msg"}, {"id", "1"},
                                   {"name", "geometry_msgs/msg/PoseStamped"}}));
  want.push_back(record("Channel", {{"id", "1"}, {"message_encoding", "cdr"}, {"metadata", {{"k", "v"}}},
                                    {"schema_id", "1"}, {"topic", "/arm/eef_pose"}}));
  for (int i = 0; i < 4; ++i) {
    json data = json::array();
    for (int b = i; b < i + 8; ++b) data.push_back(std::to_string(b));
    want.push_back(record("Message", {{"channel_id", "1"}, {"data", data}, {"log_time", std::to_string(10 + i)},
                                      {"publish_time", std::to_string(10 + i)}, {"sequence", std::to_string(i)}}));
  }
  want.push_back(record("Attachment", {{"create_time", "6"}, {"data", json::array({"97", "98", "99"})}, {"log_time", "5"},
                                       {"media_type", "text/plain"}, {"name", "notes.txt"}}));
  want.push_back(record("Metadata", {{"metadata", {{"site", "north"}}}, {"name", "dive"}}));
  REQUIRE(got.size() == want.size() + 1);
  CHECK(got.back()["type"] == "DataEnd");
  CHECK(got.back()["fields"][0][1] != "0");   // a CRC was given, and it matched
  for (std::size_t i = 0; i < want.size(); ++i) CHECK(got[i] == want[i]);
}

TEST_CASE("MCAP: what write_mcap writes reads back") {
  TempDir dir("mcapw");
  std::vector<ts::io::McapOutMessage> out;
  for (std::uint32_t i = 0; i < 20; ++i)
    out.push_back({static_cast<std::uint16_t>(1 + i % 2), i, 1000u + i, 999u + i, std::vector<std::uint8_t>(i, static_cast<std::uint8_t>(i))});
  ts::io::write_mcap(dir / "w.mcap", {"ros2", "t"}, {{1, "a/msg/A", "ros2msg", {1, 2}}},
                     {{1, 1, "/a", "cdr", {{"x", "y"}}}, {2, 0, "/b", "json", {}}}, out);
  std::vector<ts::io::McapMessage> seen;
  std::vector<std::vector<std::uint8_t>> payloads;
  std::map<std::string, std::string> meta;
  const auto s = ts::io::read_mcap(dir / "w.mcap", {.channel = [&](const ts::io::McapChannel& c) { if (c.id == 1) meta = c.metadata; },
                                                    .message = [&](const ts::io::McapMessage& m) {
                                                      seen.push_back(m);
                                                      payloads.emplace_back(m.data.begin(), m.data.end());
                                                    }});
  CHECK(s.data_end);
  CHECK(s.data_section_crc != 0);
  CHECK(meta == std::map<std::string, std::string>{{"x", "y"}});
  REQUIRE(seen.size() == 20);
  for (std::uint32_t i = 0; i < 20; ++i) {
    CHECK(seen[i].channel_id == 1 + i % 2);
    CHECK(seen[i].log_time == 1000u + i);
    CHECK(seen[i].publish_time == 999u + i);
    CHECK(payloads[i] == std::vector<std::uint8_t>(i, static_cast<std::uint8_t>(i)));
  }
}

TEST_CASE("MCAP: chunks stored plain, as lz4 frames and as zstd give the same messages") {
  TempDir dir("mcap");
  for (const std::string how : {"", "lz4", "zstd"}) {
    INFO("compression '" << how << "'");
    const Bytes records = chunk_records(50);
    const fs::path p = write(dir, "c" + how + ".mcap", file_with_chunk(records, how));
    std::vector<std::vector<std::uint8_t>> payloads;
    std::string topic;
    const auto s = ts::io::read_mcap(p, {.channel = [&](const ts::io::McapChannel& c) { topic = c.topic; },
                                         .message = [&](const ts::io::McapMessage& m) {
                                           CHECK(m.log_time == 100 + m.sequence);
                                           CHECK(m.publish_time == 90 + m.sequence);
                                           payloads.emplace_back(m.data.begin(), m.data.end());
                                         }});
    CHECK(s.chunks == 1);
    CHECK(s.messages == 50);
    CHECK(s.data_end);
    CHECK(topic == "/touch");
    REQUIRE(payloads.size() == 50);
    CHECK(payloads[17] == std::vector<std::uint8_t>{17, 18, 19});
  }
  CHECK(ts::io::mcap_compressions() == std::vector<std::string>{"", "lz4", "zstd"});
}

TEST_CASE("MCAP: malformed files give one error naming the file and the record") {
  TempDir dir("mcapbad");
  const Bytes records = chunk_records(5);
  const auto good = file_with_chunk(records, "zstd");

  CHECK(error_of(dir / "missing.mcap").find("does not exist") != std::string::npos);
  CHECK(error_of(write(dir, "text.mcap", std::vector<std::uint8_t>(64, 'x'))).find("not an MCAP file") != std::string::npos);
  auto v1 = good;
  v1[5] = '1';
  CHECK(error_of(write(dir, "v1.mcap", v1)).find("major version '1'") != std::string::npos);
  // Cut short (a recording killed): no end magic.
  CHECK(error_of(write(dir, "cut.mcap", std::vector<std::uint8_t>(good.begin(), good.begin() + 60)))
            .find("truncated") != std::string::npos);
  // A record that claims more bytes than the file has.
  auto big = good;
  for (int i = 0; i < 8; ++i) big[9 + i] = 0xFF;   // the Header's length
  CHECK(error_of(write(dir, "len.mcap", big)).find("record 1 (Header) at byte 8: length") != std::string::npos);
  // A chunk claiming 1 TB uncompressed from a few bytes: refused before anything is allocated.
  const std::string huge = error_of(write(dir, "huge.mcap", file_with_chunk(records, "zstd", std::uint64_t{1} << 40)));
  CHECK(huge.find("uncompressed_size") != std::string::npos);
  CHECK(huge.find("Chunk") != std::string::npos);
  // A lz4 chunk whose declared size is smaller than what it inflates to.
  CHECK(error_of(write(dir, "small.mcap", file_with_chunk(records, "lz4", 20))).find("lz4") != std::string::npos);
  // A flipped byte inside an uncompressed chunk: its CRC32 (and the data section's) disagree.
  auto flipped = file_with_chunk(records, "");
  flipped[flipped.size() - 60] ^= 0x01;
  CHECK(error_of(write(dir, "flip.mcap", flipped)).find("uncompressed_crc") != std::string::npos);
  // Without the chunk CRC the data section's CRC still catches it.
  auto flipped2 = file_with_chunk(records, "", 0, false);
  flipped2[flipped2.size() - 60] ^= 0x01;
  CHECK(error_of(write(dir, "flip2.mcap", flipped2)).find("data_section_crc") != std::string::npos);
  CHECK(error_of(write(dir, "brotli.mcap", file_with_chunk(records, "brotli"))).find("compression 'brotli'") !=
        std::string::npos);
  // A message on a channel never defined.
  const std::string orphan = error_of(write(dir, "orphan.mcap", file_with_chunk(chunk_records(3, 7), "")));
  CHECK(orphan.find("channel 7 is not defined") != std::string::npos);
  CHECK(orphan.find("of chunk record 2") != std::string::npos);
  // The good file reads.
  CHECK(ts::io::read_mcap(write(dir, "good.mcap", good), {}).messages == 5);
}

TEST_CASE("MCAP: the specification's conformance files stream their expected records") {
  // tests/io/mcap_conformance: the 416 conformance files of the MCAP specification's repository
  // (foxglove/mcap, tests/conformance/data), rebuilt by scripts/mcap_conformance.py and proved
  // byte for byte the official ones (SHA-256 of their Git LFS pointers; the ctest
  // io/mcap_conformance_sha256 checks them again). Every feature they use is one the reader claims:
  // chunks (uncompressed), message indexes, padded records, attachments, metadata, and a summary
  // section (statistics, repeated schemas and channels, indexes, summary offsets) that a streamed
  // reader passes over. Each file must stream exactly the data-section records the specification
  // expects, Data End's CRC included.
  const fs::path root = fs::path(TS_SOURCE_DIR) / "tests/io/mcap_conformance";
  std::size_t files = 0, records = 0;
  std::set<std::string> features;
  for (const auto& dir : fs::directory_iterator(root)) {
    if (!dir.is_directory()) continue;
    std::ifstream in(dir.path() / "expected.json");
    REQUIRE(in);
    const json expected = json::parse(in);
    std::size_t here = 0;
    for (const auto& f : fs::directory_iterator(dir.path())) {
      if (f.path().extension() != ".mcap") continue;
      const std::string name = f.path().stem().string();
      INFO(name);
      REQUIRE(expected.contains(name));
      const json got = streamed(f.path());
      CHECK(got == expected[name]);
      records += got.size();
      ++here;
      std::stringstream parts(name);
      std::string part;
      std::getline(parts, part, '-');   // the base name
      while (std::getline(parts, part, '-')) features.insert(part);
    }
    CHECK(here == expected.size());   // no expected record list without its file
    files += here;
  }
  CHECK(files == 416);
  CHECK(records > 2000);
  // The ten features of the specification's generator all occur.
  CHECK(features == std::set<std::string>{"ax", "ch", "chx", "mdx", "mx", "pad", "rch", "rsh", "st", "sum"});
}

TEST_CASE("MCAP: a conformance file changed by one byte is refused") {
  // The same files must not pass whatever they hold: flip one byte of a message's payload in a
  // chunked file (the chunk's CRC catches it) and of an unchunked one (the data section's CRC).
  TempDir dir("mcapconf");
  const fs::path root = fs::path(TS_SOURCE_DIR) / "tests/io/mcap_conformance/OneMessage";
  for (const std::string name : {"OneMessage-ch-mx", "OneMessage"}) {
    INFO(name);
    std::ifstream in(root / (name + ".mcap"), std::ios::binary);
    std::vector<char> bytes((std::istreambuf_iterator<char>(in)), {});
    // The message's log time 2, publish time 1 and payload {1, 2, 3}, little-endian.
    std::string tail(8 + 8 + 3, '\0');
    tail[0] = '\x02';
    tail[8] = '\x01';
    tail[16] = '\x01', tail[17] = '\x02', tail[18] = '\x03';
    const auto at = std::search(bytes.begin(), bytes.end(), tail.begin(), tail.end());
    REQUIRE(at != bytes.end());
    *(at + 16) = '\x07';
    const fs::path bad = dir.path() / (name + ".mcap");
    std::ofstream(bad, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    CHECK_THROWS_WITH_AS(streamed(bad), doctest::Contains(bad.string().c_str()), ts::Error);
    CHECK_THROWS_WITH_AS(streamed(bad), doctest::Contains("CRC"), ts::Error);
  }
}
