#include "io/mesh_off.hpp"

#include "engine/core.hpp"

#include <assimp/fast_atof.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string_view>
#include <vector>

namespace ts::io {

namespace {

constexpr std::size_t kMaxNumber = 100;   ///< characters of a number (Assimp's OFF lines hold 4095)

bool blank(char c) { return c == ' ' || c == '\t' || c == '\f' || c == '\v'; }
bool line_end(char c) { return c == '\n' || c == '\r'; }
bool digit(char c) { return c >= '0' && c <= '9'; }

/// Assimp's NextToken (OFFLoader.cpp): blanks and line ends, then whole lines while one begins
/// with '#'.
std::size_t next_token(std::string_view s, std::size_t p) {
  auto skip = [&] {
    while (p < s.size() && (s[p] == ' ' || s[p] == '\t' || line_end(s[p]))) ++p;
  };
  skip();
  while (p < s.size() && s[p] == '#') {
    while (p < s.size() && !line_end(s[p])) ++p;
    skip();
  }
  return p;
}

/// A count of the header: its digits from `p` on (none: 0 and no text), saturating.
struct Count {
  std::uint64_t value = 0;
  std::string text;   ///< as written (at most 30 characters, for messages)
};
Count read_count(std::string_view s, std::size_t& p) {
  Count c;
  const std::size_t start = p;
  for (; p < s.size() && digit(s[p]); ++p) {
    const auto d = static_cast<std::uint64_t>(s[p] - '0');
    c.value = c.value > (std::numeric_limits<std::uint64_t>::max() - d) / 10 ? std::numeric_limits<std::uint64_t>::max()
                                                                            : c.value * 10 + d;
  }
  c.text = std::string(s.substr(start, std::min<std::size_t>(p - start, 30)));
  return c;
}

/// The blank-separated words of a record line.
std::vector<std::string_view> words(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t p = 0;
  while (p < line.size()) {
    while (p < line.size() && blank(line[p])) ++p;
    const std::size_t start = p;
    while (p < line.size() && !blank(line[p])) ++p;
    if (p > start) out.push_back(line.substr(start, p - start));
  }
  return out;
}

/// What Assimp's number parser throws here on a word that is no number (its own exception
/// type, DeadlyImportError, is built by a function libassimp does not export).
struct NotANumber {
  template <class... T>
  explicit NotANumber(T&&...) {}
};

/// A coordinate as Assimp reads it (fast_atoreal_move into ai_real), the whole word, finite:
/// its text for Assimp ("5." written "5": Assimp would stop at the point), and its value in
/// `value`. Empty when it is none.
std::string coordinate(std::string_view word, ai_real& value) {
  std::string text(word.substr(0, kMaxNumber + 1));
  if (text.size() >= 2 && text.back() == '.' && digit(text[text.size() - 2])) text.pop_back();
  if (text.empty() || text.size() > kMaxNumber) return {};
  try {
    if (*Assimp::fast_atoreal_move<ai_real, NotANumber>(text.c_str(), value) != '\0') return {};
  } catch (const NotANumber&) {
    return {};
  }
  return std::isfinite(value) ? text : std::string();
}

/// A face's count or index: decimal digits only (Assimp's strtoul10), below `limit`.
bool index_word(std::string_view word, std::uint64_t limit, std::uint64_t& out) {
  if (word.empty() || word.size() > 19 || !std::all_of(word.begin(), word.end(), digit)) return false;
  out = 0;
  for (char c : word) out = out * 10 + static_cast<std::uint64_t>(c - '0');
  return out < limit;
}

std::string quoted(std::string_view word) { return "'" + std::string(word.substr(0, 20)) + "'"; }

}  // namespace

std::string off_for_assimp(const std::string& bytes, const std::string& name) {
  if (bytes.size() < 8)   // Assimp: "File is too small"
    throw Error("an OFF file of " + std::to_string(bytes.size()) + " bytes holds no mesh", name);
  // Assimp reads text up to its first NUL byte, after a UTF-8 byte-order mark.
  std::string_view s(bytes.data(), std::min(bytes.find('\0'), bytes.size()));
  std::size_t p = s.rfind("\xEF\xBB\xBF", 0) == 0 ? 3 : 0;
  auto at = [&](std::size_t i) { return i < s.size() ? s[i] : '\0'; };

  // The header (OFFLoader.cpp's InternReadFile): [ST][C][N][4][n]OFF, or the counts at once.
  p = next_token(s, p);
  const std::size_t first = p;
  bool homogeneous = false, dimension = false;
  if (at(p) == 'S' && at(p + 1) == 'T') p += 2;
  if (at(p) == 'C') ++p;
  if (at(p) == 'N') ++p;
  if (at(p) == '4') {
    homogeneous = true;
    ++p;
  }
  if (at(p) == 'n') {
    dimension = true;
    ++p;
  }
  if (at(p) == 'O' && at(p + 1) == 'F' && at(p + 2) == 'F') {
    p = next_token(s, p + 3);
  } else {
    p = first;
    homogeneous = dimension = false;
    if (!digit(at(p)))
      throw Error("not an OFF file: it begins with neither an OFF keyword nor the vertex count, but " +
                      quoted(s.substr(p, std::min<std::size_t>(s.size() - p, 20))),
                  name, "header");
  }
  std::uint64_t dims = 3;
  if (dimension) {
    const Count d = read_count(s, p);
    if (d.text.empty() || d.value < 1 || d.value > 3)
      throw Error("an nOFF file's dimension must be 1, 2 or 3 (Assimp reads no more), not " +
                      quoted(d.text.empty() ? s.substr(p, std::min<std::size_t>(s.size() - p, 20)) : d.text),
                  name, "header, dimension");
    dims = d.value;
    p = next_token(s, p);
  }
  Count counts[2];
  const char* what[2] = {"vertices", "faces"};
  for (int k = 0; k < 2; ++k) {
    if (k == 1) p = next_token(s, p);
    counts[k] = read_count(s, p);
    if (counts[k].value == 0)
      throw Error(counts[k].text.empty() ? std::string("the OFF header has no count of ") + what[k]
                                         : std::string("the OFF header declares no ") + what[k],
                  name, std::string("header, ") + what[k]);
  }
  while (p < s.size() && !line_end(s[p])) ++p;   // the edge count, not read

  // Nothing is sized by a count before the bytes after the header could hold it: a vertex takes
  // two bytes per number ("0 "), a face four ("1 0\n").
  const std::uint64_t room = s.size() - p, vertex_bytes = 2 * (dims + (homogeneous ? 1 : 0)), face_bytes = 4;
  const std::uint64_t vertex_limit = std::min<std::uint64_t>(room / vertex_bytes, std::numeric_limits<std::uint32_t>::max());
  const std::uint64_t n_vertices = counts[0].value, n_faces = counts[1].value;
  for (int k = 0; k < 2; ++k) {
    const std::uint64_t limit = k == 0 ? vertex_limit
                                       : std::min<std::uint64_t>((room - std::min(room, n_vertices * vertex_bytes)) / face_bytes,
                                                                 std::numeric_limits<std::uint32_t>::max());
    if (counts[k].value > limit)
      throw Error("OFF header declares " + counts[k].text + " " + what[k] + ", more than the " +
                      std::to_string(bytes.size()) + " bytes of the file can hold",
                  name, std::string("header, ") + what[k]);
  }

  std::string out = homogeneous ? "4OFF\n" : "OFF\n";
  out += std::to_string(n_vertices) + " " + std::to_string(n_faces) + " 0\n";
  out.reserve(out.size() + room);
  const std::size_t coordinates = static_cast<std::size_t>(dims) + (homogeneous ? 1 : 0);
  std::uint64_t record = 0;
  while (record < n_vertices + n_faces) {
    while (p < s.size() && line_end(s[p])) ++p;
    if (p >= s.size())
      throw Error("the file ends after " + std::to_string(std::min(record, n_vertices)) + " of " +
                      std::to_string(n_vertices) + " vertices and " +
                      std::to_string(record > n_vertices ? record - n_vertices : 0) + " of " +
                      std::to_string(n_faces) + " faces",
                  name, record < n_vertices ? "vertices" : "faces");
    const std::size_t start = p;
    while (p < s.size() && !line_end(s[p])) ++p;
    std::string_view line = s.substr(start, p - start);
    line = line.substr(0, line.find('#'));   // a comment, to the end of the line
    const auto w = words(line);
    if (w.empty()) continue;   // a blank or comment line
    const bool vertex = record < n_vertices;
    const std::string where = (vertex ? "vertex " : "face ") + std::to_string(vertex ? record : record - n_vertices);
    ++record;
    if (vertex) {
      std::string text;
      for (std::size_t i = 0; i < coordinates; ++i) {
        ai_real value = 0;
        const std::string v = i < w.size() ? coordinate(w[i], value) : std::string();
        const bool is_w = homogeneous && i + 1 == coordinates;
        if (v.empty() || (is_w && value == 0))
          throw Error("a vertex needs " + std::to_string(dims) + " finite numbers" +
                          (homogeneous ? " and a non-zero w" : "") + ", not " +
                          quoted(i < w.size() ? w[i] : std::string_view()),
                      name, where);
        if (is_w)
          for (std::uint64_t d = dims; d < 3; ++d) text += " 0";
        text += (text.empty() ? "" : " ") + v;
      }
      if (!homogeneous)
        for (std::uint64_t d = dims; d < 3; ++d) text += " 0";
      out += text + "\n";
      continue;
    }
    std::uint64_t n = 0;
    if (w.empty() || !index_word(w[0], 10, n) || n < 1)
      throw Error("a face's vertex count must be 1 to 9 (Assimp's OFF reader), not " +
                      quoted(w.empty() ? std::string_view() : w[0]),
                  name, where);
    out += std::to_string(n);
    for (std::size_t k = 1; k <= n; ++k) {
      std::uint64_t i = 0;
      if (k >= w.size() || !index_word(w[k], n_vertices, i))
        throw Error("face declares " + std::to_string(n) + " vertices; index " + std::to_string(k - 1) + " (" +
                        quoted(k < w.size() ? w[k] : std::string_view()) + ") is missing or not one of the " +
                        std::to_string(n_vertices) + " vertices",
                    name, where);
      out += " " + std::to_string(i);
    }
    out += "\n";
  }
  return out;
}

}  // namespace ts::io
