// OFF meshes (Geomview's Object File Format) read whole before Assimp sees them.
//
// Assimp 5.2.5's OFF importer (Debian's libassimp5; code/AssetLib/OFF/OFFLoader.cpp) sizes its
// arrays from the header's counts unchecked (48 GB from a 94-byte file), crashed (SEGV) on a face
// line holding fewer indices than it declares, throws on a comment line among the vertices and
// loses the last faces after one among the faces. off_for_assimp() reads the file itself and
// hands Assimp the same mesh as plain OFF that Assimp reads without those faults.
#pragma once

#include <string>

namespace ts::io {

/// The mesh of the OFF file `bytes` as the plain OFF text handed to Assimp: `OFF` (`4OFF` with
/// homogeneous coordinates), the vertex and face counts, one line per vertex (its coordinates as
/// written, a missing one of an nOFF file of dimension 1 or 2 written 0, then w) and one per
/// face (its count and indices); no comments, no colours, normals or texture coordinates.
///
/// What is read: text up to the first NUL byte, after a UTF-8 byte-order mark (as Assimp).
/// - The header, as Assimp reads it: after blanks and comment lines, the keyword: the optional
///   letters ST, C, N, 4 and n in this order (texture coordinates, colours, normals, homogeneous
///   coordinates, a dimension) and OFF, case as written (COFF, NOFF, CNOFF, STOFF, 4OFF, nOFF,
///   STCN4nOFF...), the counts following at once or after blanks and comment lines ("OFF4 10"
///   is OFF with 4 vertices). Without the keyword the file begins with the vertex count. With n,
///   the dimension (1 to 3) comes first. Then the vertex count and the face count; the rest of
///   the face count's line (the edge count) is not read.
/// - The counts are checked against the bytes after them before anything is sized by them:
///   each vertex takes at least two bytes per number, each face at least four ("1 0\n").
/// - Records, one a line (a line ends at \n or \r): `#` begins a comment to the end of its
///   line; blank and comment lines are skipped anywhere. A vertex: its coordinates (and w), each
///   a finite number as Assimp reads numbers, whole (at most 100 characters; "5." is read as
///   5); what follows them (normals, colours, texture coordinates) is not used. A face: a vertex
///   count of 1 to 9 (Assimp's OFF reader drops larger polygons) and that many indices below
///   the vertex count; what follows them (a colour) is not used. What follows the last face is
///   not read.
/// Throws ts::Error naming `name` and the field ("header, vertices", "vertex 3", "face 0", ...).
std::string off_for_assimp(const std::string& bytes, const std::string& name);

}  // namespace ts::io
