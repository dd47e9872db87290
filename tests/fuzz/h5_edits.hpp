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

namespace ts::fuzz {

/// Copy `base` to `out` and apply `script` to the copy. Edits that HDF5 refuses are skipped.
void apply_h5_edits(const std::filesystem::path& base, const std::filesystem::path& out,
                    std::span<const std::uint8_t> script);

}  // namespace ts::fuzz
