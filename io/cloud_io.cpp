#include "io/cloud_io.hpp"

#include "io/atomic_file.hpp"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <optional>
#include <string_view>

namespace ts::io {

namespace {

// --- scalar types ----------------------------------------------------------------------------
enum class Scalar { i8, u8, i16, u16, i32, u32, i64, u64, f32, f64 };

std::size_t scalar_size(Scalar t) {
  switch (t) {
    case Scalar::i8: case Scalar::u8: return 1;
    case Scalar::i16: case Scalar::u16: return 2;
    case Scalar::i32: case Scalar::u32: case Scalar::f32: return 4;
    default: return 8;
  }
}

std::optional<Scalar> ply_scalar(const std::string& s) {
  if (s == "char" || s == "int8") return Scalar::i8;
  if (s == "uchar" || s == "uint8") return Scalar::u8;
  if (s == "short" || s == "int16") return Scalar::i16;
  if (s == "ushort" || s == "uint16") return Scalar::u16;
  if (s == "int" || s == "int32") return Scalar::i32;
  if (s == "uint" || s == "uint32") return Scalar::u32;
  if (s == "float" || s == "float32") return Scalar::f32;
  if (s == "double" || s == "float64") return Scalar::f64;
  return std::nullopt;
}

std::optional<Scalar> pcd_scalar(char type, int size) {
  if (type == 'F' && size == 4) return Scalar::f32;
  if (type == 'F' && size == 8) return Scalar::f64;
  if (type == 'I' && size == 1) return Scalar::i8;
  if (type == 'I' && size == 2) return Scalar::i16;
  if (type == 'I' && size == 4) return Scalar::i32;
  if (type == 'I' && size == 8) return Scalar::i64;
  if (type == 'U' && size == 1) return Scalar::u8;
  if (type == 'U' && size == 2) return Scalar::u16;
  if (type == 'U' && size == 4) return Scalar::u32;
  if (type == 'U' && size == 8) return Scalar::u64;
  return std::nullopt;
}

template <class T>
T load_as(const unsigned char* p, bool swap) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

/// Value of one binary scalar; `big_endian` says how the file stores it.
double load(const unsigned char* p, Scalar t, bool big_endian) {
  const bool swap = big_endian != (std::endian::native == std::endian::big);
  switch (t) {
    case Scalar::i8: return load_as<std::int8_t>(p, false);
    case Scalar::u8: return load_as<std::uint8_t>(p, false);
    case Scalar::i16: return load_as<std::int16_t>(p, swap);
    case Scalar::u16: return load_as<std::uint16_t>(p, swap);
    case Scalar::i32: return load_as<std::int32_t>(p, swap);
    case Scalar::u32: return load_as<std::uint32_t>(p, swap);
    case Scalar::i64: return static_cast<double>(load_as<std::int64_t>(p, swap));
    case Scalar::u64: return static_cast<double>(load_as<std::uint64_t>(p, swap));
    case Scalar::f32: return load_as<float>(p, swap);
    case Scalar::f64: return load_as<double>(p, swap);
  }
  return 0.0;
}

template <class T>
void store_le(std::string& out, T v) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(b, b + sizeof(T));
  out.append(reinterpret_cast<const char*>(b), sizeof(T));
}

// --- text helpers ----------------------------------------------------------------------------
std::string where_line(int line) { return "line " + std::to_string(line); }
std::string where_point(const char* kind, std::uint64_t i) { return std::string(kind) + " " + std::to_string(i); }

std::vector<std::string_view> split_ws(std::string_view s) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t' || s[i] == '\r')) ++i;
    std::size_t j = i;
    while (j < s.size() && s[j] != ' ' && s[j] != '\t' && s[j] != '\r') ++j;
    if (j > i) out.push_back(s.substr(i, j - i));
    i = j;
  }
  return out;
}

/// Locale-independent number parse (accepts a leading '+', "nan", "inf").
bool parse_double(std::string_view tok, double& v) {
  if (!tok.empty() && tok[0] == '+') tok.remove_prefix(1);
  const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), v);
  return r.ec == std::errc() && r.ptr == tok.data() + tok.size();
}

bool parse_uint(std::string_view tok, std::uint64_t& v) {
  const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), v);
  return r.ec == std::errc() && r.ptr == tok.data() + tok.size();
}

std::string read_file(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw Error("file does not exist", path.string());
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error("cannot read the file", path.string());
  std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw Error("cannot read the file", path.string());
  return data;
}

/// Sequential line access over a byte buffer; `pos` is where the next line starts.
struct Lines {
  const std::string& data;
  std::size_t pos = 0;
  int line = 0;
  bool next(std::string_view& out) {
    if (pos >= data.size()) return false;
    std::size_t end = data.find('\n', pos);
    if (end == std::string::npos) end = data.size();
    out = std::string_view(data).substr(pos, end - pos);
    if (!out.empty() && out.back() == '\r') out.remove_suffix(1);
    pos = std::min(end + 1, data.size());
    ++line;
    return true;
  }
};

// --- writing ---------------------------------------------------------------------------------
void check_cloud(const PointCloud& cloud, const std::string& file) {
  if (!cloud.normals.empty() && cloud.normals.size() != cloud.points.size())
    throw Error("cloud has " + std::to_string(cloud.normals.size()) + " normals for " +
                    std::to_string(cloud.points.size()) + " points",
                file);
  for (std::size_t i = 0; i < cloud.points.size(); ++i) {
    if (!finite(cloud.points[i]))
      throw Error("non-finite coordinate (NaN or infinity)", file, where_point("point", i));
    if (cloud.has_normals() && !finite(cloud.normals[i]))
      throw Error("non-finite normal (NaN or infinity)", file, where_point("point", i));
  }
}

bool use_float64(const PointCloud& cloud, CloudPrecision p) {
  if (p != CloudPrecision::automatic) return p == CloudPrecision::float64;
  for (const auto& v : cloud.points)
    if (v.cwiseAbs().maxCoeff() > 100.0) return true;
  return false;
}

void append_number(std::string& out, double v, bool as_double) {
  char buf[40];
  const auto r = as_double ? std::to_chars(buf, buf + sizeof buf, v)
                           : std::to_chars(buf, buf + sizeof buf, static_cast<float>(v));
  out.append(buf, r.ptr);
}

/// Body rows in the order x y z [nx ny nz].
void append_rows(std::string& out, const PointCloud& cloud, bool binary, bool as_double) {
  const bool normals = cloud.has_normals();
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    double v[6];
    for (int k = 0; k < 3; ++k) v[k] = cloud.points[i][k];
    if (normals)
      for (int k = 0; k < 3; ++k) v[3 + k] = cloud.normals[i][k];
    const int n = normals ? 6 : 3;
    for (int k = 0; k < n; ++k) {
      if (binary) {
        if (as_double) store_le(out, v[k]);
        else store_le(out, static_cast<float>(v[k]));
      } else {
        if (k) out += ' ';
        append_number(out, v[k], as_double);
      }
    }
    if (!binary) out += '\n';
  }
}

void write_atomic(const std::filesystem::path& path, const std::string& bytes) {
  AtomicOutput out(path);
  {
    std::ofstream os(out.temp_path(), std::ios::binary | std::ios::trunc);
    if (!os) throw Error("cannot create the file", path.string());
    os.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    os.flush();
    if (!os) throw Error("cannot write the file (disk full?)", path.string());
  }
  out.commit();
}

std::string lower_extension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

}  // namespace

void write_ply(const std::filesystem::path& path, const PointCloud& cloud, const CloudWriteSettings& s) {
  check_cloud(cloud, path.string());
  const bool binary = s.encoding == CloudEncoding::binary;
  const bool dbl = use_float64(cloud, s.precision);
  const char* type = dbl ? "double" : "float";
  std::string out = "ply\nformat ";
  out += binary ? "binary_little_endian" : "ascii";
  out += " 1.0\ncomment written by touchstone\nelement vertex " + std::to_string(cloud.size()) + "\n";
  for (const char* name : {"x", "y", "z"}) out += std::string("property ") + type + " " + name + "\n";
  if (cloud.has_normals())
    for (const char* name : {"nx", "ny", "nz"}) out += std::string("property ") + type + " " + name + "\n";
  out += "end_header\n";
  append_rows(out, cloud, binary, dbl);
  write_atomic(path, out);
}

void write_pcd(const std::filesystem::path& path, const PointCloud& cloud, const CloudWriteSettings& s) {
  check_cloud(cloud, path.string());
  const bool binary = s.encoding == CloudEncoding::binary;
  const bool dbl = use_float64(cloud, s.precision);
  const bool normals = cloud.has_normals();
  const int fields = normals ? 6 : 3;
  auto repeat = [&](const std::string& token) {
    std::string r;
    for (int k = 0; k < fields; ++k) r += " " + token;
    return r;
  };
  const std::string n = std::to_string(cloud.size());
  std::string out = "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z";
  if (normals) out += " normal_x normal_y normal_z";
  out += "\nSIZE" + repeat(dbl ? "8" : "4") + "\nTYPE" + repeat("F") + "\nCOUNT" + repeat("1");
  out += "\nWIDTH " + n + "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " + n + "\nDATA ";
  out += binary ? "binary\n" : "ascii\n";
  append_rows(out, cloud, binary, dbl);
  write_atomic(path, out);
}

void write_cloud(const std::filesystem::path& path, const PointCloud& cloud, const CloudWriteSettings& s) {
  const std::string ext = lower_extension(path);
  if (ext == ".ply") return write_ply(path, cloud, s);
  if (ext == ".pcd") return write_pcd(path, cloud, s);
  throw Error("unknown point-cloud extension '" + path.extension().string() + "' (use .ply or .pcd)",
              path.string());
}

// --- reading: shared -------------------------------------------------------------------------
namespace {

/// Where x, y, z (and the normal) sit in one record, as value indices.
struct Layout {
  int x = -1, y = -1, z = -1, nx = -1, ny = -1, nz = -1;
  bool normals() const { return nx >= 0; }
};

void finish_layout(Layout& l, const std::string& file, const std::string& where, const char* nname) {
  if (l.x < 0 || l.y < 0 || l.z < 0) throw Error("no x, y and z fields", file, where);
  const int present = (l.nx >= 0) + (l.ny >= 0) + (l.nz >= 0);
  if (present != 0 && present != 3)
    throw Error(std::string("only some of the ") + nname + " fields are present", file, where);
}

/// Append one point from its values; rejects non-finite values.
void add_point(PointCloud& cloud, const double* v, const Layout& l, const std::string& file,
               const std::string& where) {
  const Vec3 p(v[l.x], v[l.y], v[l.z]);
  if (!finite(p)) throw Error("non-finite coordinate (NaN or infinity)", file, where);
  cloud.points.push_back(p);
  if (l.normals()) {
    const Vec3 n(v[l.nx], v[l.ny], v[l.nz]);
    if (!finite(n)) throw Error("non-finite normal (NaN or infinity)", file, where);
    cloud.normals.push_back(n);
  }
}

}  // namespace

// --- PLY -------------------------------------------------------------------------------------
namespace {
struct PlyProperty {
  std::string name;
  Scalar type = Scalar::f32;
  bool list = false;
  Scalar count_type = Scalar::u8;
};
struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
  int line = 0;
};

enum class PlyFormat { ascii, le, be };

struct PlyHeader {
  PlyFormat format = PlyFormat::ascii;
  std::vector<PlyElement> elements;
};

/// Parse the header; `lines` is left at the first line of the body.
PlyHeader parse_ply_header(Lines& lines, const std::string& file) {
  std::string_view line;
  if (!lines.next(line) || line != "ply") throw Error("not a PLY file (the first line is not 'ply')", file, "line 1");
  PlyHeader h;
  bool have_format = false, ended = false;
  std::vector<PlyElement>& elements = h.elements;
  while (lines.next(line)) {
    const auto tok = split_ws(line);
    const std::string where = where_line(lines.line);
    if (tok.empty()) continue;
    if (tok[0] == "comment" || tok[0] == "obj_info") continue;
    if (tok[0] == "end_header") {
      ended = true;
      break;
    }
    if (tok[0] == "format") {
      if (tok.size() != 3) throw Error("malformed format line", file, where);
      if (tok[1] == "ascii") h.format = PlyFormat::ascii;
      else if (tok[1] == "binary_little_endian") h.format = PlyFormat::le;
      else if (tok[1] == "binary_big_endian") h.format = PlyFormat::be;
      else throw Error("unknown PLY format '" + std::string(tok[1]) + "'", file, where);
      have_format = true;
    } else if (tok[0] == "element") {
      PlyElement e;
      if (tok.size() != 3 || !parse_uint(tok[2], e.count))
        throw Error("malformed element line (expected 'element NAME COUNT')", file, where);
      e.name = tok[1];
      e.line = lines.line;
      elements.push_back(std::move(e));
    } else if (tok[0] == "property") {
      if (elements.empty()) throw Error("property before any element", file, where);
      PlyProperty p;
      if (tok.size() == 5 && tok[1] == "list") {
        const auto ct = ply_scalar(std::string(tok[2])), it = ply_scalar(std::string(tok[3]));
        if (!ct || !it) throw Error("unknown property type in list", file, where);
        if (*ct == Scalar::f32 || *ct == Scalar::f64)
          throw Error("a list's count type must be an integer type, not '" + std::string(tok[2]) + "'", file, where);
        p.list = true;
        p.count_type = *ct;
        p.type = *it;
        p.name = tok[4];
      } else if (tok.size() == 3) {
        const auto t = ply_scalar(std::string(tok[1]));
        if (!t) throw Error("unknown property type '" + std::string(tok[1]) + "'", file, where);
        p.type = *t;
        p.name = tok[2];
      } else {
        throw Error("malformed property line", file, where);
      }
      elements.back().properties.push_back(std::move(p));
    } else {
      throw Error("unknown header keyword '" + std::string(tok[0]) + "'", file, where);
    }
  }
  if (!ended) throw Error("the PLY header has no end_header line", file);
  if (!have_format) throw Error("the PLY header has no format line", file);
  return h;
}

/// Skip one binary list (count, then values) at `p`; false if the file ends inside it.
/// Throws on a count that is negative, fractional or beyond 2^32.
bool skip_binary_list(const unsigned char*& p, const unsigned char* end, const PlyProperty& prop, bool big,
                      const std::string& file, const std::string& where) {
  const std::size_t cs = scalar_size(prop.count_type);
  if (static_cast<std::size_t>(end - p) < cs) return false;
  const double c = load(p, prop.count_type, big);
  p += cs;
  if (!(c >= 0) || c > 4294967295.0) throw Error("list length out of range", file, where);
  const auto bytes = static_cast<std::uint64_t>(c) * scalar_size(prop.type);
  if (static_cast<std::uint64_t>(end - p) < bytes) return false;
  p += bytes;
  return true;
}

}  // namespace

void check_ply_structure(const std::string& data, const std::string& file) {
  Lines lines{data};
  const PlyHeader h = parse_ply_header(lines, file);
  std::string_view line;
  if (h.format == PlyFormat::ascii) {
    for (const auto& e : h.elements)
      for (std::uint64_t r = 0; r < e.count; ++r) {
        if (!lines.next(line))
          throw Error("the file ends inside element '" + e.name + "' (" + std::to_string(r) + " of " +
                          std::to_string(e.count) + " read)",
                      file, where_line(lines.line));
        const auto tok = split_ws(line);
        std::size_t t = 0;
        for (const auto& p : e.properties) {
          std::uint64_t n = 0;
          if (p.list && (t >= tok.size() || !parse_uint(tok[t], n) || n > tok.size() - t - 1))
            throw Error("a list of element '" + e.name + "' declares more values than its line holds", file,
                        where_line(lines.line));
          if (!p.list && t >= tok.size())
            throw Error("too few values for element '" + e.name + "'", file, where_line(lines.line));
          t += p.list ? 1 + n : 1;
        }
      }
    return;
  }
  const bool big = h.format == PlyFormat::be;
  const auto* p = reinterpret_cast<const unsigned char*>(data.data()) + lines.pos;
  const auto* end = reinterpret_cast<const unsigned char*>(data.data()) + data.size();
  for (const auto& e : h.elements) {
    if (e.properties.empty()) continue;
    for (std::uint64_t r = 0; r < e.count; ++r)
      for (const auto& prop : e.properties) {
        const std::string where = where_point(e.name.c_str(), r);
        const std::size_t sz = scalar_size(prop.type);
        if (prop.list ? !skip_binary_list(p, end, prop, big, file, where) : static_cast<std::size_t>(end - p) < sz)
          throw Error("the file ends inside element '" + e.name + "'", file, where);
        if (!prop.list) p += sz;
      }
  }
}

PointCloud read_ply(const std::filesystem::path& path) {
  const std::string file = path.string();
  const std::string data = read_file(path);
  Lines lines{data};
  std::string_view line;
  const auto [format, elements] = parse_ply_header(lines, file);
  const auto vit = std::find_if(elements.begin(), elements.end(),
                                [](const PlyElement& e) { return e.name == "vertex"; });
  if (vit == elements.end()) throw Error("the PLY header has no vertex element", file);
  const PlyElement& vertex = *vit;
  const std::string vwhere = where_line(vertex.line);

  Layout layout;
  for (std::size_t i = 0; i < vertex.properties.size(); ++i) {
    const auto& p = vertex.properties[i];
    int* slot = nullptr;
    if (p.name == "x") slot = &layout.x;
    else if (p.name == "y") slot = &layout.y;
    else if (p.name == "z") slot = &layout.z;
    else if (p.name == "nx" || p.name == "normal_x") slot = &layout.nx;
    else if (p.name == "ny" || p.name == "normal_y") slot = &layout.ny;
    else if (p.name == "nz" || p.name == "normal_z") slot = &layout.nz;
    if (!slot) continue;
    if (p.list) throw Error("vertex property '" + p.name + "' is a list", file, vwhere);
    *slot = static_cast<int>(i);
  }
  finish_layout(layout, file, vwhere, "nx ny nz");

  PointCloud cloud;
  const std::size_t reserve = static_cast<std::size_t>(std::min<std::uint64_t>(vertex.count, data.size() / 3 + 1));
  cloud.points.reserve(reserve);
  if (layout.normals()) cloud.normals.reserve(reserve);
  std::vector<double> values(vertex.properties.size(), 0.0);

  if (format == PlyFormat::ascii) {
    for (const auto& e : elements) {
      const bool is_vertex = &e == &vertex;
      for (std::uint64_t r = 0; r < e.count; ++r) {
        if (!lines.next(line))
          throw Error("the file ends inside element '" + e.name + "' (" + std::to_string(r) + " of " +
                          std::to_string(e.count) + " read)",
                      file, where_line(lines.line));
        if (!is_vertex) continue;
        const std::string where = where_line(lines.line);
        const auto tok = split_ws(line);
        std::size_t t = 0;
        for (std::size_t k = 0; k < e.properties.size(); ++k) {
          const auto& p = e.properties[k];
          std::uint64_t skip = 0;
          if (p.list) {
            if (t >= tok.size() || !parse_uint(tok[t], skip))
              throw Error("malformed list count", file, where);
            if (skip > tok.size() - t - 1)
              throw Error("the list holds " + std::to_string(skip) + " values, the line only " +
                              std::to_string(tok.size() - t - 1) + " more",
                          file, where);
            t += 1 + skip;
            continue;
          }
          if (t >= tok.size())
            throw Error("too few values on the line (" + std::to_string(tok.size()) + ")", file, where);
          if (!parse_double(tok[t], values[k]))
            throw Error("cannot read '" + std::string(tok[t]) + "' as a number", file, where);
          ++t;
        }
        add_point(cloud, values.data(), layout, file, where);
      }
      if (is_vertex) break;
    }
  } else {
    const bool big = format == PlyFormat::be;
    const auto* p = reinterpret_cast<const unsigned char*>(data.data()) + lines.pos;
    const auto* end = reinterpret_cast<const unsigned char*>(data.data()) + data.size();
    for (const auto& e : elements) {
      const bool is_vertex = &e == &vertex;
      if (e.properties.empty()) continue;
      for (std::uint64_t r = 0; r < e.count; ++r) {
        const std::string where = is_vertex ? where_point("vertex", r) : where_point(e.name.c_str(), r);
        for (std::size_t k = 0; k < e.properties.size(); ++k) {
          const auto& prop = e.properties[k];
          if (prop.list) {
            if (!skip_binary_list(p, end, prop, big, file, where))
              throw Error("the file ends inside element '" + e.name + "'", file, where);
            continue;
          }
          const std::size_t sz = scalar_size(prop.type);
          if (static_cast<std::size_t>(end - p) < sz)
            throw Error("the file ends inside element '" + e.name + "' (truncated file?)", file, where);
          if (is_vertex) values[k] = load(p, prop.type, big);
          p += sz;
        }
        if (is_vertex) add_point(cloud, values.data(), layout, file, where);
      }
      if (is_vertex) break;
    }
  }
  return cloud;
}

// --- PCD -------------------------------------------------------------------------------------
namespace {

/// LZF decompression (the format of PCL's binary_compressed, after liblzf's lzf_d.c).
bool lzf_decompress(const unsigned char* in, std::size_t in_size, unsigned char* out, std::size_t out_size) {
  const unsigned char* ip = in;
  const unsigned char* const in_end = in + in_size;
  unsigned char* op = out;
  unsigned char* const out_end = out + out_size;
  while (ip < in_end) {
    unsigned ctrl = *ip++;
    if (ctrl < (1u << 5)) {  // literal run of ctrl + 1 bytes
      ++ctrl;
      if (static_cast<std::size_t>(out_end - op) < ctrl || static_cast<std::size_t>(in_end - ip) < ctrl)
        return false;
      std::memcpy(op, ip, ctrl);
      op += ctrl;
      ip += ctrl;
    } else {  // back reference
      std::size_t len = ctrl >> 5;
      std::size_t back = (static_cast<std::size_t>(ctrl & 0x1f) << 8) + 1;
      if (ip >= in_end) return false;
      if (len == 7) {
        len += *ip++;
        if (ip >= in_end) return false;
      }
      back += *ip++;
      len += 2;
      if (static_cast<std::size_t>(out_end - op) < len || static_cast<std::size_t>(op - out) < back)
        return false;
      const unsigned char* ref = op - back;
      for (std::size_t k = 0; k < len; ++k) *op++ = *ref++;  // may overlap: byte by byte
    }
  }
  return op == out_end;
}

struct PcdField {
  std::string name;
  Scalar type = Scalar::f32;
  int size = 4;
  char code = 'F';
  std::uint64_t count = 1;
};

}  // namespace

PointCloud read_pcd(const std::filesystem::path& path) {
  const std::string file = path.string();
  const std::string data = read_file(path);
  Lines lines{data};
  std::string_view line;
  std::vector<std::string> names;
  std::vector<std::uint64_t> sizes, counts;
  std::vector<std::string> types;
  std::optional<std::uint64_t> width, height, points;
  std::string encoding;
  int fields_line = 0;
  while (lines.next(line)) {
    const auto tok = split_ws(line);
    const std::string where = where_line(lines.line);
    if (tok.empty() || tok[0][0] == '#') continue;
    const std::string key(tok[0]);
    auto uints = [&](std::vector<std::uint64_t>& out) {
      out.clear();
      for (std::size_t i = 1; i < tok.size(); ++i) {
        std::uint64_t v = 0;
        if (!parse_uint(tok[i], v)) throw Error("malformed " + key + " line", file, where);
        out.push_back(v);
      }
    };
    auto one_uint = [&]() {
      std::uint64_t v = 0;
      if (tok.size() != 2 || !parse_uint(tok[1], v)) throw Error("malformed " + key + " line", file, where);
      return v;
    };
    if (key == "VERSION" || key == "VIEWPOINT") {
      continue;
    } else if (key == "FIELDS" || key == "COLUMNS") {
      names.assign(tok.begin() + 1, tok.end());
      fields_line = lines.line;
    } else if (key == "SIZE") {
      uints(sizes);
    } else if (key == "TYPE") {
      types.assign(tok.begin() + 1, tok.end());
    } else if (key == "COUNT") {
      uints(counts);
    } else if (key == "WIDTH") {
      width = one_uint();
    } else if (key == "HEIGHT") {
      height = one_uint();
    } else if (key == "POINTS") {
      points = one_uint();
    } else if (key == "DATA") {
      if (tok.size() != 2) throw Error("malformed DATA line", file, where);
      encoding = tok[1];
      if (encoding != "ascii" && encoding != "binary" && encoding != "binary_compressed")
        throw Error("unknown PCD DATA encoding '" + encoding + "'", file, where);
      break;
    } else if (lines.line == 1) {
      throw Error("not a PCD file (unknown first line)", file, where);
    } else {
      throw Error("unknown PCD header keyword '" + key + "'", file, where);
    }
  }
  if (encoding.empty()) throw Error("the PCD header has no DATA line", file);
  const std::string fwhere = where_line(fields_line);
  if (names.empty()) throw Error("the PCD header has no FIELDS line", file);
  if (counts.empty()) counts.assign(names.size(), 1);
  if (sizes.size() != names.size() || types.size() != names.size() || counts.size() != names.size())
    throw Error("FIELDS, SIZE, TYPE and COUNT have different lengths (" + std::to_string(names.size()) +
                    ", " + std::to_string(sizes.size()) + ", " + std::to_string(types.size()) + ", " +
                    std::to_string(counts.size()) + ")",
                file, fwhere);
  // Counts are validated before anything is computed from them: every product below fits.
  constexpr std::uint64_t kMaxPoints = std::uint64_t{1} << 40, kMaxCount = std::uint64_t{1} << 20;
  std::uint64_t wh = 0;
  if (width && __builtin_mul_overflow(*width, height.value_or(1), &wh))
    throw Error("WIDTH*HEIGHT overflows", file, "WIDTH");
  if (!points) {
    if (!width) throw Error("the PCD header has neither POINTS nor WIDTH", file);
    points = wh;
  } else if (width && wh != *points) {
    throw Error("POINTS (" + std::to_string(*points) + ") differs from WIDTH*HEIGHT (" + std::to_string(wh) + ")",
                file);
  }
  if (*points > kMaxPoints)
    throw Error("POINTS " + std::to_string(*points) + " is beyond any real cloud (at most 2^40)", file, "POINTS");
  for (std::size_t i = 0; i < counts.size(); ++i)
    if (counts[i] > kMaxCount)
      throw Error("field '" + names[i] + "' has COUNT " + std::to_string(counts[i]) + " (at most 2^20)", file, fwhere);

  // Fields: value index of each component, byte offset within a binary record.
  std::vector<PcdField> fields(names.size());
  std::vector<std::uint64_t> value_index(names.size()), byte_offset(names.size());
  std::uint64_t values_per_point = 0, record = 0;
  Layout layout;
  for (std::size_t i = 0; i < names.size(); ++i) {
    auto& f = fields[i];
    f.name = names[i];
    f.size = static_cast<int>(sizes[i]);
    f.code = types[i].size() == 1 ? types[i][0] : '?';
    f.count = counts[i];
    const auto t = pcd_scalar(f.code, f.size);
    if (!t)
      throw Error("unsupported field type " + types[i] + std::to_string(sizes[i]) + " for '" + f.name + "'",
                  file, fwhere);
    f.type = *t;
    if (f.count == 0) throw Error("field '" + f.name + "' has COUNT 0", file, fwhere);
    value_index[i] = values_per_point;
    byte_offset[i] = record;
    values_per_point += f.count;
    record += f.count * sizes[i];
    int* slot = nullptr;
    if (f.name == "x") slot = &layout.x;
    else if (f.name == "y") slot = &layout.y;
    else if (f.name == "z") slot = &layout.z;
    else if (f.name == "normal_x") slot = &layout.nx;
    else if (f.name == "normal_y") slot = &layout.ny;
    else if (f.name == "normal_z") slot = &layout.nz;
    if (slot) {
      if (f.count != 1) throw Error("field '" + f.name + "' must have COUNT 1", file, fwhere);
      *slot = static_cast<int>(i);
    }
  }
  finish_layout(layout, file, fwhere, "normal_x normal_y normal_z");
  // Layout in terms of per-point value slots (x, y, z, nx, ny, nz -> 0..5).
  const int used[6] = {layout.x, layout.y, layout.z, layout.nx, layout.ny, layout.nz};
  const Layout compact{0, 1, 2, layout.normals() ? 3 : -1, layout.normals() ? 4 : -1,
                       layout.normals() ? 5 : -1};
  const int n_used = layout.normals() ? 6 : 3;

  PointCloud cloud;
  const std::size_t reserve = static_cast<std::size_t>(std::min<std::uint64_t>(*points, data.size() / 3 + 1));
  cloud.points.reserve(reserve);
  if (layout.normals()) cloud.normals.reserve(reserve);
  double v[6] = {0, 0, 0, 0, 0, 0};

  if (encoding == "ascii") {
    for (std::uint64_t r = 0; r < *points; ++r) {
      if (!lines.next(line))
        throw Error("the file ends after " + std::to_string(r) + " of " + std::to_string(*points) + " points",
                    file, where_line(lines.line + 1));
      const std::string where = where_line(lines.line);
      const auto tok = split_ws(line);
      if (tok.size() != values_per_point)
        throw Error("line has " + std::to_string(tok.size()) + " values, expected " +
                        std::to_string(values_per_point),
                    file, where);
      for (int k = 0; k < n_used; ++k) {
        const auto tk = tok[value_index[static_cast<std::size_t>(used[k])]];
        if (!parse_double(tk, v[k])) throw Error("cannot read '" + std::string(tk) + "' as a number", file, where);
      }
      add_point(cloud, v, compact, file, where);
    }
    return cloud;
  }

  const auto* body = reinterpret_cast<const unsigned char*>(data.data()) + lines.pos;
  const std::size_t available = data.size() - lines.pos;
  std::uint64_t needed = 0;   // bytes of point data
  if (__builtin_mul_overflow(*points, record, &needed))
    throw Error("POINTS (" + std::to_string(*points) + ") records of " + std::to_string(record) +
                    " bytes exceed any file",
                file, "POINTS");
  if (encoding == "binary") {
    if (record > 0 && available / record < *points)
      throw Error("the file is truncated: " + std::to_string(*points) + " points need " +
                      std::to_string(needed) + " bytes of data, found " + std::to_string(available),
                  file, "DATA");
    for (std::uint64_t r = 0; r < *points; ++r) {
      const unsigned char* rec = body + r * record;
      for (int k = 0; k < n_used; ++k) {
        const auto f = static_cast<std::size_t>(used[k]);
        v[k] = load(rec + byte_offset[f], fields[f].type, false);
      }
      add_point(cloud, v, compact, file, where_point("point", r));
    }
    return cloud;
  }

  // binary_compressed: two little-endian uint32 sizes, then LZF data holding the fields one
  // after another (structure of arrays).
  if (available < 8) throw Error("the compressed PCD data is truncated", file);
  const auto compressed = load_as<std::uint32_t>(body, std::endian::native == std::endian::big);
  const auto uncompressed = load_as<std::uint32_t>(body + 4, std::endian::native == std::endian::big);
  if (compressed > available - 8) throw Error("the compressed PCD data is truncated", file);
  if (uncompressed != needed)
    throw Error("the compressed PCD data holds " + std::to_string(uncompressed) + " bytes, expected " +
                    std::to_string(needed),
                file);
  std::vector<unsigned char> soa(uncompressed);
  if (uncompressed > 0 && !lzf_decompress(body + 8, compressed, soa.data(), soa.size()))
    throw Error("the compressed PCD data is corrupt", file);
  for (std::uint64_t r = 0; r < *points; ++r) {
    for (int k = 0; k < n_used; ++k) {
      const auto f = static_cast<std::size_t>(used[k]);
      const std::uint64_t field_start = *points * byte_offset[f];
      v[k] = load(soa.data() + field_start + r * static_cast<std::uint64_t>(fields[f].size), fields[f].type, false);
    }
    add_point(cloud, v, compact, file, where_point("point", r));
  }
  return cloud;
}

PointCloud read_cloud(const std::filesystem::path& path) {
  const std::string ext = lower_extension(path);
  if (ext == ".ply") return read_ply(path);
  if (ext == ".pcd") return read_pcd(path);
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    std::error_code ec;
    throw Error(std::filesystem::exists(path, ec) ? "cannot read the file" : "file does not exist", path.string());
  }
  std::string first;
  std::getline(in, first);
  if (first.rfind("ply", 0) == 0) return read_ply(path);
  if (first.rfind("# .PCD", 0) == 0 || first.rfind("VERSION", 0) == 0) return read_pcd(path);
  throw Error("unknown point-cloud format (expected a .ply or .pcd file)", path.string());
}

}  // namespace ts::io
