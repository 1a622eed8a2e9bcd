// Encoders of the fine-mesh animation formats `tetrig export` writes (docs/export.md): the PC2
// point cache (Blender's Mesh Cache modifier, 3ds Max, Maya), OBJ and PLY frames, and glTF 2.0
// (tinygltf) with one morph target per frame and animated weights. Pure functions from arrays to
// bytes: no file I/O (tools/export.cpp stages and renames the files).
//
// Shapes: positions are #V*3 floats (x0 y0 z0 x1 ...) in rig units and axes, triangles #F*3
// vertex indices (counter-clockwise seen from outside, as LiveRig::fineTriangles gives them).
// Offline; any thread; allocates; throws std::invalid_argument on inconsistent sizes.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace tetrig::tools {

// The asset's texture coordinates and materials on the fine mesh (Rig::surface) as the encoders
// write them. Empty spans: no texture coordinates (corner_uvs) or no materials
// (triangle_materials).
struct ExportMaterial {
  std::string name;                               // the asset's material name
  std::string texture_uri;                        // glTF: its diffuse texture, a URI relative to the output ("" none)
  std::array<double, 3> color = {1.0, 1.0, 1.0};  // glTF baseColorFactor when there is no texture
};
struct SurfaceLayout {
  std::vector<std::string> material_libraries;       // OBJ `mtllib` references (relative to the output's folder)
  std::vector<ExportMaterial> materials;
  std::span<const double> uvs;                       // #U*2 (u, v), OBJ convention: v up
  std::span<const std::int32_t> corner_uvs;          // #F*3: row of `uvs` per triangle corner, -1: none
  std::span<const std::int32_t> triangle_materials;  // #F: index into `materials`, -1: none
};

// PC2 ("POINTCACHE2\0", int32 version 1, int32 numPoints, float startFrame, float sampleRate,
// int32 numSamples: 32 bytes, little-endian), followed by numSamples x numPoints x 3 float32.
inline constexpr std::size_t kPc2HeaderBytes = 32;
std::vector<std::uint8_t> pc2Header(std::int32_t points, float start_frame, float sample_rate, std::int32_t samples);
// One sample (#V*3 floats, little-endian) appended to `out`.
void appendPc2Sample(std::span<const float> positions, std::vector<std::uint8_t>& out);

// Wavefront OBJ: `comment` lines (each prefixed "# "), one "v x y z" per vertex (shortest decimal
// that reads back to the same float), one "f a b c" per triangle (1-based). With `surface`: a
// `mtllib` line per library after the comments, one "vt u v" per uv (shortest decimal that reads
// back to the same double), "usemtl NAME" before each run of triangles of one material, and
// "f a/ta b/tb c/tc" for triangles whose three corners have a uv (else "f a b c").
std::string objText(std::span<const float> positions, std::span<const std::int32_t> triangles, std::span<const std::string> comment,
                    const SurfaceLayout* surface = nullptr);

// PLY 1.0 binary_little_endian: element vertex (float x, y, z, and float s, t when `vertex_uvs`
// (#V*2) is given), element face (list uchar int vertex_indices), `comment` lines in the header.
std::vector<std::uint8_t> plyBytes(std::span<const float> positions, std::span<const std::int32_t> triangles,
                                   std::span<const std::string> comment, std::span<const float> vertex_uvs = {});

// One uv per vertex (#V*2 floats, OBJ convention) when every corner of every vertex has a uv and
// each vertex's corners agree on it (no seam); nullopt otherwise (a PLY vertex holds one uv).
std::optional<std::vector<float>> perVertexUvs(std::size_t vertex_count, std::span<const std::int32_t> triangles,
                                               const SurfaceLayout& surface);

// glTF needs one uv per vertex: the vertices split where their corners' uvs differ. Vertex i < #V
// is vertex i (with the uv of its first corner in triangle order); the copies follow, in order of
// first use. Corners without a uv share one vertex with uv (0, 0).
struct SeamSplit {
  std::vector<std::int32_t> source;     // per split vertex: the vertex it copies (#V + copies)
  std::vector<float> uvs;               // per split vertex: (u, v), OBJ convention
  std::vector<std::int32_t> triangles;  // #F*3 split-vertex indices
};
SeamSplit splitAtSeams(std::size_t vertex_count, std::span<const std::int32_t> triangles, const SurfaceLayout& surface);

// glTF 2.0: one mesh whose base POSITION is `rest` and which has one morph target per frame
// (POSITION deltas frame - rest), one node, and one animation whose "weights" channel (LINEAR)
// has sample k at time k / rate_hz with weight 1 for target k and 0 for every other target, so
// the animation plays the frames in order (and blends neighbours between samples). `frames` is
// frame_count x #V*3 floats. binary: .glb (one BIN chunk), else .gltf JSON with the buffer as a
// base64 data URI (one self-contained file). The weights output holds frame_count^2 floats: the
// caller limits frame_count (kMaxGltfFrames). asset.extras.tetrig_export holds
// {"rate_hz", "first_frame", "frames"} (glTF has no frame rate of its own; the Blender add-on sets
// the scene rate from it before importing). Throws std::runtime_error if tinygltf fails.
inline constexpr std::size_t kMaxGltfFrames = 1000;
//
// Normals: with `rest_normals`, the base mesh has NORMAL and each morph target NORMAL deltas
// (frame_normals - rest_normals). Texture coordinates and materials (`surface`): the vertices are
// split at uv seams (splitAtSeams: vertex i < #V stays vertex i, copies follow; every morph target
// moves a copy as its vertex), TEXCOORD_0 = (u, 1 - v) (glTF's v points down), one material per
// asset material (name, metallic 0; baseColorTexture by URI when it has a texture, else its
// colour) and one primitive per material used, all sharing the vertex accessors and targets.
// asset.extras.tetrig_export also holds "vertices" (#V) and "seam_copies" (the vertex each copy
// repeats, in order).
struct GltfAnimation {
  std::string name;                        // mesh, node and animation name
  std::span<const float> rest;             // #V*3
  std::span<const std::int32_t> triangles; // #F*3
  std::span<const float> frames;           // frame_count * #V*3
  std::span<const float> rest_normals;     // #V*3 unit vectors, or empty: no NORMAL
  std::span<const float> frame_normals;    // frame_count * #V*3 (with rest_normals)
  const SurfaceLayout* surface = nullptr;  // texture coordinates and materials, or null
  std::size_t frame_count = 0;
  double rate_hz = 0;                      // > 0
  std::int64_t first_frame = 0;            // clip frame of frame 0 (recorded in asset.extras)
  std::string generator = "tetrig export";
};
std::vector<std::uint8_t> gltfBytes(const GltfAnimation& animation, bool binary);

// glTF is +Y up (glTF 2.0, 3.4): rotates xyz triples in place so that the rig's up axis `up`
// ("y", "-y", "x", "-x", "z", "-z", as RigAlignment::rig_up) becomes +Y, by a proper rotation about
// a coordinate axis ("z": (x, y, z) -> (x, z, -y)). "y" changes nothing. Throws
// std::invalid_argument for another name.
void rotateUpToY(const std::string& up, std::span<float> xyz);

}  // namespace tetrig::tools
