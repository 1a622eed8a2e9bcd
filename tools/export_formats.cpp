// Animation file encoders (tools/export_formats.hpp). Byte layouts:
//  - PC2: the point cache format of 3ds Max's Point Cache 2 modifier, as Blender's Mesh Cache
//    modifier and Maya read it: a 32-byte header then float32 xyz per point per sample;
//  - PLY 1.0 (Turk, Stanford 1994), binary_little_endian;
//  - glTF 2.0 (Khronos), written through tinygltf (Debian libtinygltf-dev): morph targets
//    ("targets" of a primitive, section 3.7.2.2) and an animation channel with path "weights"
//    (section 3.11), the way glTF carries vertex animation of one mesh.
#include "export_formats.hpp"

#include <tiny_gltf.h>

#include <algorithm>
#include <bit>
#include <charconv>
#include <cstring>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <system_error>

namespace tetrig::tools {

static_assert(std::endian::native == std::endian::little, "the export writers copy host floats as little-endian");

namespace {

void checkMesh(std::span<const float> positions, std::span<const std::int32_t> triangles) {
  if (positions.size() % 3 != 0) throw std::invalid_argument("export: positions are not a multiple of 3 floats");
  if (triangles.size() % 3 != 0) throw std::invalid_argument("export: triangle indices are not a multiple of 3");
  const auto n = static_cast<std::int64_t>(positions.size() / 3);
  for (const std::int32_t i : triangles) {
    if (i < 0 || i >= n) throw std::invalid_argument("export: triangle index " + std::to_string(i) + " out of range");
  }
}

template <class T>
void appendPod(std::vector<std::uint8_t>& out, const T& value) {
  const auto* p = reinterpret_cast<const std::uint8_t*>(&value);
  out.insert(out.end(), p, p + sizeof(T));
}

void appendFloats(std::vector<std::uint8_t>& out, std::span<const float> values) {
  const auto* p = reinterpret_cast<const std::uint8_t*>(values.data());
  out.insert(out.end(), p, p + values.size_bytes());
}

// Shortest decimal that reads back to the same float (std::to_chars).
void appendFloatText(std::string& out, float value) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, value);
  out.append(buf, r.ptr);
}

void appendIntText(std::string& out, std::int64_t value) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof buf, value);
  out.append(buf, r.ptr);
}

// Appends `bytes` to the glTF buffer (4-byte aligned) and adds a buffer view; returns its index.
int addView(tinygltf::Model& model, const void* bytes, std::size_t size, int target) {
  auto& data = model.buffers[0].data;
  while (data.size() % 4 != 0) data.push_back(0);
  tinygltf::BufferView view;
  view.buffer = 0;
  view.byteOffset = data.size();
  view.byteLength = size;
  view.target = target;
  const auto* p = static_cast<const std::uint8_t*>(bytes);
  data.insert(data.end(), p, p + size);
  model.bufferViews.push_back(view);
  return static_cast<int>(model.bufferViews.size() - 1);
}

int addAccessor(tinygltf::Model& model, int view, int component, std::size_t count, int type, std::vector<double> min = {},
                std::vector<double> max = {}) {
  tinygltf::Accessor a;
  a.bufferView = view;
  a.byteOffset = 0;
  a.componentType = component;
  a.count = count;
  a.type = type;
  a.minValues = std::move(min);
  a.maxValues = std::move(max);
  model.accessors.push_back(a);
  return static_cast<int>(model.accessors.size() - 1);
}

// A VEC3 float accessor with its min/max (required for POSITION, also on morph targets).
int addVec3(tinygltf::Model& model, std::span<const float> xyz) {
  std::vector<double> lo(3, std::numeric_limits<double>::infinity()), hi(3, -std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < xyz.size(); ++i) {
    lo[i % 3] = std::min(lo[i % 3], static_cast<double>(xyz[i]));
    hi[i % 3] = std::max(hi[i % 3], static_cast<double>(xyz[i]));
  }
  const int view = addView(model, xyz.data(), xyz.size_bytes(), TINYGLTF_TARGET_ARRAY_BUFFER);
  return addAccessor(model, view, TINYGLTF_COMPONENT_TYPE_FLOAT, xyz.size() / 3, TINYGLTF_TYPE_VEC3, std::move(lo), std::move(hi));
}

}  // namespace

std::vector<std::uint8_t> pc2Header(std::int32_t points, float start_frame, float sample_rate, std::int32_t samples) {
  if (points <= 0 || samples <= 0) throw std::invalid_argument("PC2: the cache needs at least one point and one sample");
  std::vector<std::uint8_t> out;
  out.reserve(kPc2HeaderBytes);
  const char magic[12] = {'P', 'O', 'I', 'N', 'T', 'C', 'A', 'C', 'H', 'E', '2', '\0'};
  out.insert(out.end(), magic, magic + 12);
  appendPod(out, std::int32_t{1});
  appendPod(out, points);
  appendPod(out, start_frame);
  appendPod(out, sample_rate);
  appendPod(out, samples);
  return out;
}

void appendPc2Sample(std::span<const float> positions, std::vector<std::uint8_t>& out) { appendFloats(out, positions); }

std::string objText(std::span<const float> positions, std::span<const std::int32_t> triangles, std::span<const std::string> comment) {
  checkMesh(positions, triangles);
  std::string out;
  out.reserve(positions.size() * 12 + triangles.size() * 8 + 256);
  for (const std::string& line : comment) out += "# " + line + "\n";
  for (std::size_t i = 0; i < positions.size(); i += 3) {
    out += "v ";
    appendFloatText(out, positions[i]);
    out += ' ';
    appendFloatText(out, positions[i + 1]);
    out += ' ';
    appendFloatText(out, positions[i + 2]);
    out += '\n';
  }
  for (std::size_t i = 0; i < triangles.size(); i += 3) {
    out += "f ";
    appendIntText(out, std::int64_t{triangles[i]} + 1);
    out += ' ';
    appendIntText(out, std::int64_t{triangles[i + 1]} + 1);
    out += ' ';
    appendIntText(out, std::int64_t{triangles[i + 2]} + 1);
    out += '\n';
  }
  return out;
}

std::vector<std::uint8_t> plyBytes(std::span<const float> positions, std::span<const std::int32_t> triangles,
                                   std::span<const std::string> comment) {
  checkMesh(positions, triangles);
  std::string header = "ply\nformat binary_little_endian 1.0\n";
  for (const std::string& line : comment) header += "comment " + line + "\n";
  header += "element vertex " + std::to_string(positions.size() / 3) +
            "\nproperty float x\nproperty float y\nproperty float z\n"
            "element face " + std::to_string(triangles.size() / 3) +
            "\nproperty list uchar int vertex_indices\nend_header\n";
  std::vector<std::uint8_t> out(header.begin(), header.end());
  out.reserve(out.size() + positions.size_bytes() + triangles.size() / 3 * 13);
  appendFloats(out, positions);
  for (std::size_t i = 0; i < triangles.size(); i += 3) {
    out.push_back(3);
    for (int c = 0; c < 3; ++c) appendPod(out, triangles[i + static_cast<std::size_t>(c)]);
  }
  return out;
}

std::vector<std::uint8_t> gltfBytes(const GltfAnimation& a, bool binary) {
  checkMesh(a.rest, a.triangles);
  const std::size_t n = a.frame_count, values = a.rest.size();
  if (n == 0) throw std::invalid_argument("glTF: no frame to write");
  if (a.frames.size() != n * values) throw std::invalid_argument("glTF: frame data does not match the frame count and vertex count");
  if (!(a.rate_hz > 0.0)) throw std::invalid_argument("glTF: the sample times need a frame rate");
  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = a.generator;
  tinygltf::Value::Object info;
  info["rate_hz"] = tinygltf::Value(a.rate_hz);
  info["first_frame"] = tinygltf::Value(static_cast<int>(a.first_frame));
  info["frames"] = tinygltf::Value(static_cast<int>(n));
  tinygltf::Value::Object extras;
  extras["tetrig_export"] = tinygltf::Value(info);
  model.asset.extras = tinygltf::Value(extras);
  model.buffers.resize(1);
  std::size_t bytes = values * 4 * (n + 1) + a.triangles.size() * 4 + n * 4 + n * n * 4 + 64;
  model.buffers[0].data.reserve(bytes);

  tinygltf::Primitive prim;
  prim.mode = TINYGLTF_MODE_TRIANGLES;
  prim.attributes["POSITION"] = addVec3(model, a.rest);
  if (!a.triangles.empty()) {
    const int view = addView(model, a.triangles.data(), a.triangles.size_bytes(), TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
    prim.indices = addAccessor(model, view, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, a.triangles.size(), TINYGLTF_TYPE_SCALAR);
  }
  std::vector<float> delta(values);
  for (std::size_t k = 0; k < n; ++k) {
    const float* frame = a.frames.data() + k * values;
    for (std::size_t i = 0; i < values; ++i) delta[i] = frame[i] - a.rest[i];
    prim.targets.push_back({{"POSITION", addVec3(model, delta)}});
  }
  tinygltf::Mesh mesh;
  mesh.name = a.name;
  mesh.primitives.push_back(std::move(prim));
  mesh.weights.assign(n, 0.0);  // without the animation: the rest pose
  model.meshes.push_back(std::move(mesh));
  tinygltf::Node node;
  node.name = a.name;
  node.mesh = 0;
  model.nodes.push_back(node);
  tinygltf::Scene scene;
  scene.nodes.push_back(0);
  model.scenes.push_back(scene);
  model.defaultScene = 0;

  std::vector<float> times(n), weights(n * n, 0.0f);
  for (std::size_t k = 0; k < n; ++k) {
    times[k] = static_cast<float>(static_cast<double>(k) / a.rate_hz);
    weights[k * n + k] = 1.0f;
  }
  const int time_view = addView(model, times.data(), times.size() * 4, 0);
  const int input = addAccessor(model, time_view, TINYGLTF_COMPONENT_TYPE_FLOAT, n, TINYGLTF_TYPE_SCALAR, {times.front()}, {times.back()});
  const int weight_view = addView(model, weights.data(), weights.size() * 4, 0);
  const int output = addAccessor(model, weight_view, TINYGLTF_COMPONENT_TYPE_FLOAT, n * n, TINYGLTF_TYPE_SCALAR);
  tinygltf::Animation anim;
  anim.name = a.name;
  tinygltf::AnimationSampler sampler;
  sampler.input = input;
  sampler.output = output;
  sampler.interpolation = "LINEAR";
  anim.samplers.push_back(sampler);
  tinygltf::AnimationChannel channel;
  channel.sampler = 0;
  channel.target_node = 0;
  channel.target_path = "weights";
  anim.channels.push_back(channel);
  model.animations.push_back(std::move(anim));
  model.buffers[0].data.resize((model.buffers[0].data.size() + 3) / 4 * 4, 0);

  std::ostringstream stream(std::ios::binary);
  tinygltf::TinyGLTF writer;
  if (!writer.WriteGltfSceneToStream(&model, stream, false, binary)) throw std::runtime_error("glTF: tinygltf could not serialize the model");
  const std::string text = std::move(stream).str();
  return std::vector<std::uint8_t>(text.begin(), text.end());
}

void rotateUpToY(const std::string& up, std::span<float> xyz) {
  if (xyz.size() % 3 != 0) throw std::invalid_argument("export: positions are not a multiple of 3 floats");
  // Rows of the rotation (det +1) taking `up` to +Y.
  int m[3][3];
  if (up == "y" || up == "+y") return;
  if (up == "z" || up == "+z") {
    const int r[3][3] = {{1, 0, 0}, {0, 0, 1}, {0, -1, 0}};
    std::memcpy(m, r, sizeof m);
  } else if (up == "-z") {
    const int r[3][3] = {{1, 0, 0}, {0, 0, -1}, {0, 1, 0}};
    std::memcpy(m, r, sizeof m);
  } else if (up == "x" || up == "+x") {
    const int r[3][3] = {{0, -1, 0}, {1, 0, 0}, {0, 0, 1}};
    std::memcpy(m, r, sizeof m);
  } else if (up == "-x") {
    const int r[3][3] = {{0, 1, 0}, {-1, 0, 0}, {0, 0, 1}};
    std::memcpy(m, r, sizeof m);
  } else if (up == "-y") {
    const int r[3][3] = {{1, 0, 0}, {0, -1, 0}, {0, 0, -1}};
    std::memcpy(m, r, sizeof m);
  } else {
    throw std::invalid_argument("export: unknown up axis '" + up + "' (x, y, z, -x, -y, -z)");
  }
  for (std::size_t i = 0; i < xyz.size(); i += 3) {
    const float p[3] = {xyz[i], xyz[i + 1], xyz[i + 2]};
    for (int r = 0; r < 3; ++r)
      xyz[i + static_cast<std::size_t>(r)] = static_cast<float>(m[r][0]) * p[0] + static_cast<float>(m[r][1]) * p[1] +
                                              static_cast<float>(m[r][2]) * p[2];
  }
}

}  // namespace tetrig::tools
