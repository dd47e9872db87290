// Structured fuzzing of the HDF5 readers: an input is an edit script applied through the HDF5
// API to a well-formed base file (a store Touchstone wrote), so every mutated file is valid HDF5
// holding values, shapes and types that Touchstone's own validation must handle: counts declared
// as 10^12, NaN and negative sizes, missing datasets and attributes, a string where a number was.
// (Raw byte damage to HDF5's own metadata exercises libhdf5 itself: the hdf5 target.)
//
// Script: records of 16 bytes (at most 8; a shorter tail is ignored):
//   byte 0      operation (mod 4): 0 set one element, 1 resize one dimension, 2 delete, 3 retype
//   bytes 1-2   which object: index (mod count) into the file's datasets and attributes, in
//               HDF5 name order
//   bytes 3-6   element index (op 0, mod the element count) or axis (op 1, mod the rank)
//   bytes 7-14  value: the new element as int64 or double (op 0, byte 15 chooses), the new
//               extent (op 1, at most 2^62), the new type (op 3: int32, double, string)
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

namespace ts::fuzz {

/// Copy `base` to `out` and apply `script` to the copy. Edits that HDF5 refuses are skipped.
void apply_h5_edits(const std::filesystem::path& base, const std::filesystem::path& out,
                    std::span<const std::uint8_t> script);

/// Named edits of one file (the bad-input catalogue's crafted stores), each through the HDF5 API:
/// redeclare a dataset with other dimensions (chunked, nothing written: fill values), set a
/// numeric attribute (replacing it, whatever its type), write a string attribute, remove a
/// dataset, group or attribute ("path@name"). Each throws std::runtime_error if HDF5 refuses.
void h5_redeclare(const std::filesystem::path& file, const std::string& dataset, const std::vector<std::uint64_t>& dims);
void h5_set_number(const std::filesystem::path& file, const std::string& object, const std::string& name, double value);
void h5_set_text(const std::filesystem::path& file, const std::string& object, const std::string& name, const std::string& value);
void h5_remove(const std::filesystem::path& file, const std::string& path);

}  // namespace ts::fuzz
