// The guard in front of the surface importer: a mesh file is input from anyone, and assimp trusts
// it. Its OFF and PLY readers allocate whatever the header's counts say before reading any data
// (a 170-byte PLY claiming 2^28 vertices costs 3 GB), read past their buffers when a file holds
// fewer faces or list items than it declares (an assertion abort or a segmentation fault), clamp
// or keep out-of-range vertex indices, drop OFF faces of more than 9 corners, and triangulate
// polygons in quadratic time (one face of 100k corners: minutes). checkSurfaceBytes reads the file
// once, in linear time and without allocating for the file's counts, and refuses every such file
// with one line (what is wrong, where, what to do) before assimp sees it.
//
// What is checked, by format (the extension, as assimp picks its reader by extension):
//   OFF  "[ST][C][N]OFF" then the vertex, face and edge counts; then one vertex per line (3
//        numbers) and one face per line ("k i_1 .. i_k", 1 <= k <= 9, 0 <= i < #vertices); every
//        declared vertex and face present; lines shorter than 4096 bytes (assimp's line buffer);
//        no comment lines inside the data (assimp reads them as data).
//   PLY  ascii and binary (either byte order): the header (standard types; properties right
//        after their element, no comment or obj_info line between them, which makes assimp drop
//        the properties after it; elements the importer reads when they hold data: vertex,
//        face, edge, material; no triangle strips, which it reads wrongly); every declared item
//        present, each ascii item on its own line; list lengths within the data; lists only
//        where the importer reads them safely (face vertex_indices, texcoord); face corners
//        1..max_face_corners, indices in range; x, y, z scalar properties of element vertex.
//   OBJ  face ("f", "l", "p") lines: at most max_face_corners corners each (continuations joined).
//        Indices are checked by assimp itself.
//   STL  binary: 84 + 50 * (triangle count) bytes exactly; else it must be ASCII ("solid").
// All formats: the total triangulation work, the sum of k^2 over polygons of k > 4 corners, at
// most max_polygon_work. Other formats (glTF, FBX, ...) are not checked here: importSurface runs
// assimp in a child process with memory and time limits for every format (import_surface.hpp).
//
// Offline, any thread, no I/O, allocates only small buffers, throws RigBuildError.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

namespace tetrig::rigbuild {

struct SurfaceFileLimits {
  // Corners of one polygon. assimp's ear-clipping triangulation costs O(k^2) per polygon.
  std::int32_t max_face_corners = 1024;
  // Sum over polygons of more than 4 corners of corners^2 (triangles and quads cost nothing
  // extra): bounds the whole file's triangulation at about 0.2 s.
  std::int64_t max_polygon_work = std::int64_t{1} << 24;
};

enum class SurfaceFileFormat { kOther, kObj, kOff, kPlyAscii, kPlyBinary, kStlAscii, kStlBinary };

// What the check saw (tests and messages).
struct SurfaceFileSummary {
  SurfaceFileFormat format = SurfaceFileFormat::kOther;
  std::int64_t vertices = 0;         // declared (OFF, PLY) or "v" lines (OBJ); 0 for STL and others
  std::int64_t faces = 0;            // declared faces (OFF, PLY), "f" lines (OBJ), triangles (binary STL)
  std::int32_t largest_face = 0;     // most corners of one face (OFF, PLY, OBJ)
  std::int64_t polygon_work = 0;     // sum of k^2 over faces of k > 4 corners
};

// Checks a file's bytes, read by the caller (importSurface reads the file once and hands assimp
// the same bytes, so the file cannot change between the check and the import). `extension` is
// the lower-case extension with its dot (".off"): OFF, PLY, OBJ and STL are checked, anything
// else passes (format kOther). `name` is the file name used in messages. Throws RigBuildError
// naming the file, the line or byte offset and what to do.
SurfaceFileSummary checkSurfaceBytes(std::string_view bytes, std::string_view extension, const std::string& name,
                                     const SurfaceFileLimits& limits = {});

}  // namespace tetrig::rigbuild
