// A small RAII wrapper over the HDF5 C API, shared by every Touchstone store (object databases,
// tactile logs, run stores).
//
// Guarantees
// - Every failure throws ts::Error naming the file and the HDF5 path, e.g.
//   "dataset has shape [120,2], expected [n,3] (db.h5, /objects/cube/fine/points)".
//   HDF5's own error-stack printing is silenced; its innermost message is appended instead.
// - Thread safety: HDF5 is not thread-safe, so every call here (including handle release) takes
//   one global recursive mutex, h5::mutex(). Hold it yourself to make a sequence of calls atomic.
// - Byte-identical output: objects are created without timestamps and nothing random is stored,
//   so writing the same content in the same order gives the same bytes.
// - Types are checked strictly on read: a float64 dataset reads only as double, a float32 one
//   only as float, and so on (class, size and sign must match).
//
// hdf5.h is deliberately not included here: users of this header need no HDF5 include path.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

namespace ts {
class Error;
}
namespace ts::io {
class AtomicOutput;
}

namespace ts::io::h5 {

/// Dataset shape (row-major; the first dimension is the one that grows on append).
using Shape = std::vector<std::uint64_t>;
/// Expected shape on read: a size per dimension, or kAny for "any size" (printed as n).
using ShapeSpec = std::vector<std::int64_t>;
constexpr std::int64_t kAny = -1;

/// The global HDF5 lock (recursive). Every function of this wrapper takes it.
std::recursive_mutex& mutex();

/// "[120,3]" and "[n,3]".
std::string to_string(const Shape& shape);
std::string to_string(const ShapeSpec& spec);

/// Storage options of a dataset. Compressed (or extendible) datasets are chunked; deflate output
/// is deterministic, so compressed files stay byte-identical.
struct Storage {
  int deflate = 0;                 ///< zlib level 0..9; 0 = no compression
  bool shuffle = true;             ///< byte-shuffle filter before deflate (helps numbers)
  std::uint64_t chunk_rows = 0;    ///< rows per chunk; 0 = about 256 KiB per chunk
};

namespace detail {
struct Node;
}

class Group {
 public:
  Group();
  ~Group();
  Group(const Group&);
  Group& operator=(const Group&);
  Group(Group&&) noexcept;
  Group& operator=(Group&&) noexcept;

  const std::string& file() const;   ///< the file name used in error messages
  const std::string& path() const;   ///< HDF5 path of this group ("/", "/objects/cube")
  std::string child_path(const std::string& name) const;

  // --- links and groups -------------------------------------------------------------------
  /// True when `name` (may be nested, "a/b/c") exists below this group.
  bool has(const std::string& name) const;
  bool has_group(const std::string& name) const;
  bool has_dataset(const std::string& name) const;
  Group open_group(const std::string& name) const;     ///< throws when missing
  Group create_group(const std::string& name);         ///< throws when it exists
  Group require_group(const std::string& name);        ///< open or create
  /// Names of the direct children, sorted by name.
  std::vector<std::string> children() const;
  /// Unlink a child (group or dataset). Its space is not reclaimed in the file.
  void remove(const std::string& name);
  /// Copy `source`'s child `name` (a group with everything below it, or a dataset) here under
  /// the same name, compressed chunks as they are (H5Ocopy). Throws when it exists here.
  void copy_from(const Group& source, const std::string& name);

  // --- datasets ---------------------------------------------------------------------------
  /// Write a new dataset of `shape` from `data` (row-major, product(shape) values).
  /// T: double, float, int16_t, int32_t, int64_t, uint8_t, uint32_t, uint64_t.
  template <class T>
  void write(const std::string& name, const T* data, const Shape& shape, const Storage& storage = {});
  template <class T>
  void write(const std::string& name, const std::vector<T>& data, const Storage& storage = {}) {
    write(name, data.data(), Shape{data.size()}, storage);
  }
  void write_strings(const std::string& name, const std::vector<std::string>& values);

  Shape shape(const std::string& name) const;
  /// Read a whole dataset, checking the element type and that the shape matches `expected`
  /// (same rank, each fixed size equal). `actual` receives the shape when given.
  template <class T>
  std::vector<T> read(const std::string& name, const ShapeSpec& expected, Shape* actual = nullptr) const;
  /// Rows [first, first + count) along the first dimension.
  template <class T>
  std::vector<T> read_rows(const std::string& name, std::uint64_t first, std::uint64_t count,
                           const ShapeSpec& expected) const;
  std::vector<std::string> read_strings(const std::string& name) const;

  /// Create an empty dataset that grows along its first dimension: shape [0, row_shape...].
  template <class T>
  void create_extendible(const std::string& name, const Shape& row_shape, const Storage& storage = {});
  /// Append `rows` rows (each of the dataset's row shape) to an extendible dataset.
  template <class T>
  void append(const std::string& name, const T* data, std::uint64_t rows);

  // --- attributes (on this group) ---------------------------------------------------------
  bool has_attribute(const std::string& name) const;
  void set_attribute(const std::string& name, const std::string& value);
  void set_attribute(const std::string& name, const char* value) { set_attribute(name, std::string(value)); }
  void set_attribute(const std::string& name, std::int64_t value);
  void set_attribute(const std::string& name, double value);
  void set_attribute(const std::string& name, const std::vector<double>& values);
  std::string string_attribute(const std::string& name) const;
  std::int64_t int_attribute(const std::string& name) const;
  double double_attribute(const std::string& name) const;
  /// expected_size: the number of values required, or kAny.
  std::vector<double> doubles_attribute(const std::string& name, std::int64_t expected_size = kAny) const;
  /// Attribute names, sorted.
  std::vector<std::string> attributes() const;

 private:
  friend class File;
  explicit Group(std::shared_ptr<detail::Node> node);
  std::shared_ptr<detail::Node> node_;
};

class File {
 public:
  enum class Access { read, read_write };

  File();
  ~File();  ///< closes quietly; call close() to see errors
  File(File&&) noexcept;
  File& operator=(File&&) noexcept;

  /// Create (truncate) `path`. `display` is the name used in errors (default: path).
  static File create(const std::filesystem::path& path, const std::string& display = {});
  /// Create the temporary file of an atomic output; errors name the target.
  static File create(const AtomicOutput& output);
  /// Open an existing file. A missing, foreign (not HDF5) or truncated file throws a clear error.
  static File open(const std::filesystem::path& path, Access access = Access::read,
                   const std::string& display = {});

  bool is_open() const;
  const std::string& name() const;
  Group root() const;
  Group group(const std::string& path) const { return root().open_group(path); }
  /// Flush and close (every handle into the file becomes invalid). Throws on failure.
  void close();

 private:
  std::shared_ptr<detail::Node> node_;
};

/// Whether an error thrown by File::open says the file is locked by another process (HDF5's
/// "unable to lock (the) file"), which is worth waiting out, as opposed to a missing, foreign or
/// corrupt file, which is not.
bool is_lock_contention(const ts::Error& e);

}  // namespace ts::io::h5
