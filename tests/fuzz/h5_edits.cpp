#include "fuzz/h5_edits.hpp"

#include <hdf5.h>

#include <algorithm>
#include <stdexcept>
#include <cstring>
#include <string>
#include <vector>

namespace ts::fuzz {
namespace {

/// One editable object: a dataset (attr empty) or an attribute of the object at `path`.
struct Item {
  std::string path;
  std::string attr;
};

struct Collect {
  hid_t file;
  std::vector<Item>* items;
};

herr_t add_attribute(hid_t, const char* name, const H5A_info_t*, void* data) {
  auto* c = static_cast<std::pair<std::string, std::vector<Item>*>*>(data);
  c->second->push_back({c->first, name});
  return 0;
}

void add_attributes_of(hid_t file, const std::string& path, std::vector<Item>& items) {
  hid_t obj = H5Oopen(file, path.c_str(), H5P_DEFAULT);
  if (obj < 0) return;
  std::pair<std::string, std::vector<Item>*> c{path, &items};
  hsize_t at = 0;
  H5Aiterate2(obj, H5_INDEX_NAME, H5_ITER_INC, &at, add_attribute, &c);
  H5Oclose(obj);
}

herr_t visit(hid_t, const char* name, const H5O_info_t* info, void* data) {
  auto* c = static_cast<Collect*>(data);
  const std::string path = std::string("/") + (std::strcmp(name, ".") == 0 ? "" : name);
  if (info->type == H5O_TYPE_DATASET) c->items->push_back({path, ""});
  add_attributes_of(c->file, path, *c->items);
  return 0;
}

std::uint64_t u64(const std::uint8_t* p, int n) {
  std::uint64_t v = 0;
  for (int i = n - 1; i >= 0; --i) v = (v << 8) | p[i];
  return v;
}

/// A dataspace's dimensions (empty for a scalar).
std::vector<hsize_t> dims_of(hid_t space) {
  const int rank = H5Sget_simple_extent_ndims(space);
  std::vector<hsize_t> d(static_cast<std::size_t>(std::max(rank, 0)));
  if (rank > 0) H5Sget_simple_extent_dims(space, d.data(), nullptr);
  return d;
}

hsize_t count_of(const std::vector<hsize_t>& d) {
  hsize_t n = 1;
  for (hsize_t x : d) n *= x;
  return n;
}

/// Op 0 on a dataset: overwrite element `index` with `raw` (as int64 or double; HDF5 converts
/// to the stored type, clamping). Strings are left alone (op 3 replaces them).
void set_element(hid_t file, const Item& it, std::uint64_t index, const std::uint8_t* raw, bool as_double) {
  hid_t mem = as_double ? H5T_NATIVE_DOUBLE : H5T_NATIVE_INT64;
  if (it.attr.empty()) {
    hid_t ds = H5Dopen2(file, it.path.c_str(), H5P_DEFAULT);
    if (ds < 0) return;
    hid_t type = H5Dget_type(ds);
    hid_t space = H5Dget_space(ds);
    const auto d = dims_of(space);
    const hsize_t n = count_of(d);
    if (H5Tget_class(type) != H5T_STRING && n > 0) {
      std::vector<hsize_t> at(d.size());
      std::uint64_t k = index % n;
      for (std::size_t a = d.size(); a-- > 0;) {
        at[a] = k % d[a];
        k /= d[a];
      }
      if (!d.empty()) H5Sselect_elements(space, H5S_SELECT_SET, 1, at.data());
      hsize_t one = 1;
      hid_t mspace = H5Screate_simple(1, &one, nullptr);
      H5Dwrite(ds, mem, mspace, d.empty() ? H5S_ALL : space, H5P_DEFAULT, raw);
      H5Sclose(mspace);
    }
    H5Sclose(space);
    H5Tclose(type);
    H5Dclose(ds);
    return;
  }
  hid_t a = H5Aopen_by_name(file, it.path.c_str(), it.attr.c_str(), H5P_DEFAULT, H5P_DEFAULT);
  if (a < 0) return;
  hid_t type = H5Aget_type(a);
  hid_t space = H5Aget_space(a);
  const hsize_t n = count_of(dims_of(space));
  if (H5Tget_class(type) != H5T_STRING && n > 0 && n <= (1u << 20)) {
    std::vector<std::uint8_t> all(n * 8);
    if (H5Aread(a, mem, all.data()) >= 0) {
      std::memcpy(all.data() + (index % n) * 8, raw, 8);
      H5Awrite(a, mem, all.data());
    }
  }
  H5Sclose(space);
  H5Tclose(type);
  H5Aclose(a);
}

/// Replace the object by a new one of `type` and dims `d` holding fill values (a chunked
/// dataset: nothing is written, so the file stays small however large the declared extent).
void recreate(hid_t file, const Item& it, hid_t type, const std::vector<hsize_t>& d) {
  // Datasets get unlimited maximum extents, so that any chunk shape is allowed (even for 0).
  const std::vector<hsize_t> unlimited(d.size(), H5S_UNLIMITED);
  hid_t space = d.empty() ? H5Screate(H5S_SCALAR)
                          : H5Screate_simple(static_cast<int>(d.size()), d.data(),
                                             it.attr.empty() ? unlimited.data() : nullptr);
  if (it.attr.empty()) {
    H5Ldelete(file, it.path.c_str(), H5P_DEFAULT);
    hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
    if (!d.empty()) {
      std::vector<hsize_t> chunk(d.size());
      for (std::size_t a = 0; a < d.size(); ++a) chunk[a] = std::clamp<hsize_t>(d[a], 1, 64);
      H5Pset_chunk(dcpl, static_cast<int>(chunk.size()), chunk.data());
    }
    hid_t lcpl = H5Pcreate(H5P_LINK_CREATE);
    H5Pset_create_intermediate_group(lcpl, 1);
    hid_t ds = H5Dcreate2(file, it.path.c_str(), type, space, lcpl, dcpl, H5P_DEFAULT);
    if (ds >= 0) H5Dclose(ds);
    H5Pclose(lcpl);
    H5Pclose(dcpl);
  } else if (count_of(d) <= (1u << 16)) {   // attributes live in the object header: kept small
    H5Adelete_by_name(file, it.path.c_str(), it.attr.c_str(), H5P_DEFAULT);
    hid_t a = H5Acreate_by_name(file, it.path.c_str(), it.attr.c_str(), type, space, H5P_DEFAULT, H5P_DEFAULT,
                                H5P_DEFAULT);
    if (a >= 0) H5Aclose(a);
  }
  H5Sclose(space);
}

/// The object's type and dims (false if it cannot be opened).
bool shape_of(hid_t file, const Item& it, hid_t& type, std::vector<hsize_t>& d) {
  hid_t obj = it.attr.empty() ? H5Dopen2(file, it.path.c_str(), H5P_DEFAULT)
                              : H5Aopen_by_name(file, it.path.c_str(), it.attr.c_str(), H5P_DEFAULT, H5P_DEFAULT);
  if (obj < 0) return false;
  hid_t space = it.attr.empty() ? H5Dget_space(obj) : H5Aget_space(obj);
  type = it.attr.empty() ? H5Dget_type(obj) : H5Aget_type(obj);
  d = dims_of(space);
  H5Sclose(space);
  if (it.attr.empty()) H5Dclose(obj);
  else H5Aclose(obj);
  return true;
}

}  // namespace

void apply_h5_edits(const std::filesystem::path& base, const std::filesystem::path& out,
                    std::span<const std::uint8_t> script) {
  std::filesystem::copy_file(base, out, std::filesystem::copy_options::overwrite_existing);
  if (script.size() < 16) return;
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  hid_t file = H5Fopen(out.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
  if (file < 0) return;
  for (std::size_t r = 0; r + 16 <= script.size() && r < 8 * 16; r += 16) {
    const std::uint8_t* rec = script.data() + r;
    std::vector<Item> items;   // again after each edit: deletions and retypes change the list
    Collect c{file, &items};
    H5Ovisit2(file, H5_INDEX_NAME, H5_ITER_INC, visit, &c, H5O_INFO_BASIC);
    if (items.empty()) break;
    const Item& it = items[u64(rec + 1, 2) % items.size()];
    const std::uint64_t index = u64(rec + 3, 4), value = u64(rec + 7, 8);
    switch (rec[0] % 4) {
      case 0:
        set_element(file, it, index, rec + 7, (rec[15] & 1) != 0);
        break;
      case 1: {
        hid_t type = -1;
        std::vector<hsize_t> d;
        if (!shape_of(file, it, type, d)) break;
        if (!d.empty()) {
          d[index % d.size()] = std::min<std::uint64_t>(value, std::uint64_t{1} << 62);
          recreate(file, it, type, d);
        }
        H5Tclose(type);
        break;
      }
      case 2:
        if (it.attr.empty()) H5Ldelete(file, it.path.c_str(), H5P_DEFAULT);
        else H5Adelete_by_name(file, it.path.c_str(), it.attr.c_str(), H5P_DEFAULT);
        break;
      default: {
        hid_t type = -1;
        std::vector<hsize_t> d;
        if (!shape_of(file, it, type, d)) break;
        H5Tclose(type);
        hid_t to = value % 3 == 0   ? H5Tcopy(H5T_NATIVE_INT32)
                   : value % 3 == 1 ? H5Tcopy(H5T_NATIVE_DOUBLE)
                                    : H5Tcopy(H5T_C_S1);
        if (value % 3 == 2) H5Tset_size(to, H5T_VARIABLE);
        recreate(file, it, to, d);
        H5Tclose(to);
        break;
      }
    }
  }
  H5Fclose(file);
}

namespace {
/// The file opened read-write, closed at scope exit.
struct Rw {
  hid_t id;
  explicit Rw(const std::filesystem::path& f) : id(H5Fopen(f.c_str(), H5F_ACC_RDWR, H5P_DEFAULT)) {
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    if (id < 0) throw std::runtime_error("cannot open " + f.string());
  }
  ~Rw() { H5Fclose(id); }
  Rw(const Rw&) = delete;
  Rw& operator=(const Rw&) = delete;
};

void replace_attribute(hid_t file, const std::string& object, const std::string& name, hid_t type, const void* value) {
  if (H5Aexists_by_name(file, object.c_str(), name.c_str(), H5P_DEFAULT) > 0)
    H5Adelete_by_name(file, object.c_str(), name.c_str(), H5P_DEFAULT);
  hid_t space = H5Screate(H5S_SCALAR);
  hid_t a = H5Acreate_by_name(file, object.c_str(), name.c_str(), type, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  H5Sclose(space);
  if (a < 0) throw std::runtime_error("cannot create the attribute " + object + "@" + name);
  const herr_t w = H5Awrite(a, type, value);
  H5Aclose(a);
  if (w < 0) throw std::runtime_error("cannot write the attribute " + object + "@" + name);
}
}  // namespace

void h5_redeclare(const std::filesystem::path& file, const std::string& dataset, const std::vector<std::uint64_t>& dims) {
  Rw f(file);
  const Item it{dataset, ""};
  hid_t type = -1;
  std::vector<hsize_t> old;
  if (!shape_of(f.id, it, type, old)) throw std::runtime_error("no dataset " + dataset);
  recreate(f.id, it, type, std::vector<hsize_t>(dims.begin(), dims.end()));
  H5Tclose(type);
  if (H5Lexists(f.id, dataset.c_str(), H5P_DEFAULT) <= 0) throw std::runtime_error("cannot redeclare " + dataset);
}

void h5_set_number(const std::filesystem::path& file, const std::string& object, const std::string& name, double value) {
  Rw f(file);
  replace_attribute(f.id, object, name, H5T_NATIVE_DOUBLE, &value);
}

void h5_set_text(const std::filesystem::path& file, const std::string& object, const std::string& name,
                 const std::string& value) {
  Rw f(file);
  hid_t type = H5Tcopy(H5T_C_S1);
  H5Tset_size(type, H5T_VARIABLE);
  const char* p = value.c_str();
  replace_attribute(f.id, object, name, type, &p);
  H5Tclose(type);
}

void h5_remove(const std::filesystem::path& file, const std::string& path) {
  Rw f(file);
  const auto at = path.find('@');
  const herr_t r = at == std::string::npos
                       ? H5Ldelete(f.id, path.c_str(), H5P_DEFAULT)
                       : H5Adelete_by_name(f.id, path.substr(0, at).c_str(), path.substr(at + 1).c_str(), H5P_DEFAULT);
  if (r < 0) throw std::runtime_error("cannot remove " + path);
}

}  // namespace ts::fuzz
