#include "datasets/archive.hpp"

#include "engine/core.hpp"

#include <zlib.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <cstdint>
#include <functional>
#include <optional>

namespace ts::datasets {

namespace {

constexpr std::size_t kBlock = 512;

/// gzip-or-plain reader (gzread passes uncompressed files through unchanged).
class Reader {
 public:
  explicit Reader(const std::filesystem::path& path) : name_(path.string()) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) throw Error("archive does not exist", name_);
    file_ = gzopen(path.c_str(), "rb");
    if (!file_) throw Error("cannot open the archive", name_);
    gzbuffer(file_, 1 << 17);
    if (gzdirect(file_)) {   // not compressed (gzdirect looks at the first bytes, read here)
      const auto size = std::filesystem::file_size(path, ec);
      if (!ec) plain_size_ = size;
    }
  }
  ~Reader() {
    if (file_) gzclose(file_);
  }
  Reader(const Reader&) = delete;
  Reader& operator=(const Reader&) = delete;

  /// Read up to n bytes; returns how many were read (short only at the end of the data).
  std::size_t read(void* buffer, std::size_t n) {
    std::size_t total = 0;
    auto* out = static_cast<unsigned char*>(buffer);
    while (total < n) {
      const auto want = static_cast<unsigned>(std::min<std::size_t>(n - total, 1u << 30));
      const int got = gzread(file_, out + total, want);
      if (got < 0) {
        int code = 0;
        const char* msg = gzerror(file_, &code);
        throw Error(std::string("corrupt archive: ") + (msg ? msg : "read error"), name_);
      }
      if (got == 0) {
        // zlib reports a cut-off gzip stream as an error after the last bytes.
        int code = 0;
        const char* msg = gzerror(file_, &code);
        if (code != Z_OK && code != Z_STREAM_END)
          throw Error(std::string("corrupt or truncated archive: ") + (msg ? msg : "read error"), name_);
        break;
      }
      total += static_cast<std::size_t>(got);
    }
    offset_ += total;
    return total;
  }
  /// Bytes left after the offset: known for a plain tar (gzread passes it through unchanged),
  /// not for a compressed one (the largest value).
  std::uint64_t left() const { return plain_size_ ? *plain_size_ - std::min(offset_, *plain_size_) : UINT64_MAX; }
  void skip(std::uint64_t n, const std::string& member) {
    std::array<unsigned char, 1 << 16> scratch;
    while (n > 0) {
      const auto chunk = static_cast<std::size_t>(std::min<std::uint64_t>(n, scratch.size()));
      if (read(scratch.data(), chunk) != chunk) truncated(member);
      n -= chunk;
    }
  }
  [[noreturn]] void truncated(const std::string& member) const {
    throw Error("archive is truncated (inside member '" + member + "')", name_);
  }
  const std::string& name() const { return name_; }
  std::uint64_t offset() const { return offset_; }

 private:
  std::string name_;
  gzFile file_ = nullptr;
  std::uint64_t offset_ = 0;
  std::optional<std::uint64_t> plain_size_;
};

/// A member's body of `size` bytes, read as it arrives: nothing is sized by the header's count
/// before the archive has held that much (a compressed archive's size after decompression is not
/// known before it is read).
std::string read_body(Reader& in, std::uint64_t size, const std::string& member) {
  std::string data;
  while (data.size() < size) {
    const std::size_t have = data.size(), chunk = static_cast<std::size_t>(std::min<std::uint64_t>(size - have, 1u << 20));
    data.resize(have + chunk);
    const std::size_t got = in.read(data.data() + have, chunk);
    if (got != chunk)
      throw Error("archive is truncated: member '" + member + "' declares " + std::to_string(size) +
                      " bytes, and the archive ends after " + std::to_string(have + got) + " of them",
                  in.name(), "member '" + member + "'");
  }
  return data;
}

std::string field_string(const unsigned char* b, std::size_t n) {
  const auto* end = static_cast<const unsigned char*>(std::memchr(b, 0, n));
  return std::string(reinterpret_cast<const char*>(b), end ? static_cast<std::size_t>(end - b) : n);
}

bool parse_number(const unsigned char* b, std::size_t n, std::uint64_t& out) {
  out = 0;
  if (b[0] & 0x80) {  // GNU base-256
    for (std::size_t i = 1; i < n; ++i) {
      if (out >> 55) return false;
      out = (out << 8) | b[i];
    }
    return (b[0] & 0x7f) == 0;
  }
  std::size_t i = 0;
  while (i < n && b[i] == ' ') ++i;
  bool any = false;
  for (; i < n && b[i] >= '0' && b[i] <= '7'; ++i) {
    out = out * 8 + static_cast<std::uint64_t>(b[i] - '0');
    any = true;
  }
  for (; i < n; ++i)
    if (b[i] != ' ' && b[i] != 0) return false;
  return any;
}

std::string normalize(std::string name) {
  while (name.rfind("./", 0) == 0) name.erase(0, 2);
  return name;
}

/// pax extended header: records "LEN key=value\n"; returns the path= value, if any.
std::string pax_path(const std::string& data) {
  std::string path;
  std::size_t pos = 0;
  while (pos < data.size()) {
    const auto space = data.find(' ', pos);
    if (space == std::string::npos) break;
    const std::size_t len = std::strtoull(data.c_str() + pos, nullptr, 10);
    if (len == 0 || pos + len > data.size()) break;
    const std::string record = data.substr(space + 1, pos + len - space - 2);  // drop '\n'
    if (record.rfind("path=", 0) == 0) path = record.substr(5);
    pos += len;
  }
  return path;
}

/// Visit every regular file: on_file(name, size) returns true to receive the body (then
/// `body` is filled), false to skip it. Returning from `done()` true stops early.
void walk(const std::filesystem::path& archive,
          const std::function<bool(const std::string&, std::uint64_t)>& want,
          const std::function<void(const std::string&, std::string&&)>& body,
          const std::function<bool()>& done) {
  Reader in(archive);
  std::array<unsigned char, kBlock> h;
  std::string long_name;
  bool first = true;
  while (!done()) {
    const std::uint64_t at = in.offset();
    const std::size_t got = in.read(h.data(), kBlock);
    if (got == 0 && !first) return;  // end without the two zero blocks: accepted
    if (got != kBlock) {
      if (first) throw Error("not a tar archive (too short)", in.name());
      throw Error("archive is truncated (inside a header)", in.name());
    }
    if (std::all_of(h.begin(), h.end(), [](unsigned char c) { return c == 0; })) return;
    // Header checksum: sum of all bytes with the checksum field read as spaces.
    std::uint64_t stored = 0;
    std::uint64_t sum = 0;
    for (std::size_t i = 0; i < kBlock; ++i) sum += (i >= 148 && i < 156) ? ' ' : h[i];
    if (!parse_number(h.data() + 148, 8, stored) || stored != sum)
      throw Error(first ? "not a tar archive (bad header checksum)"
                        : "corrupt archive: bad header checksum at byte " + std::to_string(at),
                  in.name());
    first = false;
    std::uint64_t size = 0;
    if (!parse_number(h.data() + 124, 12, size))
      throw Error("corrupt archive: bad size field at byte " + std::to_string(at), in.name());
    std::string name = field_string(h.data(), 100);
    if (std::memcmp(h.data() + 257, "ustar", 5) == 0) {
      const std::string prefix = field_string(h.data() + 345, 155);
      if (!prefix.empty()) name = prefix + "/" + name;
    }
    if (!long_name.empty()) {
      name = long_name;
      long_name.clear();
    }
    name = normalize(name);
    if (size > in.left())
      throw Error("archive is truncated or corrupt: member '" + name + "' declares " + std::to_string(size) +
                      " bytes, more than the " + std::to_string(in.left()) + " bytes left in the archive",
                  in.name(), "member '" + name + "'");
    const std::uint64_t padded = (size + kBlock - 1) / kBlock * kBlock;
    const char type = static_cast<char>(h[156]);
    if (type == 'L' || type == 'x') {  // GNU long name / pax header for the next entry
      if (size > (1u << 20)) throw Error("corrupt archive: oversized extended header", in.name());
      std::string data(size, '\0');
      if (in.read(data.data(), size) != size) in.truncated(name);
      in.skip(padded - size, name);
      long_name = type == 'L' ? field_string(reinterpret_cast<const unsigned char*>(data.data()), data.size())
                              : pax_path(data);
      continue;
    }
    const bool regular = type == '0' || type == '\0' || type == '7';
    if (regular && want(name, size)) {
      std::string data = read_body(in, size, name);
      in.skip(padded - size, name);
      body(name, std::move(data));
    } else {
      in.skip(padded, name);
    }
  }
}

}  // namespace

std::map<std::string, std::string> read_archive_members(const std::filesystem::path& archive,
                                                        const std::set<std::string>& members) {
  std::set<std::string> wanted;
  for (const auto& m : members) wanted.insert(normalize(m));
  std::map<std::string, std::string> out;
  walk(
      archive, [&](const std::string& name, std::uint64_t) { return wanted.count(name) && !out.count(name); },
      [&](const std::string& name, std::string&& data) { out.emplace(name, std::move(data)); },
      [&] { return out.size() == wanted.size(); });
  for (const auto& m : wanted)
    if (!out.count(m)) throw Error("archive has no member '" + m + "'", archive.string());
  // Answer under the names asked for.
  std::map<std::string, std::string> result;
  for (const auto& m : members) result.emplace(m, out.at(normalize(m)));
  return result;
}

std::string read_archive_member(const std::filesystem::path& archive, const std::string& member) {
  return std::move(read_archive_members(archive, {member}).begin()->second);
}

std::vector<std::string> list_archive(const std::filesystem::path& archive) {
  std::vector<std::string> names;
  walk(
      archive, [&](const std::string& name, std::uint64_t) {
        names.push_back(name);
        return false;
      },
      [](const std::string&, std::string&&) {}, [] { return false; });
  return names;
}

}  // namespace ts::datasets
