// Point clouds in PLY and PCD files, readable by CloudCompare, PCL, MeshLab and Open3D.
//
// Writing: vertices x y z (and nx ny nz / normal_x normal_y normal_z when the cloud has
// normals), ascii or binary (little endian). Outputs go through io::AtomicOutput.
// Precision: float32 is what PCL's point types expect, so it is the default while every
// coordinate is within ±100 m (float32 then resolves better than 8 µm); beyond that (a dive log
// far from the origin) the file is written in float64 so no precision is lost.
//
// Reading: PLY ascii / binary_little_endian / binary_big_endian, any scalar property types,
// extra properties and elements (faces, colours) ignored; PCD v0.7 ascii / binary /
// binary_compressed, any field types and counts, extra fields ignored. x y z are required;
// normals are read when all three components are present. Any non-finite value is rejected.
// Errors are ts::Error naming the file and the line (header, ascii data) or the point.
#pragma once

#include "engine/core.hpp"

#include <filesystem>

namespace ts::io {

enum class CloudEncoding { ascii, binary };
enum class CloudPrecision { automatic, float32, float64 };

struct CloudWriteSettings {
  CloudEncoding encoding = CloudEncoding::binary;
  CloudPrecision precision = CloudPrecision::automatic;  ///< see the header comment
};

/// Write by extension: .ply or .pcd (case-insensitive); other extensions throw.
void write_cloud(const std::filesystem::path& path, const PointCloud& cloud,
                 const CloudWriteSettings& settings = {});
void write_ply(const std::filesystem::path& path, const PointCloud& cloud,
               const CloudWriteSettings& settings = {});
void write_pcd(const std::filesystem::path& path, const PointCloud& cloud,
               const CloudWriteSettings& settings = {});

/// Read by extension (.ply / .pcd); other extensions are recognised by the file's first line.
PointCloud read_cloud(const std::filesystem::path& path);
PointCloud read_ply(const std::filesystem::path& path);
/// Walk a whole PLY file's header and records (every element, not only vertices), checking that
/// each element count and list length fits the bytes that follow; throws ts::Error naming the
/// file and the line or record. Mesh import runs it before handing PLY to Assimp, which sizes
/// arrays from those counts unchecked.
void check_ply_structure(const std::string& data, const std::string& file);
PointCloud read_pcd(const std::filesystem::path& path);

}  // namespace ts::io
