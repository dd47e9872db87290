#include "io/mcap.hpp"

#include "engine/core.hpp"

#include <lz4frame.h>
#include <zlib.h>
#include <zstd.h>

#include <array>
#include <cstring>
#include <fstream>
#include <limits>
#include <set>

namespace ts::io {

namespace {

constexpr std::array<std::uint8_t, 8> kMagic = {0x89, 'M', 'C', 'A', 'P', 0x30, '\r', '\n'};

enum Op : std::uint8_t {
  kHeader = 0x01, kFooter = 0x02, kSchema = 0x03, kChannel = 0x04, kMessage = 0x05, kChunk = 0x06,
  kMessageIndex = 0x07, kAttachment = 0x09, kMetadata = 0x0C, kDataEnd = 0x0F,
};

const char* op_name(std::uint8_t op) {
  switch (op) {
    case 0x01: return "Header";
    case 0x02: return "Footer";
    case 0x03: return "Schema";
    case 0x04: return "Channel";
    case 0x05: return "Message";
    case 0x06: return "Chunk";
    case 0x07: return "Message Index";
    case 0x08: return "Chunk Index";
    case 0x09: return "Attachment";
    case 0x0A: return "Attachment Index";
    case 0x0B: return "Statistics";
    case 0x0C: return "Metadata";
    case 0x0D: return "Metadata Index";
    case 0x0E: return "Summary Offset";
    case 0x0F: return "Data End";
    default: return op >= 0x80 ? "private" : "unknown";
  }
}

// A chunk may claim at most this much uncompressed: 2 GiB, and 64 MiB plus 4096 times its
// compressed bytes (zstd's run-length blocks reach about 32 768 : 1 only on constant data).
constexpr std::uint64_t kMaxChunk = std::uint64_t{1} << 31;
constexpr std::uint64_t kChunkSlack = std::uint64_t{64} << 20;
constexpr std::uint64_t kChunkRatio = 4096;

std::uint32_t crc_of(std::uint32_t crc, const std::uint8_t* p, std::size_t n) {
  while (n > 0) {   // zlib's crc32 takes a uInt length
    const auto step = static_cast<uInt>(std::min<std::size_t>(n, 1u << 30));
    crc = static_cast<std::uint32_t>(crc32(crc, p, step));
    p += step;
    n -= step;
  }
  return crc;
}

/// The reading position of one record: errors name it.
struct Where {
  const std::string& file;
  std::uint64_t index = 0;       ///< 1-based record number in the file (chunk contents counted)
  std::uint64_t offset = 0;      ///< byte of its opcode (in the file, or in the chunk's records)
  std::uint8_t op = 0;
  std::uint64_t chunk = 0;       ///< the chunk record's number when inside one (0: not)

  [[noreturn]] void fail(const std::string& message, const std::string& field) const {
    std::string where = "record " + std::to_string(index) + " (" + op_name(op) + ")";
    where += chunk ? " at byte " + std::to_string(offset) + " of chunk record " + std::to_string(chunk)
                   : " at byte " + std::to_string(offset);
    throw Error(message, file, field.empty() ? where : where + ": " + field);
  }
};

/// Little-endian fields of one record's content, each checked against what remains.
class Cursor {
 public:
  Cursor(std::span<const std::uint8_t> bytes, const Where& where) : b_(bytes), w_(where) {}

  std::uint8_t u8(const char* field) { return static_cast<std::uint8_t>(le(1, field)); }
  std::uint16_t u16(const char* field) { return static_cast<std::uint16_t>(le(2, field)); }
  std::uint32_t u32(const char* field) { return static_cast<std::uint32_t>(le(4, field)); }
  std::uint64_t u64(const char* field) { return le(8, field); }

  std::span<const std::uint8_t> bytes(std::uint64_t n, const char* field) {
    if (n > remaining())
      w_.fail("declares " + std::to_string(n) + " bytes but the record has " + std::to_string(remaining()) + " left",
              field);
    const auto out = b_.subspan(pos_, static_cast<std::size_t>(n));
    pos_ += static_cast<std::size_t>(n);
    return out;
  }
  std::string string(const char* field) {
    const auto s = bytes(u32(field), field);
    return std::string(s.begin(), s.end());
  }
  std::map<std::string, std::string> map(const char* field) {
    const std::uint32_t n = u32(field);
    Cursor inner(bytes(n, field), w_);
    std::map<std::string, std::string> m;
    while (inner.remaining() > 0) {
      std::string key = inner.string(field);
      m[std::move(key)] = inner.string(field);
    }
    return m;
  }
  std::span<const std::uint8_t> rest() { return bytes(remaining(), "data"); }
  std::size_t remaining() const { return b_.size() - pos_; }
  std::size_t position() const { return pos_; }

 private:
  std::uint64_t le(int n, const char* field) {
    if (remaining() < static_cast<std::size_t>(n))
      w_.fail("the record ends inside this field (" + std::to_string(remaining()) + " of " + std::to_string(n) +
                  " bytes)", field);
    std::uint64_t v = 0;
    for (int i = 0; i < n; ++i) v |= std::uint64_t{b_[pos_ + static_cast<std::size_t>(i)]} << (8 * i);
    pos_ += static_cast<std::size_t>(n);
    return v;
  }

  std::span<const std::uint8_t> b_;
  std::size_t pos_ = 0;
  const Where& w_;
};

std::vector<std::uint8_t> inflate(const std::string& compression, std::span<const std::uint8_t> in,
                                  std::uint64_t size, const Where& w) {
  std::vector<std::uint8_t> out(static_cast<std::size_t>(size));
  if (compression == "zstd") {
    const std::size_t n = ZSTD_decompress(out.data(), out.size(), in.data(), in.size());
    if (ZSTD_isError(n)) w.fail(std::string("zstd: ") + ZSTD_getErrorName(n), "records");
    if (n != size)
      w.fail("inflates to " + std::to_string(n) + " bytes, not the " + std::to_string(size) + " declared",
             "uncompressed_size");
    return out;
  }
  // "lz4": an LZ4 frame.
  LZ4F_dctx* ctx = nullptr;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&ctx, LZ4F_VERSION))) w.fail("lz4: no context", "records");
  std::size_t done_in = 0, done_out = 0;
  std::size_t hint = 1;
  while (hint != 0 && done_in < in.size()) {
    std::size_t src = in.size() - done_in, dst = out.size() - done_out;
    hint = LZ4F_decompress(ctx, out.data() + done_out, &dst, in.data() + done_in, &src, nullptr);
    if (LZ4F_isError(hint)) {
      const std::string e = LZ4F_getErrorName(hint);
      LZ4F_freeDecompressionContext(ctx);
      w.fail("lz4: " + e, "records");
    }
    done_in += src;
    done_out += dst;
    if (src == 0 && dst == 0) break;   // no progress: the output is full or the input ends
  }
  LZ4F_freeDecompressionContext(ctx);
  if (hint != 0) w.fail("the lz4 frame is incomplete or inflates to more than the declared size", "records");
  if (done_out != size)
    w.fail("inflates to " + std::to_string(done_out) + " bytes, not the " + std::to_string(size) + " declared",
           "uncompressed_size");
  return out;
}

class McapReader {
 public:
  McapReader(const std::filesystem::path& path, const McapHandlers& h) : file_(path.string()), h_(h) {}

  McapReadSummary run() {
    std::error_code ec;
    if (!std::filesystem::exists(file_, ec)) throw Error("file does not exist", file_);
    const auto size = std::filesystem::file_size(file_, ec);
    if (ec) throw Error("cannot read the file size: " + ec.message(), file_);
    in_.open(file_, std::ios::binary);
    if (!in_) throw Error("cannot open the file", file_);
    size_ = size;
    if (size_ < 2 * kMagic.size()) throw Error("too short for an MCAP file (" + std::to_string(size_) + " bytes)", file_, "magic");
    std::array<std::uint8_t, 8> magic{};
    read(magic.data(), magic.size());
    if (magic != kMagic) {
      const bool mcap = std::memcmp(magic.data() + 1, "MCAP", 4) == 0;
      throw Error(mcap ? "MCAP major version '" + std::string(1, static_cast<char>(magic[5])) + "' is not supported (0 is)"
                       : "not an MCAP file (no MCAP magic bytes at the start)",
                  file_, "magic");
    }
    // The trailing magic: a file cut short is told apart from a malformed one.
    in_.seekg(static_cast<std::streamoff>(size_ - kMagic.size()));
    std::array<std::uint8_t, 8> tail{};
    in_.read(reinterpret_cast<char*>(tail.data()), static_cast<std::streamsize>(tail.size()));
    if (!in_ || tail != kMagic)
      throw Error("no MCAP magic bytes at the end: the file is truncated (a recording cut short?)", file_, "magic");
    in_.seekg(static_cast<std::streamoff>(kMagic.size()));
    pos_ = kMagic.size();

    bool first = true;
    while (!s_.data_end) {
      if (pos_ + 9 > size_ - kMagic.size())
        throw Error("the file ends before its Data End record", file_, "record " + std::to_string(s_.records + 1));
      const std::uint64_t at = pos_;
      const std::uint32_t crc_before = crc_;
      std::array<std::uint8_t, 9> head{};
      read(head.data(), head.size());
      const std::uint8_t op = head[0];
      std::uint64_t len = 0;
      for (int i = 0; i < 8; ++i) len |= std::uint64_t{head[static_cast<std::size_t>(1 + i)]} << (8 * i);
      Where w{file_, ++s_.records, at, op, 0};
      if (first && op != kHeader) w.fail("the first record must be a Header", "");
      first = false;
      if (len > size_ - kMagic.size() - pos_)
        w.fail("declares " + std::to_string(len) + " bytes of content but the file has " +
                   std::to_string(size_ - kMagic.size() - pos_) + " before its end magic", "length");
      if (op == kDataEnd) {
        std::vector<std::uint8_t> content(static_cast<std::size_t>(len));
        read(content.data(), content.size());
        Cursor c(content, w);
        s_.data_section_crc = c.u32("data_section_crc");
        if (s_.data_section_crc != 0 && s_.data_section_crc != crc_before)
          w.fail("the data section's CRC32 is " + std::to_string(crc_before) + ", not the stored " +
                     std::to_string(s_.data_section_crc) + " (the file is damaged)", "data_section_crc");
        s_.data_end = true;
        break;
      }
      if (op == kFooter) w.fail("a Footer before the Data End record", "");
      std::vector<std::uint8_t> content(static_cast<std::size_t>(len));
      read(content.data(), content.size());
      record(op, content, w);
    }
    return s_;
  }

 private:
  void read(std::uint8_t* p, std::size_t n) {
    in_.read(reinterpret_cast<char*>(p), static_cast<std::streamsize>(n));
    if (!in_) throw Error("read failed at byte " + std::to_string(pos_), file_);
    crc_ = crc_of(crc_, p, n);
    pos_ += n;
  }

  void record(std::uint8_t op, std::span<const std::uint8_t> content, const Where& w) {
    Cursor c(content, w);
    switch (op) {
      case kHeader: {
        McapHeader hd;
        hd.profile = c.string("profile");
        hd.library = c.string("library");
        if (h_.header) h_.header(hd);
        break;
      }
      case kSchema: {
        McapSchema sc;
        sc.id = c.u16("id");
        sc.name = c.string("name");
        sc.encoding = c.string("encoding");
        const auto data = c.bytes(c.u32("data"), "data");
        sc.data.assign(data.begin(), data.end());
        if (sc.id == 0) break;   // invalid, to be ignored (the specification)
        schemas_.insert(sc.id);
        if (h_.schema) h_.schema(sc);
        break;
      }
      case kChannel: {
        McapChannel ch;
        ch.id = c.u16("id");
        ch.schema_id = c.u16("schema_id");
        ch.topic = c.string("topic");
        ch.message_encoding = c.string("message_encoding");
        ch.metadata = c.map("metadata");
        if (ch.schema_id != 0 && !schemas_.count(ch.schema_id))
          w.fail("schema " + std::to_string(ch.schema_id) + " is not defined before the channel", "schema_id");
        channels_.insert(ch.id);
        if (h_.channel) h_.channel(ch);
        break;
      }
      case kMessage: {
        McapMessage m;
        m.channel_id = c.u16("channel_id");
        m.sequence = c.u32("sequence");
        m.log_time = c.u64("log_time");
        m.publish_time = c.u64("publish_time");
        m.data = c.rest();
        if (!channels_.count(m.channel_id))
          w.fail("channel " + std::to_string(m.channel_id) + " is not defined before the message", "channel_id");
        ++s_.messages;
        if (h_.message) h_.message(m);
        break;
      }
      case kChunk: {
        if (w.chunk) w.fail("a Chunk inside a chunk", "");
        c.u64("message_start_time");
        c.u64("message_end_time");
        const std::uint64_t size = c.u64("uncompressed_size");
        const std::uint32_t crc = c.u32("uncompressed_crc");
        const std::string compression = c.string("compression");
        const auto records = c.bytes(c.u64("records"), "records");
        ++s_.chunks;
        if (compression.empty()) {
          if (size != records.size())
            w.fail("declares " + std::to_string(size) + " uncompressed bytes but holds " +
                       std::to_string(records.size()) + " uncompressed", "uncompressed_size");
          chunk(records, crc, w);
        } else if (compression == "lz4" || compression == "zstd") {
          if (size > kMaxChunk || size > kChunkSlack + kChunkRatio * records.size())
            w.fail("declares " + std::to_string(size) + " uncompressed bytes from " + std::to_string(records.size()) +
                       " compressed: more than this reader accepts (2 GiB, 64 MiB + 4096 : 1)", "uncompressed_size");
          const std::vector<std::uint8_t> plain = inflate(compression, records, size, w);
          chunk(plain, crc, w);
        } else {
          w.fail("compression '" + compression + "' is not supported (\"\", lz4, zstd)", "compression");
        }
        break;
      }
      case kAttachment: {
        McapAttachment a;
        a.log_time = c.u64("log_time");
        a.create_time = c.u64("create_time");
        a.name = c.string("name");
        a.media_type = c.string("media_type");
        a.data = c.bytes(c.u64("data"), "data");
        const std::size_t covered = c.position();
        const std::uint32_t crc = c.u32("crc");
        if (crc != 0 && crc != crc_of(0, content.data(), covered))
          w.fail("the attachment's CRC32 does not match its contents (the file is damaged)", "crc");
        if (h_.attachment) h_.attachment(a);
        break;
      }
      case kMetadata: {
        McapMetadata md;
        md.name = c.string("name");
        md.metadata = c.map("metadata");
        if (h_.metadata) h_.metadata(md);
        break;
      }
      case kFooter:
      case kDataEnd:
        w.fail("not allowed inside a chunk", "");
      default:
        break;   // Message Index, summary records out of place, unknown and private opcodes: skipped
    }
  }

  /// The records of one chunk, in order.
  void chunk(std::span<const std::uint8_t> records, std::uint32_t crc, const Where& outer) {
    if (crc != 0 && crc != crc_of(0, records.data(), records.size()))
      outer.fail("the chunk's records do not match its CRC32 (the file is damaged)", "uncompressed_crc");
    std::size_t pos = 0;
    while (pos < records.size()) {
      Where w{file_, ++s_.records, pos, records[pos], outer.index};
      if (records.size() - pos < 9) w.fail("the chunk ends inside a record's opcode and length", "length");
      std::uint64_t len = 0;
      for (int i = 0; i < 8; ++i) len |= std::uint64_t{records[pos + 1 + static_cast<std::size_t>(i)]} << (8 * i);
      if (len > records.size() - pos - 9)
        w.fail("declares " + std::to_string(len) + " bytes of content but the chunk has " +
                   std::to_string(records.size() - pos - 9) + " left", "length");
      record(records[pos], records.subspan(pos + 9, static_cast<std::size_t>(len)), w);
      pos += 9 + static_cast<std::size_t>(len);
    }
  }

  std::string file_;
  const McapHandlers& h_;
  std::ifstream in_;
  std::uint64_t size_ = 0, pos_ = 0;
  std::uint32_t crc_ = 0;
  McapReadSummary s_;
  std::set<std::uint16_t> schemas_, channels_;
};

}  // namespace

McapReadSummary read_mcap(const std::filesystem::path& path, const McapHandlers& handlers) {
  return McapReader(path, handlers).run();
}

namespace {

struct Out {
  std::vector<std::uint8_t> b;
  void le(std::uint64_t x, int n) {
    for (int i = 0; i < n; ++i) b.push_back(static_cast<std::uint8_t>(x >> (8 * i)));
  }
  void str(const std::string& s) {
    le(s.size(), 4);
    b.insert(b.end(), s.begin(), s.end());
  }
  void record(std::uint8_t op, const Out& content) {
    b.push_back(op);
    le(content.b.size(), 8);
    b.insert(b.end(), content.b.begin(), content.b.end());
  }
};

}  // namespace

void write_mcap(const std::filesystem::path& path, const McapHeader& header, const std::vector<McapSchema>& schemas,
                const std::vector<McapChannel>& channels, const std::vector<McapOutMessage>& messages) {
  Out f;
  f.b.assign(kMagic.begin(), kMagic.end());
  Out h;
  h.str(header.profile);
  h.str(header.library);
  f.record(kHeader, h);
  for (const McapSchema& s : schemas) {
    Out r;
    r.le(s.id, 2);
    r.str(s.name);
    r.str(s.encoding);
    r.le(s.data.size(), 4);
    r.b.insert(r.b.end(), s.data.begin(), s.data.end());
    f.record(kSchema, r);
  }
  for (const McapChannel& c : channels) {
    Out r, m;
    r.le(c.id, 2);
    r.le(c.schema_id, 2);
    r.str(c.topic);
    r.str(c.message_encoding);
    for (const auto& [k, v] : c.metadata) {
      m.str(k);
      m.str(v);
    }
    r.le(m.b.size(), 4);
    r.b.insert(r.b.end(), m.b.begin(), m.b.end());
    f.record(kChannel, r);
  }
  for (const McapOutMessage& m : messages) {
    Out r;
    r.le(m.channel_id, 2);
    r.le(m.sequence, 4);
    r.le(m.log_time, 8);
    r.le(m.publish_time, 8);
    r.b.insert(r.b.end(), m.data.begin(), m.data.end());
    f.record(kMessage, r);
  }
  Out end;
  end.le(crc_of(0, f.b.data(), f.b.size()), 4);
  f.record(kDataEnd, end);
  Out footer;
  footer.le(0, 8);
  footer.le(0, 8);
  footer.le(0, 4);
  f.record(kFooter, footer);
  f.b.insert(f.b.end(), kMagic.begin(), kMagic.end());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(f.b.data()), static_cast<std::streamsize>(f.b.size()));
  if (!out) throw Error("cannot write the MCAP file", path.string());
}

const std::vector<std::string>& mcap_compressions() {
  static const std::vector<std::string> names = {"", "lz4", "zstd"};
  return names;
}

}  // namespace ts::io
