// Encoders of the fine-mesh animation formats `tetrig export` writes (docs/export.md): the PC2
// point cache (Blender's Mesh Cache modifier, 3ds Max, Maya), OBJ and PLY frames, and glTF 2.0
// (tinygltf) with one morph target per frame and animated weights. Pure functions from arrays to
// bytes: no file I/O (tools/export.cpp stages and renames the files).
//
// Shapes: positions are #V*3 floats (x0 y0 z0 x1 ...) in rig units and axes, triangles #F*3
// vertex indices (counter-clockwise seen from outside, as LiveRig::fineTriangles gives them).
// Offline; any thread; allocates; throws std::invalid_argument on inconsistent sizes.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace tetrig::tools {

// PC2 ("POINTCACHE2\0", int32 version 1, int32 numPoints, float startFrame, float sampleRate,
// int32 numSamples: 32 bytes, little-endian), followed by numSamples x numPoints x 3 float32.
inline constexpr std::size_t kPc2HeaderBytes = 32;
std::vector<std::uint8_t> pc2Header(std::int32_t points, float start_frame, float sample_rate, std::int32_t samples);
// One sample (#V*3 floats, little-endian) appended to `out`.
void appendPc2Sample(std::span<const float> positions, std::vector<std::uint8_t>& out);

// Wavefront OBJ: `comment` lines (each prefixed "# "), one "v x y z" per vertex (shortest decimal
// that reads back to the same float), one "f a b c" per triangle (1-based).
std::string objText(std::span<const float> positions, std::span<const std::int32_t> triangles, std::span<const std::string> comment);

// PLY 1.0 binary_little_endian: element vertex (float x, y, z), element face
// (list uchar int vertex_indices), `comment` lines in the header.
std::vector<std::uint8_t> plyBytes(std::span<const float> positions, std::span<const std::int32_t> triangles,
                                   std::span<const std::string> comment);

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
struct GltfAnimation {
  std::string name;                        // mesh, node and animation name
  std::span<const float> rest;             // #V*3
  std::span<const std::int32_t> triangles; // #F*3
  std::span<const float> frames;           // frame_count * #V*3
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
