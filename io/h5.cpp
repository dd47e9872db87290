#include "io/h5.hpp"

#include "engine/core.hpp"
#include "io/atomic_file.hpp"

#include <hdf5.h>
#include <libdeflate.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <memory>
#include <numeric>
#include <type_traits>

namespace ts::io::h5 {

static_assert(std::is_same_v<hid_t, std::int64_t>, "h5.hpp stores hid_t as int64_t");
static_assert(std::is_same_v<hsize_t, unsigned long long> || sizeof(hsize_t) == 8);

std::recursive_mutex& mutex() {
  static std::recursive_mutex m;
  return m;
}

std::string to_string(const Shape& shape) {
  std::string s = "[";
  for (std::size_t i = 0; i < shape.size(); ++i) {
    if (i) s += ',';
    s += std::to_string(shape[i]);
  }
  return s + "]";
}

std::string to_string(const ShapeSpec& spec) {
  std::string s = "[";
  for (std::size_t i = 0; i < spec.size(); ++i) {
    if (i) s += ',';
    s += spec[i] == kAny ? std::string("n") : std::to_string(spec[i]);
  }
  return s + "]";
}

namespace {

/// Takes the global lock; the first time on each thread, silences HDF5's automatic error
/// printing (the library is built thread-safe, so that setting is per thread).
struct Guard {
  std::lock_guard<std::recursive_mutex> lock{mutex()};
  Guard() {
    thread_local bool silenced = false;
    if (!silenced) {
      H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
      silenced = true;
    }
  }
};

herr_t innermost_message(unsigned n, const H5E_error2_t* err, void* data) {
  if (n == 0 && err && err->desc) *static_cast<std::string*>(data) = err->desc;
  return 0;
}

/// The innermost message of HDF5's error stack (where the failure was detected), then clear.
std::string hdf5_detail() {
  std::string s;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, innermost_message, &s);
  H5Eclear2(H5E_DEFAULT);
  return s;
}

/// Owns one HDF5 identifier of any kind.
class Id {
 public:
  Id() = default;
  explicit Id(hid_t id) : id_(id) {}
  ~Id() { reset(); }
  Id(const Id&) = delete;
  Id& operator=(const Id&) = delete;
  Id(Id&& o) noexcept : id_(o.id_) { o.id_ = -1; }
  hid_t get() const { return id_; }
  bool valid() const { return id_ >= 0; }
  void reset() {
    if (id_ >= 0) {
      Guard g;
      switch (H5Iget_type(id_)) {
        case H5I_FILE: H5Fclose(id_); break;
        case H5I_GROUP: H5Gclose(id_); break;
        case H5I_DATASET: H5Dclose(id_); break;
        case H5I_DATASPACE: H5Sclose(id_); break;
        case H5I_DATATYPE: H5Tclose(id_); break;
        case H5I_ATTR: H5Aclose(id_); break;
        case H5I_GENPROP_LST: H5Pclose(id_); break;
        default: break;
      }
      H5Eclear2(H5E_DEFAULT);
      id_ = -1;
    }
  }

 private:
  hid_t id_ = -1;
};

std::string join(const std::string& parent, const std::string& name) {
  if (name.empty()) return parent;
  if (name[0] == '/') return name;
  return parent == "/" ? "/" + name : parent + "/" + name;
}

template <class T>
struct TypeOf;
template <>
struct TypeOf<double> {
  static hid_t mem() { return H5T_NATIVE_DOUBLE; }
  static hid_t file() { return H5T_IEEE_F64LE; }
};
template <>
struct TypeOf<float> {
  static hid_t mem() { return H5T_NATIVE_FLOAT; }
  static hid_t file() { return H5T_IEEE_F32LE; }
};
template <>
struct TypeOf<std::int16_t> {
  static hid_t mem() { return H5T_NATIVE_INT16; }
  static hid_t file() { return H5T_STD_I16LE; }
};
template <>
struct TypeOf<std::int32_t> {
  static hid_t mem() { return H5T_NATIVE_INT32; }
  static hid_t file() { return H5T_STD_I32LE; }
};
template <>
struct TypeOf<std::int64_t> {
  static hid_t mem() { return H5T_NATIVE_INT64; }
  static hid_t file() { return H5T_STD_I64LE; }
};
template <>
struct TypeOf<std::uint8_t> {
  static hid_t mem() { return H5T_NATIVE_UINT8; }
  static hid_t file() { return H5T_STD_U8LE; }
};
template <>
struct TypeOf<std::uint32_t> {
  static hid_t mem() { return H5T_NATIVE_UINT32; }
  static hid_t file() { return H5T_STD_U32LE; }
};
template <>
struct TypeOf<std::uint64_t> {
  static hid_t mem() { return H5T_NATIVE_UINT64; }
  static hid_t file() { return H5T_STD_U64LE; }
};

template <class T>
std::string type_name() {
  if constexpr (std::is_floating_point_v<T>) return "float" + std::to_string(8 * sizeof(T));
  else if constexpr (std::is_signed_v<T>) return "int" + std::to_string(8 * sizeof(T));
  else return "uint" + std::to_string(8 * sizeof(T));
}

std::string describe_type(hid_t type) {
  const std::size_t bits = 8 * H5Tget_size(type);
  switch (H5Tget_class(type)) {
    case H5T_FLOAT: return "float" + std::to_string(bits);
    case H5T_INTEGER:
      return (H5Tget_sign(type) == H5T_SGN_NONE ? "uint" : "int") + std::to_string(bits);
    case H5T_STRING: return "string";
    case H5T_COMPOUND: return "compound";
    case H5T_ARRAY: return "array";
    case H5T_ENUM: return "enum";
    case H5T_VLEN: return "variable-length";
    default: return "an unsupported type";
  }
}

template <class T>
bool type_matches(hid_t type) {
  const H5T_class_t cls = H5Tget_class(type);
  if (H5Tget_size(type) != sizeof(T)) return false;
  if constexpr (std::is_floating_point_v<T>) {
    return cls == H5T_FLOAT;
  } else {
    return cls == H5T_INTEGER && ((H5Tget_sign(type) != H5T_SGN_NONE) == std::is_signed_v<T>);
  }
}

std::uint64_t product(const Shape& s) {
  return std::accumulate(s.begin(), s.end(), std::uint64_t{1}, std::multiplies<>());
}

}  // namespace

// ------------------------------------------------------------------------------------------
namespace detail {
struct Node {
  hid_t id = -1;
  bool is_file = false;
  std::shared_ptr<Node> file;   ///< keeps the file open while a group is alive
  std::string file_name;
  std::string path;

  ~Node() {
    if (id < 0) return;
    Guard g;
    if (is_file) H5Fclose(id);
    else H5Gclose(id);
    H5Eclear2(H5E_DEFAULT);
  }

  [[noreturn]] void fail(const std::string& field, const std::string& message, bool detail = true) const {
    std::string what = message;
    if (detail) {
      const std::string d = hdf5_detail();
      if (!d.empty()) what += ": " + d;
    }
    throw Error(what, file_name, field);
  }
  void require_open(const std::string& field) const {
    if (id < 0) throw Error("HDF5 handle used after the file was closed", file_name, field);
  }
};
}  // namespace detail

using detail::Node;

namespace {

std::shared_ptr<Node> make_group_node(const Node& parent, hid_t id, const std::string& path) {
  auto n = std::make_shared<Node>();
  n->id = id;
  n->is_file = false;
  n->file = parent.file;   // group nodes always carry the file node
  n->file_name = parent.file_name;
  n->path = path;
  return n;
}

Id object_create_plist(hid_t cls) {
  Id p(H5Pcreate(cls));
  H5Pset_obj_track_times(p.get(), false);   // no timestamps: byte-identical output
  return p;
}

/// Open a dataset below `node`; throws naming the path when it is missing.
Id open_dataset(const Node& node, const std::string& name) {
  const std::string field = join(node.path, name);
  node.require_open(field);
  htri_t exists = H5Lexists(node.id, name.c_str(), H5P_DEFAULT);
  if (exists <= 0) {
    H5Eclear2(H5E_DEFAULT);
    // Name the first missing component for a clearer message.
    node.fail(field, "dataset is missing", false);
  }
  Id d(H5Dopen2(node.id, name.c_str(), H5P_DEFAULT));
  if (!d.valid()) node.fail(field, "cannot open the dataset (is it a group?)");
  return d;
}

Shape dataset_shape(const Node& node, hid_t dataset, const std::string& field) {
  Id space(H5Dget_space(dataset));
  if (!space.valid()) node.fail(field, "cannot read the dataset's dataspace");
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 0) node.fail(field, "cannot read the dataset's rank");
  std::vector<hsize_t> dims(static_cast<std::size_t>(rank));
  if (rank > 0) H5Sget_simple_extent_dims(space.get(), dims.data(), nullptr);
  return Shape(dims.begin(), dims.end());
}

void check_shape(const Node& node, const std::string& field, const Shape& actual,
                 const ShapeSpec& expected) {
  bool ok = actual.size() == expected.size();
  for (std::size_t i = 0; ok && i < actual.size(); ++i)
    ok = expected[i] == kAny || static_cast<std::uint64_t>(expected[i]) == actual[i];
  if (!ok)
    throw Error("dataset has shape " + to_string(actual) + ", expected " + to_string(expected),
                node.file_name, field);
}

template <class T>
void check_type(const Node& node, hid_t dataset, const std::string& field, const char* what) {
  Id type(H5Dget_type(dataset));
  if (!type.valid()) node.fail(field, "cannot read the dataset's type");
  if (!type_matches<T>(type.get()))
    throw Error(std::string(what) + " holds " + describe_type(type.get()) + " values, expected " +
                    type_name<T>(),
                node.file_name, field);
}

/// Split "a/b/c" into ("a/b", "c"); ("", "c") when there is no slash.
std::pair<std::string, std::string> split_parent(const std::string& name) {
  const auto pos = name.rfind('/');
  if (pos == std::string::npos) return {"", name};
  return {name.substr(0, pos), name.substr(pos + 1)};
}

Id string_type(std::size_t length) {
  Id t(H5Tcopy(H5T_C_S1));
  H5Tset_size(t.get(), std::max<std::size_t>(1, length));
  H5Tset_strpad(t.get(), H5T_STR_NULLPAD);
  H5Tset_cset(t.get(), H5T_CSET_UTF8);
  return t;
}

}  // namespace

// ------------------------------------------------------------------------------------------
Group::Group() = default;
Group::~Group() = default;
Group::Group(const Group&) = default;
Group& Group::operator=(const Group&) = default;
Group::Group(Group&&) noexcept = default;
Group& Group::operator=(Group&&) noexcept = default;
Group::Group(std::shared_ptr<detail::Node> node) : node_(std::move(node)) {}

const std::string& Group::file() const {
  static const std::string none;
  return node_ ? node_->file_name : none;
}
const std::string& Group::path() const {
  static const std::string none;
  return node_ ? node_->path : none;
}
std::string Group::child_path(const std::string& name) const { return join(path(), name); }

bool Group::has(const std::string& name) const {
  Guard g;
  if (!node_ || node_->id < 0) return false;
  // H5Lexists fails when an intermediate component is missing: test each prefix.
  std::size_t pos = 0;
  while (true) {
    const auto next = name.find('/', pos);
    const std::string prefix = name.substr(0, next);
    if (!prefix.empty()) {
      const htri_t e = H5Lexists(node_->id, prefix.c_str(), H5P_DEFAULT);
      if (e <= 0) {
        H5Eclear2(H5E_DEFAULT);
        return false;
      }
    }
    if (next == std::string::npos) return true;
    pos = next + 1;
  }
}

namespace {
H5I_type_t object_kind(const Node& node, const std::string& name) {
  Id obj(H5Oopen(node.id, name.c_str(), H5P_DEFAULT));
  if (!obj.valid()) {
    H5Eclear2(H5E_DEFAULT);
    return H5I_BADID;
  }
  return H5Iget_type(obj.get());
}
}  // namespace

bool Group::has_group(const std::string& name) const {
  Guard g;
  return has(name) && object_kind(*node_, name) == H5I_GROUP;
}

bool Group::has_dataset(const std::string& name) const {
  Guard g;
  return has(name) && object_kind(*node_, name) == H5I_DATASET;
}

Group Group::open_group(const std::string& name) const {
  Guard g;
  const std::string field = child_path(name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  node_->require_open(field);
  if (!has(name)) throw Error("group is missing", node_->file_name, field);
  hid_t id = H5Gopen2(node_->id, name.c_str(), H5P_DEFAULT);
  if (id < 0) node_->fail(field, "cannot open the group (is it a dataset?)");
  return Group(make_group_node(*node_, id, field));
}

Group Group::create_group(const std::string& name) {
  Guard g;
  const std::string field = child_path(name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  node_->require_open(field);
  if (has(name)) throw Error("group already exists", node_->file_name, field);
  const auto [parent, leaf] = split_parent(name);
  if (!parent.empty()) return require_group(parent).create_group(leaf);
  Id gcpl = object_create_plist(H5P_GROUP_CREATE);
  hid_t id = H5Gcreate2(node_->id, name.c_str(), H5P_DEFAULT, gcpl.get(), H5P_DEFAULT);
  if (id < 0) node_->fail(field, "cannot create the group");
  return Group(make_group_node(*node_, id, field));
}

Group Group::require_group(const std::string& name) {
  Guard g;
  return has(name) ? open_group(name) : create_group(name);
}

namespace {
herr_t collect_link(hid_t, const char* name, const H5L_info_t*, void* data) {
  static_cast<std::vector<std::string>*>(data)->emplace_back(name);
  return 0;
}
herr_t collect_attr(hid_t, const char* name, const H5A_info_t*, void* data) {
  static_cast<std::vector<std::string>*>(data)->emplace_back(name);
  return 0;
}
}  // namespace

std::vector<std::string> Group::children() const {
  Guard g;
  std::vector<std::string> names;
  if (!node_) return names;
  node_->require_open(path());
  hsize_t idx = 0;
  if (H5Literate(node_->id, H5_INDEX_NAME, H5_ITER_INC, &idx, collect_link, &names) < 0)
    node_->fail(path(), "cannot list the group");
  std::sort(names.begin(), names.end());
  return names;
}

void Group::remove(const std::string& name) {
  Guard g;
  const std::string field = child_path(name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  node_->require_open(field);
  if (!has(name)) throw Error("cannot remove a missing object", node_->file_name, field);
  if (H5Ldelete(node_->id, name.c_str(), H5P_DEFAULT) < 0) node_->fail(field, "cannot remove the object");
}

void Group::copy_from(const Group& source, const std::string& name) {
  Guard g;
  const std::string field = child_path(name);
  if (!node_ || !source.node_) throw Error("HDF5 group used before it was opened", "", field);
  node_->require_open(field);
  source.node_->require_open(source.child_path(name));
  if (!source.has(name)) throw Error("cannot copy a missing object", source.node_->file_name, source.child_path(name));
  if (has(name)) throw Error("object already exists", node_->file_name, field);
  if (H5Ocopy(source.node_->id, name.c_str(), node_->id, name.c_str(), H5P_DEFAULT, H5P_DEFAULT) < 0)
    node_->fail(field, "cannot copy " + source.node_->file_name + ":" + source.child_path(name));
}

// --- datasets --------------------------------------------------------------------------------
template <class T>
void Group::write(const std::string& name, const T* data, const Shape& shape, const Storage& storage) {
  Guard g;
  const std::string field = child_path(name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  node_->require_open(field);
  const auto [parent, leaf] = split_parent(name);
  if (!parent.empty()) {
    require_group(parent).write(leaf, data, shape, storage);
    return;
  }
  if (has(name)) throw Error("dataset already exists", node_->file_name, field);
  std::vector<hsize_t> dims(shape.begin(), shape.end());
  Id space(shape.empty() ? H5Screate(H5S_SCALAR)
                         : H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr));
  if (!space.valid()) node_->fail(field, "cannot create the dataspace " + to_string(shape));
  Id dcpl = object_create_plist(H5P_DATASET_CREATE);
  const std::uint64_t n = product(shape);
  if (storage.deflate > 0 && n > 0 && !shape.empty()) {
    const std::uint64_t row = n / shape[0];
    std::uint64_t rows = storage.chunk_rows;
    if (rows == 0) rows = std::max<std::uint64_t>(1, (256 * 1024) / (row * sizeof(T)));
    std::vector<hsize_t> chunk = dims;
    chunk[0] = std::min<hsize_t>(rows, dims[0]);
    H5Pset_chunk(dcpl.get(), static_cast<int>(chunk.size()), chunk.data());
    if (storage.shuffle) H5Pset_shuffle(dcpl.get());
    H5Pset_deflate(dcpl.get(), static_cast<unsigned>(std::min(storage.deflate, 9)));
  }
  Id ds(H5Dcreate2(node_->id, name.c_str(), TypeOf<T>::file(), space.get(), H5P_DEFAULT,
                   dcpl.get(), H5P_DEFAULT));
  if (!ds.valid()) node_->fail(field, "cannot create the dataset");
  if (n > 0 && H5Dwrite(ds.get(), TypeOf<T>::mem(), H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0)
    node_->fail(field, "cannot write the dataset");
}

void Group::write_strings(const std::string& name, const std::vector<std::string>& values) {
  Guard g;
  const std::string field = child_path(name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  node_->require_open(field);
  const auto [parent, leaf] = split_parent(name);
  if (!parent.empty()) {
    require_group(parent).write_strings(leaf, values);
    return;
  }
  if (has(name)) throw Error("dataset already exists", node_->file_name, field);
  std::size_t width = 1;
  for (const auto& v : values) width = std::max(width, v.size());
  std::vector<char> buffer(values.size() * width, '\0');
  for (std::size_t i = 0; i < values.size(); ++i)
    std::memcpy(buffer.data() + i * width, values[i].data(), values[i].size());
  Id type = string_type(width);
  hsize_t dims[1] = {values.size()};
  Id space(H5Screate_simple(1, dims, nullptr));
  Id dcpl = object_create_plist(H5P_DATASET_CREATE);
  Id ds(H5Dcreate2(node_->id, name.c_str(), type.get(), space.get(), H5P_DEFAULT, dcpl.get(),
                   H5P_DEFAULT));
  if (!ds.valid()) node_->fail(field, "cannot create the dataset");
  if (!values.empty() && H5Dwrite(ds.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, buffer.data()) < 0)
    node_->fail(field, "cannot write the dataset");
}

namespace {
/// The compressed chunks of a dataset, as stored, for inflate_chunks.
struct RawChunks {
  std::size_t element = 0;       ///< bytes of one value
  std::size_t row_bytes = 0;     ///< bytes of one row (dimension 0)
  std::size_t chunk_rows = 0;    ///< rows of one chunk
  std::size_t rows = 0;          ///< rows of the dataset
  bool shuffle = false;          ///< byte-shuffled before deflate
  std::vector<std::vector<unsigned char>> chunks;  ///< chunk k holds rows from k * chunk_rows
};

/// Reads the chunks of `ds` as stored (H5Dread_chunk) when its layout is the one this project
/// writes: chunked along dimension 0 only, filters [shuffle,] deflate, the file type equal to
/// `mem_type`, every chunk allocated and filtered, their sizes within the deflate bound and
/// within the storage the file declares. Returns false otherwise (nothing is trusted; H5Dread
/// then reads the dataset). Call under the lock.
bool read_raw_chunks(hid_t ds, hid_t mem_type, std::size_t element, const Shape& s, RawChunks& raw) {
  raw = RawChunks{};
  if (s.empty() || s[0] == 0) return false;
  Id dcpl(H5Dget_create_plist(ds));
  if (!dcpl.valid() || H5Pget_layout(dcpl.get()) != H5D_CHUNKED) return false;
  const int rank = static_cast<int>(s.size());
  std::vector<hsize_t> cdims(s.size());
  if (rank > 32 || H5Pget_chunk(dcpl.get(), rank, cdims.data()) != rank || cdims[0] == 0) return false;
  std::uint64_t row = element;
  for (std::size_t k = 1; k < s.size(); ++k) {
    if (cdims[k] != s[k]) return false;
    row *= s[k];
  }
  // Partial edge chunks stored unfiltered would not inflate: HDF5 reads those files.
  unsigned chunk_opts = 0;
  if (H5Pget_chunk_opts(dcpl.get(), &chunk_opts) < 0 || chunk_opts != 0) return false;
  const int nf = H5Pget_nfilters(dcpl.get());
  if (nf < 1 || nf > 2) return false;
  for (int i = 0; i < nf; ++i) {
    unsigned flags = 0, config = 0;
    std::size_t nelem = 8;
    unsigned cd[8] = {};
    char fname[64];
    const H5Z_filter_t f = H5Pget_filter2(dcpl.get(), static_cast<unsigned>(i), &flags, &nelem, cd, sizeof fname, fname, &config);
    if (f != (i + 1 == nf ? H5Z_FILTER_DEFLATE : H5Z_FILTER_SHUFFLE)) return false;
    if (f == H5Z_FILTER_SHUFFLE && (nelem < 1 || cd[0] != element)) return false;  // shuffled by another size
  }
  Id ftype(H5Dget_type(ds));
  if (!ftype.valid() || H5Tequal(ftype.get(), mem_type) <= 0) return false;
  constexpr std::uint64_t kMaxChunk = std::uint64_t{64} << 20, kMaxChunks = std::uint64_t{1} << 20;
  const std::uint64_t chunk_rows = cdims[0];
  if (row > kMaxChunk || chunk_rows > kMaxChunk / row) return false;
  const std::uint64_t chunk_bytes = chunk_rows * row;
  const std::uint64_t n = (s[0] + chunk_rows - 1) / chunk_rows;
  if (n > kMaxChunks) return false;
  const std::uint64_t bound = chunk_bytes + chunk_bytes / 1000 + 64;  // zlib's worst expansion
  const std::uint64_t stored = H5Dget_storage_size(ds);
  std::uint64_t total = 0;
  raw.chunks.resize(n);
  std::vector<hsize_t> offset(s.size(), 0);
  for (std::uint64_t k = 0; k < n; ++k) {
    offset[0] = k * chunk_rows;
    hsize_t bytes = 0;
    if (H5Dget_chunk_storage_size(ds, offset.data(), &bytes) < 0 || bytes == 0 || bytes > bound ||
        (total += bytes) > stored) {
      raw.chunks.clear();
      return false;
    }
    raw.chunks[k].resize(bytes);
    std::uint32_t skipped = 0;
    if (H5Dread_chunk(ds, H5P_DEFAULT, offset.data(), &skipped, raw.chunks[k].data()) < 0 || skipped != 0) {
      raw.chunks.clear();
      return false;
    }
  }
  raw.element = element;
  raw.row_bytes = row;
  raw.chunk_rows = chunk_rows;
  raw.rows = s[0];
  raw.shuffle = nf == 2;
  return true;
}

/// HDF5's shuffle filter undone: byte j of value i is stored at j * count + i.
template <std::size_t E>
void unshuffle_fixed(const unsigned char* __restrict a, unsigned char* __restrict b, std::size_t count) {
  for (std::size_t i = 0; i < count; ++i)
    for (std::size_t j = 0; j < E; ++j) b[i * E + j] = a[j * count + i];
}

void unshuffle(const unsigned char* a, unsigned char* b, std::size_t bytes, std::size_t element) {
  const std::size_t count = bytes / element;
  switch (element) {
    case 2: unshuffle_fixed<2>(a, b, count); break;
    case 4: unshuffle_fixed<4>(a, b, count); break;
    case 8: unshuffle_fixed<8>(a, b, count); break;
    default:
      for (std::size_t j = 0; j < element; ++j)
        for (std::size_t i = 0; i < count; ++i) b[i * element + j] = a[j * count + i];
  }
  std::memcpy(b + count * element, a + count * element, bytes - count * element);  // as HDF5: the rest as is
}

/// Inflates (libdeflate) and unshuffles the chunks of `raw` into `out` (`bytes` = rows x
/// row_bytes), in parallel over chunks; needs no lock. Returns -1, or the first chunk that is
/// not a zlib stream of exactly one chunk's bytes.
std::int64_t inflate_chunks(const RawChunks& raw, unsigned char* out, std::size_t bytes) {
  if (bytes != raw.rows * raw.row_bytes) throw Error("inflate_chunks: output size mismatch");
  const std::size_t chunk_bytes = raw.chunk_rows * raw.row_bytes;
  std::vector<std::uint8_t> failed(raw.chunks.size(), 0);
  // Isolated: a caller may hold the HDF5 lock, and a thread waiting here must not pick up an
  // unrelated task that could wait for that lock.
  tbb::this_task_arena::isolate([&] {
    tbb::parallel_for(std::size_t{0}, raw.chunks.size(), [&](std::size_t k) {
      struct Freer {
        void operator()(libdeflate_decompressor* d) const { libdeflate_free_decompressor(d); }
      };
      thread_local std::unique_ptr<libdeflate_decompressor, Freer> d;
      thread_local std::vector<unsigned char> a, b;
      if (!d) d.reset(libdeflate_alloc_decompressor());
      if (!d) throw std::bad_alloc();
      a.resize(chunk_bytes);
      std::size_t got = 0;
      if (libdeflate_zlib_decompress(d.get(), raw.chunks[k].data(), raw.chunks[k].size(), a.data(), chunk_bytes, &got) !=
              LIBDEFLATE_SUCCESS ||
          got != chunk_bytes) {
        failed[k] = 1;
        return;
      }
      const unsigned char* src = a.data();
      if (raw.shuffle && raw.element > 1) {
        b.resize(chunk_bytes);
        unshuffle(a.data(), b.data(), chunk_bytes, raw.element);
        src = b.data();
      }
      const std::size_t first = k * raw.chunk_rows;
      const std::size_t rows = std::min(raw.chunk_rows, raw.rows - first);
      std::memcpy(out + first * raw.row_bytes, src, rows * raw.row_bytes);
      constexpr std::size_t kKeep = std::size_t{4} << 20;  // a crafted huge chunk is not kept
      if (a.capacity() > kKeep) std::vector<unsigned char>().swap(a);
      if (b.capacity() > kKeep) std::vector<unsigned char>().swap(b);
    });
  });
  const auto bad = std::find(failed.begin(), failed.end(), 1);
  return bad == failed.end() ? -1 : static_cast<std::int64_t>(bad - failed.begin());
}

/// Never trust a size read from a file: the declared shape must not overflow, and the values it
/// declares must be backed by the bytes the file stores for them (zlib cannot compress better
/// than about 1 000:1; the writers here never leave chunks unallocated). Checked before any
/// allocation, so a crafted few-KB file cannot ask for gigabytes.
void check_declared_size(const Node& node, hid_t ds, const std::string& field, const Shape& s, std::size_t value_size) {
  std::uint64_t n = 1;
  for (std::uint64_t d : s)
    if (__builtin_mul_overflow(n, d, &n)) throw Error("dataset shape overflows", node.file_name, field);
  std::uint64_t bytes = 0;
  if (__builtin_mul_overflow(n, std::uint64_t{value_size}, &bytes))
    throw Error("dataset shape overflows", node.file_name, field);
  const std::uint64_t stored = H5Dget_storage_size(ds);
  constexpr std::uint64_t kMaxRatio = 1100, kSlack = std::uint64_t{1} << 20;
  if (bytes > kSlack && (bytes - kSlack) / kMaxRatio > stored)
    throw Error("dataset declares " + std::to_string(n) + " values (" + std::to_string(bytes) +
                    " bytes) but the file stores only " + std::to_string(stored) + " bytes for them",
                node.file_name, field);
}
}  // namespace

Shape Group::shape(const std::string& name) const {
  Guard g;
  if (!node_) throw Error("HDF5 group used before it was opened", "", name);
  Id ds = open_dataset(*node_, name);
  return dataset_shape(*node_, ds.get(), child_path(name));
}


template <class T>
std::vector<T> Group::read(const std::string& name, const ShapeSpec& expected, Shape* actual) const {
  const std::string field = child_path(name);
  std::vector<T> out;
  Shape s;
  RawChunks raw;
  {
    Guard g;
    if (!node_) throw Error("HDF5 group used before it was opened", "", field);
    Id ds = open_dataset(*node_, name);
    check_type<T>(*node_, ds.get(), field, "dataset");
    s = dataset_shape(*node_, ds.get(), field);
    check_shape(*node_, field, s, expected);
    check_declared_size(*node_, ds.get(), field, s, sizeof(T));
    out.resize(product(s));
    // Deflated chunks are read as stored and inflated below, outside the lock, so that threads
    // loading objects inflate in parallel; any other layout is read by HDF5 itself.
    if (!out.empty() && !read_raw_chunks(ds.get(), TypeOf<T>::mem(), sizeof(T), s, raw) &&
        H5Dread(ds.get(), TypeOf<T>::mem(), H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()) < 0)
      node_->fail(field, "cannot read the dataset");
  }
  if (!raw.chunks.empty()) {
    const std::int64_t bad = inflate_chunks(raw, reinterpret_cast<unsigned char*>(out.data()), out.size() * sizeof(T));
    if (bad >= 0)  // (libhdf5 itself would return whatever a short stream gives, unnoticed)
      node_->fail(field, "cannot read the dataset: its chunk at row " + std::to_string(bad * raw.chunk_rows) +
                             " is not a deflate stream of the chunk's " + std::to_string(raw.chunk_rows * raw.row_bytes) +
                             " bytes (damaged data)",
                  false);
  }
  if (actual) *actual = s;
  return out;
}

template <class T>
std::vector<T> Group::read_rows(const std::string& name, std::uint64_t first, std::uint64_t count,
                                const ShapeSpec& expected) const {
  Guard g;
  const std::string field = child_path(name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  Id ds = open_dataset(*node_, name);
  check_type<T>(*node_, ds.get(), field, "dataset");
  const Shape s = dataset_shape(*node_, ds.get(), field);
  check_shape(*node_, field, s, expected);
  check_declared_size(*node_, ds.get(), field, s, sizeof(T));
  if (s.empty()) throw Error("dataset is a scalar, expected rows", node_->file_name, field);
  if (first > s[0] || count > s[0] - first)
    throw Error("rows [" + std::to_string(first) + "," + std::to_string(first + count) +
                    ") are out of range; the dataset has " + std::to_string(s[0]) + " rows",
                node_->file_name, field);
  Shape sel = s;
  sel[0] = count;
  std::vector<T> out(product(sel));
  if (out.empty()) return out;
  std::vector<hsize_t> start(s.size(), 0), cnt(sel.begin(), sel.end());
  start[0] = first;
  Id fspace(H5Dget_space(ds.get()));
  H5Sselect_hyperslab(fspace.get(), H5S_SELECT_SET, start.data(), nullptr, cnt.data(), nullptr);
  Id mspace(H5Screate_simple(static_cast<int>(cnt.size()), cnt.data(), nullptr));
  if (H5Dread(ds.get(), TypeOf<T>::mem(), mspace.get(), fspace.get(), H5P_DEFAULT, out.data()) < 0)
    node_->fail(field, "cannot read the dataset");
  return out;
}

std::vector<std::string> Group::read_strings(const std::string& name) const {
  Guard g;
  const std::string field = child_path(name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  Id ds = open_dataset(*node_, name);
  Id type(H5Dget_type(ds.get()));
  if (H5Tget_class(type.get()) != H5T_STRING)
    throw Error("dataset holds " + describe_type(type.get()) + " values, expected strings",
                node_->file_name, field);
  const Shape s = dataset_shape(*node_, ds.get(), field);
  check_shape(*node_, field, s, {kAny});
  const bool variable = H5Tis_variable_str(type.get()) > 0;
  check_declared_size(*node_, ds.get(), field, s, variable ? sizeof(char*) : H5Tget_size(type.get()));
  std::vector<std::string> out(s[0]);
  if (out.empty()) return out;
  if (variable) {
    Id mtype(H5Tcopy(H5T_C_S1));
    H5Tset_size(mtype.get(), H5T_VARIABLE);
    H5Tset_cset(mtype.get(), H5Tget_cset(type.get()));  // h5py writes UTF-8, others ASCII
    std::vector<char*> ptrs(out.size(), nullptr);
    if (H5Dread(ds.get(), mtype.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, ptrs.data()) < 0)
      node_->fail(field, "cannot read the dataset");
    for (std::size_t i = 0; i < out.size(); ++i) out[i] = ptrs[i] ? ptrs[i] : "";
    Id space(H5Dget_space(ds.get()));
    H5Dvlen_reclaim(mtype.get(), space.get(), H5P_DEFAULT, ptrs.data());
  } else {
    const std::size_t width = H5Tget_size(type.get());
    Id mtype = string_type(width);
    H5Tset_cset(mtype.get(), H5Tget_cset(type.get()));
    std::vector<char> buffer(out.size() * width);
    if (H5Dread(ds.get(), mtype.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, buffer.data()) < 0)
      node_->fail(field, "cannot read the dataset");
    for (std::size_t i = 0; i < out.size(); ++i) {
      const char* p = buffer.data() + i * width;
      out[i].assign(p, strnlen(p, width));
    }
  }
  return out;
}

template <class T>
void Group::create_extendible(const std::string& name, const Shape& row_shape, const Storage& storage) {
  Guard g;
  const std::string field = child_path(name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  node_->require_open(field);
  const auto [parent, leaf] = split_parent(name);
  if (!parent.empty()) {
    require_group(parent).create_extendible<T>(leaf, row_shape, storage);
    return;
  }
  if (has(name)) throw Error("dataset already exists", node_->file_name, field);
  std::vector<hsize_t> dims{0}, maxdims{H5S_UNLIMITED};
  for (auto d : row_shape) {
    if (d == 0) throw Error("extendible dataset rows must not be empty", node_->file_name, field);
    dims.push_back(d);
    maxdims.push_back(d);
  }
  const std::uint64_t row = product(row_shape);
  std::vector<hsize_t> chunk = dims;
  chunk[0] = storage.chunk_rows ? storage.chunk_rows
                                : std::max<std::uint64_t>(1, (64 * 1024) / (row * sizeof(T)));
  Id space(H5Screate_simple(static_cast<int>(dims.size()), dims.data(), maxdims.data()));
  Id dcpl = object_create_plist(H5P_DATASET_CREATE);
  H5Pset_chunk(dcpl.get(), static_cast<int>(chunk.size()), chunk.data());
  if (storage.deflate > 0) {
    if (storage.shuffle) H5Pset_shuffle(dcpl.get());
    H5Pset_deflate(dcpl.get(), static_cast<unsigned>(std::min(storage.deflate, 9)));
  }
  Id ds(H5Dcreate2(node_->id, name.c_str(), TypeOf<T>::file(), space.get(), H5P_DEFAULT,
                   dcpl.get(), H5P_DEFAULT));
  if (!ds.valid()) node_->fail(field, "cannot create the extendible dataset");
}

template <class T>
void Group::append(const std::string& name, const T* data, std::uint64_t rows) {
  Guard g;
  const std::string field = child_path(name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  Id ds = open_dataset(*node_, name);
  check_type<T>(*node_, ds.get(), field, "dataset");
  Shape s = dataset_shape(*node_, ds.get(), field);
  if (s.empty()) throw Error("cannot append to a scalar dataset", node_->file_name, field);
  if (rows == 0) return;
  std::vector<hsize_t> start(s.size(), 0), count(s.begin(), s.end());
  start[0] = s[0];
  count[0] = rows;
  s[0] += rows;
  std::vector<hsize_t> dims(s.begin(), s.end());
  if (H5Dset_extent(ds.get(), dims.data()) < 0)
    node_->fail(field, "cannot extend the dataset (is it extendible?)");
  Id fspace(H5Dget_space(ds.get()));
  H5Sselect_hyperslab(fspace.get(), H5S_SELECT_SET, start.data(), nullptr, count.data(), nullptr);
  Id mspace(H5Screate_simple(static_cast<int>(count.size()), count.data(), nullptr));
  if (H5Dwrite(ds.get(), TypeOf<T>::mem(), mspace.get(), fspace.get(), H5P_DEFAULT, data) < 0)
    node_->fail(field, "cannot append to the dataset");
}

// --- attributes ------------------------------------------------------------------------------
bool Group::has_attribute(const std::string& name) const {
  Guard g;
  if (!node_ || node_->id < 0) return false;
  const htri_t e = H5Aexists(node_->id, name.c_str());
  if (e < 0) H5Eclear2(H5E_DEFAULT);
  return e > 0;
}

namespace {
std::string attr_field(const Group& g, const std::string& name) { return g.path() + "@" + name; }

void write_attribute(const Node& node, const std::string& field, const std::string& name,
                     hid_t file_type, hid_t mem_type, hid_t space, const void* data) {
  if (H5Aexists(node.id, name.c_str()) > 0) H5Adelete(node.id, name.c_str());
  H5Eclear2(H5E_DEFAULT);
  Id a(H5Acreate2(node.id, name.c_str(), file_type, space, H5P_DEFAULT, H5P_DEFAULT));
  if (!a.valid()) node.fail(field, "cannot create the attribute");
  if (H5Awrite(a.get(), mem_type, data) < 0) node.fail(field, "cannot write the attribute");
}

Id open_attribute(const Node& node, const std::string& field, const std::string& name) {
  node.require_open(field);
  if (H5Aexists(node.id, name.c_str()) <= 0) {
    H5Eclear2(H5E_DEFAULT);
    throw Error("attribute is missing", node.file_name, field);
  }
  Id a(H5Aopen(node.id, name.c_str(), H5P_DEFAULT));
  if (!a.valid()) node.fail(field, "cannot open the attribute");
  return a;
}

/// Number of elements of an attribute (1 for a scalar).
hssize_t attribute_elements(const Node& node, hid_t attr, const std::string& field) {
  Id space(H5Aget_space(attr));
  const hssize_t n = H5Sget_simple_extent_npoints(space.get());
  if (n < 0) node.fail(field, "cannot read the attribute's dataspace");
  return n;
}

template <class T>
T scalar_attribute(const Node& node, const std::string& field, const std::string& name,
                   H5T_class_t cls, const char* expected) {
  Id a = open_attribute(node, field, name);
  Id type(H5Aget_type(a.get()));
  if (H5Tget_class(type.get()) != cls)
    throw Error("attribute holds " + describe_type(type.get()) + ", expected " + expected,
                node.file_name, field);
  if (attribute_elements(node, a.get(), field) != 1)
    throw Error("attribute holds several values, expected one", node.file_name, field);
  T value{};
  if (H5Aread(a.get(), TypeOf<T>::mem(), &value) < 0) node.fail(field, "cannot read the attribute");
  return value;
}
}  // namespace

void Group::set_attribute(const std::string& name, const std::string& value) {
  Guard g;
  const std::string field = attr_field(*this, name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  node_->require_open(field);
  Id type = string_type(value.size());
  Id space(H5Screate(H5S_SCALAR));
  std::vector<char> buffer(std::max<std::size_t>(1, value.size()), '\0');
  std::memcpy(buffer.data(), value.data(), value.size());
  write_attribute(*node_, field, name, type.get(), type.get(), space.get(), buffer.data());
}

void Group::set_attribute(const std::string& name, std::int64_t value) {
  Guard g;
  const std::string field = attr_field(*this, name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  node_->require_open(field);
  Id space(H5Screate(H5S_SCALAR));
  write_attribute(*node_, field, name, H5T_STD_I64LE, H5T_NATIVE_INT64, space.get(), &value);
}

void Group::set_attribute(const std::string& name, double value) {
  Guard g;
  const std::string field = attr_field(*this, name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  node_->require_open(field);
  Id space(H5Screate(H5S_SCALAR));
  write_attribute(*node_, field, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, space.get(), &value);
}

void Group::set_attribute(const std::string& name, const std::vector<double>& values) {
  Guard g;
  const std::string field = attr_field(*this, name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  node_->require_open(field);
  hsize_t dims[1] = {values.size()};
  Id space(H5Screate_simple(1, dims, nullptr));
  write_attribute(*node_, field, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, space.get(),
                  values.empty() ? nullptr : values.data());
}

std::string Group::string_attribute(const std::string& name) const {
  Guard g;
  const std::string field = attr_field(*this, name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  Id a = open_attribute(*node_, field, name);
  Id type(H5Aget_type(a.get()));
  if (H5Tget_class(type.get()) != H5T_STRING)
    throw Error("attribute holds " + describe_type(type.get()) + ", expected a string",
                node_->file_name, field);
  if (attribute_elements(*node_, a.get(), field) != 1)
    throw Error("attribute holds several strings, expected one", node_->file_name, field);
  if (H5Tis_variable_str(type.get()) > 0) {
    Id mtype(H5Tcopy(H5T_C_S1));
    H5Tset_size(mtype.get(), H5T_VARIABLE);
    H5Tset_cset(mtype.get(), H5Tget_cset(type.get()));  // h5py writes UTF-8, others ASCII
    char* p = nullptr;
    if (H5Aread(a.get(), mtype.get(), &p) < 0) node_->fail(field, "cannot read the attribute");
    std::string out = p ? p : "";
    Id space(H5Aget_space(a.get()));
    H5Dvlen_reclaim(mtype.get(), space.get(), H5P_DEFAULT, &p);
    return out;
  }
  const std::size_t width = H5Tget_size(type.get());
  Id mtype = string_type(width);
  H5Tset_cset(mtype.get(), H5Tget_cset(type.get()));
  std::vector<char> buffer(width);
  if (H5Aread(a.get(), mtype.get(), buffer.data()) < 0) node_->fail(field, "cannot read the attribute");
  return std::string(buffer.data(), strnlen(buffer.data(), width));
}

std::int64_t Group::int_attribute(const std::string& name) const {
  Guard g;
  const std::string field = attr_field(*this, name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  return scalar_attribute<std::int64_t>(*node_, field, name, H5T_INTEGER, "an integer");
}

double Group::double_attribute(const std::string& name) const {
  Guard g;
  const std::string field = attr_field(*this, name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  return scalar_attribute<double>(*node_, field, name, H5T_FLOAT, "a number");
}

std::vector<double> Group::doubles_attribute(const std::string& name, std::int64_t expected_size) const {
  Guard g;
  const std::string field = attr_field(*this, name);
  if (!node_) throw Error("HDF5 group used before it was opened", "", field);
  Id a = open_attribute(*node_, field, name);
  Id type(H5Aget_type(a.get()));
  if (H5Tget_class(type.get()) != H5T_FLOAT)
    throw Error("attribute holds " + describe_type(type.get()) + ", expected numbers",
                node_->file_name, field);
  const hssize_t n = attribute_elements(*node_, a.get(), field);
  if (expected_size != kAny && n != expected_size)
    throw Error("attribute holds " + std::to_string(n) + " values, expected " +
                    std::to_string(expected_size),
                node_->file_name, field);
  std::vector<double> out(static_cast<std::size_t>(n));
  if (n > 0 && H5Aread(a.get(), H5T_NATIVE_DOUBLE, out.data()) < 0)
    node_->fail(field, "cannot read the attribute");
  return out;
}

std::vector<std::string> Group::attributes() const {
  Guard g;
  std::vector<std::string> names;
  if (!node_) return names;
  node_->require_open(path());
  hsize_t idx = 0;
  if (H5Aiterate2(node_->id, H5_INDEX_NAME, H5_ITER_INC, &idx, collect_attr, &names) < 0)
    node_->fail(path(), "cannot list the attributes");
  std::sort(names.begin(), names.end());
  return names;
}

// --- files -----------------------------------------------------------------------------------
File::File() = default;
File::~File() = default;
File::File(File&&) noexcept = default;
File& File::operator=(File&&) noexcept = default;

namespace {
/// A file read only keeps at most this much metadata cached (HDF5's default: 32 MB). Each object
/// a reader loads leaves its datasets' headers and chunk indexes in the metadata cache, whose
/// resident memory is several times its nominal size: on a database of thousands of objects the
/// default held a few hundred MB more once every object's features were loaded (bench_recognize's
/// memory line after the feature search), for no faster loads (the objects are read one after
/// another; their metadata is not wanted again soon).
constexpr std::size_t kReadMetadataCacheBytes = std::size_t{4} << 20;

Id file_access_plist(bool read_only) {
  Id fapl(H5Pcreate(H5P_FILE_ACCESS));
  // Closing the file closes every object still open in it, so close() really releases it.
  H5Pset_fclose_degree(fapl.get(), H5F_CLOSE_STRONG);
  if (read_only) {
    H5AC_cache_config_t c{};
    c.version = H5AC__CURR_CACHE_CONFIG_VERSION;
    if (H5Pget_mdc_config(fapl.get(), &c) >= 0 && c.max_size > kReadMetadataCacheBytes) {
      c.max_size = kReadMetadataCacheBytes;
      c.min_size = std::min(c.min_size, c.max_size);
      c.set_initial_size = true;
      c.initial_size = std::min(c.initial_size, c.max_size);
      H5Pset_mdc_config(fapl.get(), &c);
    }
  }
  return fapl;
}

std::shared_ptr<Node> make_file_node(hid_t id, const std::string& name) {
  auto n = std::make_shared<Node>();
  n->id = id;
  n->is_file = true;
  n->file_name = name;
  n->path = "/";
  return n;
}
}  // namespace

File File::create(const std::filesystem::path& path, const std::string& display) {
  Guard g;
  const std::string name = display.empty() ? path.string() : display;
  Id fcpl(H5Pcreate(H5P_FILE_CREATE));
  H5Pset_obj_track_times(fcpl.get(), false);   // the root group has no timestamps either
  Id fapl = file_access_plist(false);
  hid_t id = H5Fcreate(path.c_str(), H5F_ACC_TRUNC, fcpl.get(), fapl.get());
  if (id < 0) {
    const std::string d = hdf5_detail();
    throw Error("cannot create the HDF5 file" + (d.empty() ? "" : ": " + d), name);
  }
  File f;
  f.node_ = make_file_node(id, name);
  return f;
}

File File::create(const AtomicOutput& output) {
  return create(output.temp_path(), output.target().string());
}

File File::open(const std::filesystem::path& path, Access access, const std::string& display) {
  Guard g;
  const std::string name = display.empty() ? path.string() : display;
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw Error("file does not exist", name);
  if (!std::filesystem::is_regular_file(path, ec)) throw Error("not a regular file", name);
  const htri_t is_hdf5 = H5Fis_hdf5(path.c_str());
  if (is_hdf5 < 0) {
    const std::string d = hdf5_detail();
    throw Error("cannot read the file" + (d.empty() ? "" : ": " + d), name);
  }
  if (is_hdf5 == 0) throw Error("not an HDF5 file", name);
  Id fapl = file_access_plist(access == Access::read);
  hid_t id = H5Fopen(path.c_str(), access == Access::read ? H5F_ACC_RDONLY : H5F_ACC_RDWR, fapl.get());
  if (id < 0) {
    const std::string d = hdf5_detail();
    throw Error(d.empty() ? std::string("cannot open the HDF5 file (corrupt?)") : "cannot open the HDF5 file: " + d, name);
  }
  File f;
  f.node_ = make_file_node(id, name);
  return f;
}

bool is_lock_contention(const Error& e) {
  std::string what = e.what();
  std::transform(what.begin(), what.end(), what.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return what.find("unable to lock") != std::string::npos;
}

bool File::is_open() const { return node_ && node_->id >= 0; }

const std::string& File::name() const {
  static const std::string none;
  return node_ ? node_->file_name : none;
}

Group File::root() const {
  Guard g;
  if (!is_open()) throw Error("HDF5 file is not open", name());
  hid_t id = H5Gopen2(node_->id, "/", H5P_DEFAULT);
  if (id < 0) node_->fail("/", "cannot open the root group");
  auto n = std::make_shared<Node>();
  n->id = id;
  n->file = node_;
  n->file_name = node_->file_name;
  n->path = "/";
  return Group(n);
}

void File::close() {
  Guard g;
  if (!is_open()) return;
  const hid_t id = node_->id;
  node_->id = -1;
  if (H5Fclose(id) < 0) node_->fail("", "cannot close the HDF5 file");
  node_.reset();
}

// --- explicit instantiations -----------------------------------------------------------------
#define TS_H5_INSTANTIATE(T)                                                                       \
  template void Group::write<T>(const std::string&, const T*, const Shape&, const Storage&);       \
  template std::vector<T> Group::read<T>(const std::string&, const ShapeSpec&, Shape*) const;      \
  template std::vector<T> Group::read_rows<T>(const std::string&, std::uint64_t, std::uint64_t,    \
                                              const ShapeSpec&) const;                             \
  template void Group::create_extendible<T>(const std::string&, const Shape&, const Storage&);     \
  template void Group::append<T>(const std::string&, const T*, std::uint64_t);

TS_H5_INSTANTIATE(double)
TS_H5_INSTANTIATE(float)
TS_H5_INSTANTIATE(std::int16_t)
TS_H5_INSTANTIATE(std::int32_t)
TS_H5_INSTANTIATE(std::int64_t)
TS_H5_INSTANTIATE(std::uint8_t)
TS_H5_INSTANTIATE(std::uint32_t)
TS_H5_INSTANTIATE(std::uint64_t)
#undef TS_H5_INSTANTIATE

}  // namespace ts::io::h5
