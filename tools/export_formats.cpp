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
#include <cctype>
#include <charconv>
#include <map>
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

// Shortest decimal that reads back to the same double.
void appendDoubleText(std::string& out, double value) {
  char buf[40];
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

void checkSurface(const SurfaceLayout& s, std::size_t triangle_values) {
  if (s.uvs.size() % 2 != 0) throw std::invalid_argument("export: uvs are not a multiple of 2 values");
  if (!s.corner_uvs.empty() && s.corner_uvs.size() != triangle_values)
    throw std::invalid_argument("export: corner uvs do not match the triangles");
  if (!s.triangle_materials.empty() && s.triangle_materials.size() * 3 != triangle_values)
    throw std::invalid_argument("export: triangle materials do not match the triangles");
  const auto uvs = static_cast<std::int64_t>(s.uvs.size() / 2), materials = static_cast<std::int64_t>(s.materials.size());
  for (const std::int32_t u : s.corner_uvs)
    if (u < -1 || u >= uvs) throw std::invalid_argument("export: corner uv " + std::to_string(u) + " out of range");
  for (const std::int32_t m : s.triangle_materials)
    if (m < -1 || m >= materials) throw std::invalid_argument("export: material " + std::to_string(m) + " out of range");
}

// A relative file reference as a URI reference (RFC 3986): bytes outside the unreserved and
// path characters percent-encoded.
std::string uriReference(const std::string& path) {
  static const char* kHex = "0123456789ABCDEF";
  std::string out;
  for (const char ch : path) {
    const auto c = static_cast<unsigned char>(ch);
    if (std::isalnum(c) || std::strchr("-._~/!$&'()*+,;=:@", c) != nullptr) {
      out += ch;
    } else {
      out += '%';
      out += kHex[c >> 4];
      out += kHex[c & 15];
    }
  }
  return out;
}

// A name on one OBJ line: a control character (a line break would end the line) becomes '?'.
std::string oneLine(const std::string& text) {
  std::string out = text;
  for (char& c : out) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  }
  return out;
}

// tinygltf writes images itself unless its writer says it did not: keep the URI as given.
bool keepImageUri(const std::string*, const std::string*, const tinygltf::Image*, bool, std::string*, void*) { return false; }

}  // namespace

std::optional<std::vector<float>> perVertexUvs(std::size_t vertex_count, std::span<const std::int32_t> triangles,
                                               const SurfaceLayout& surface) {
  checkSurface(surface, triangles.size());
  if (surface.corner_uvs.empty()) return std::nullopt;
  std::vector<std::int32_t> first(vertex_count, -1);
  std::vector<float> out(vertex_count * 2, 0.0f);
  for (std::size_t c = 0; c < triangles.size(); ++c) {
    const std::int32_t u = surface.corner_uvs[c];
    if (u < 0) return std::nullopt;
    const auto v = static_cast<std::size_t>(triangles[c]);
    if (v >= vertex_count) throw std::invalid_argument("export: triangle index out of range");
    if (first[v] < 0) {
      first[v] = u;
    } else if (first[v] != u && (surface.uvs[2 * static_cast<std::size_t>(u)] != surface.uvs[2 * static_cast<std::size_t>(first[v])] ||
                                 surface.uvs[2 * static_cast<std::size_t>(u) + 1] != surface.uvs[2 * static_cast<std::size_t>(first[v]) + 1])) {
      return std::nullopt;
    }
  }
  for (std::size_t v = 0; v < vertex_count; ++v) {
    if (first[v] < 0) continue;  // no triangle uses it: (0, 0)
    out[2 * v] = static_cast<float>(surface.uvs[2 * static_cast<std::size_t>(first[v])]);
    out[2 * v + 1] = static_cast<float>(surface.uvs[2 * static_cast<std::size_t>(first[v]) + 1]);
  }
  return out;
}

SeamSplit splitAtSeams(std::size_t vertex_count, std::span<const std::int32_t> triangles, const SurfaceLayout& surface) {
  checkSurface(surface, triangles.size());
  SeamSplit out;
  out.source.resize(vertex_count);
  for (std::size_t v = 0; v < vertex_count; ++v) out.source[v] = static_cast<std::int32_t>(v);
  out.uvs.assign(vertex_count * 2, 0.0f);
  out.triangles.resize(triangles.size());
  // Per vertex: the (u, v) of each split vertex made for it so far (a few at a seam).
  struct Copy {
    double u, v;
    std::int32_t index;
  };
  std::vector<std::vector<Copy>> copies(vertex_count);
  for (std::size_t c = 0; c < triangles.size(); ++c) {
    const auto v = static_cast<std::size_t>(triangles[c]);
    if (v >= vertex_count) throw std::invalid_argument("export: triangle index out of range");
    const std::int32_t k = surface.corner_uvs.empty() ? -1 : surface.corner_uvs[c];
    // No uv: (0, 0), as glTF has no "none".
    const double u = k < 0 ? 0.0 : surface.uvs[2 * static_cast<std::size_t>(k)], w = k < 0 ? 0.0 : surface.uvs[2 * static_cast<std::size_t>(k) + 1];
    std::int32_t index = -1;
    for (const Copy& copy : copies[v]) {
      if (copy.u == u && copy.v == w) index = copy.index;
    }
    if (index < 0) {
      index = copies[v].empty() ? static_cast<std::int32_t>(v) : static_cast<std::int32_t>(out.source.size());
      if (index != static_cast<std::int32_t>(v)) {
        out.source.push_back(static_cast<std::int32_t>(v));
        out.uvs.push_back(0.0f);
        out.uvs.push_back(0.0f);
      }
      out.uvs[2 * static_cast<std::size_t>(index)] = static_cast<float>(u);
      out.uvs[2 * static_cast<std::size_t>(index) + 1] = static_cast<float>(w);
      copies[v].push_back({u, w, index});
    }
    out.triangles[c] = index;
  }
  return out;
}

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

std::string objText(std::span<const float> positions, std::span<const std::int32_t> triangles, std::span<const std::string> comment,
                    const SurfaceLayout* surface) {
  checkMesh(positions, triangles);
  if (surface) checkSurface(*surface, triangles.size());
  const bool uvs = surface && !surface->corner_uvs.empty();
  const bool materials = surface && !surface->triangle_materials.empty();
  std::string out;
  out.reserve(positions.size() * 12 + triangles.size() * (uvs ? 16 : 8) + (surface ? surface->uvs.size() * 12 : 0) + 256);
  for (const std::string& line : comment) out += "# " + line + "\n";
  if (materials) {
    for (const std::string& library : surface->material_libraries) out += "mtllib " + oneLine(library) + "\n";
  }
  for (std::size_t i = 0; i < positions.size(); i += 3) {
    out += "v ";
    appendFloatText(out, positions[i]);
    out += ' ';
    appendFloatText(out, positions[i + 1]);
    out += ' ';
    appendFloatText(out, positions[i + 2]);
    out += '\n';
  }
  if (uvs) {
    for (std::size_t i = 0; i < surface->uvs.size(); i += 2) {
      out += "vt ";
      appendDoubleText(out, surface->uvs[i]);
      out += ' ';
      appendDoubleText(out, surface->uvs[i + 1]);
      out += '\n';
    }
  }
  std::int32_t material = -1;
  for (std::size_t i = 0; i < triangles.size(); i += 3) {
    if (materials) {
      const std::int32_t m = surface->triangle_materials[i / 3];
      if (m >= 0 && m != material) out += "usemtl " + oneLine(surface->materials[static_cast<std::size_t>(m)].name) + "\n";
      if (m >= 0) material = m;
    }
    const bool textured = uvs && surface->corner_uvs[i] >= 0 && surface->corner_uvs[i + 1] >= 0 && surface->corner_uvs[i + 2] >= 0;
    out += 'f';
    for (std::size_t k = 0; k < 3; ++k) {
      out += ' ';
      appendIntText(out, std::int64_t{triangles[i + k]} + 1);
      if (textured) {
        out += '/';
        appendIntText(out, std::int64_t{surface->corner_uvs[i + k]} + 1);
      }
    }
    out += '\n';
  }
  return out;
}

std::vector<std::uint8_t> plyBytes(std::span<const float> positions, std::span<const std::int32_t> triangles,
                                   std::span<const std::string> comment, std::span<const float> vertex_uvs) {
  checkMesh(positions, triangles);
  const std::size_t vertices = positions.size() / 3;
  if (!vertex_uvs.empty() && vertex_uvs.size() != vertices * 2) throw std::invalid_argument("PLY: vertex uvs do not match the vertices");
  std::string header = "ply\nformat binary_little_endian 1.0\n";
  for (const std::string& line : comment) header += "comment " + line + "\n";
  header += "element vertex " + std::to_string(vertices) + "\nproperty float x\nproperty float y\nproperty float z\n" +
            (vertex_uvs.empty() ? "" : "property float s\nproperty float t\n") + "element face " + std::to_string(triangles.size() / 3) +
            "\nproperty list uchar int vertex_indices\nend_header\n";
  std::vector<std::uint8_t> out(header.begin(), header.end());
  out.reserve(out.size() + positions.size_bytes() + vertex_uvs.size_bytes() + triangles.size() / 3 * 13);
  if (vertex_uvs.empty()) {
    appendFloats(out, positions);
  } else {
    for (std::size_t v = 0; v < vertices; ++v) {
      appendFloats(out, positions.subspan(3 * v, 3));
      appendFloats(out, vertex_uvs.subspan(2 * v, 2));
    }
  }
  for (std::size_t i = 0; i < triangles.size(); i += 3) {
    out.push_back(3);
    for (int c = 0; c < 3; ++c) appendPod(out, triangles[i + static_cast<std::size_t>(c)]);
  }
  return out;
}

std::vector<std::uint8_t> gltfBytes(const GltfAnimation& a, bool binary) {
  checkMesh(a.rest, a.triangles);
  const std::size_t n = a.frame_count, values = a.rest.size(), vertices = values / 3;
  if (n == 0) throw std::invalid_argument("glTF: no frame to write");
  if (a.frames.size() != n * values) throw std::invalid_argument("glTF: frame data does not match the frame count and vertex count");
  const bool normals = !a.rest_normals.empty();
  if (normals && (a.rest_normals.size() != values || a.frame_normals.size() != n * values))
    throw std::invalid_argument("glTF: normals do not match the vertices and frames");
  if (!(a.rate_hz > 0.0)) throw std::invalid_argument("glTF: the sample times need a frame rate");
  const SurfaceLayout none;
  const SurfaceLayout& surface = a.surface ? *a.surface : none;
  const bool uvs = !surface.corner_uvs.empty();
  const bool materials = !surface.triangle_materials.empty() && !surface.materials.empty();
  // The vertices as glTF holds them: split at uv seams (vertex i < #V is vertex i).
  SeamSplit split;
  if (uvs) {
    split = splitAtSeams(vertices, a.triangles, surface);
  } else {
    checkSurface(surface, a.triangles.size());
    split.source.resize(vertices);
    for (std::size_t v = 0; v < vertices; ++v) split.source[v] = static_cast<std::int32_t>(v);
    split.triangles.assign(a.triangles.begin(), a.triangles.end());
  }
  const std::size_t split_values = split.source.size() * 3;
  auto expand = [&](const float* xyz, std::vector<float>& out) {
    out.resize(split_values);
    for (std::size_t v = 0; v < split.source.size(); ++v) {
      const auto s3 = static_cast<std::size_t>(split.source[v]) * 3;
      out[3 * v] = xyz[s3];
      out[3 * v + 1] = xyz[s3 + 1];
      out[3 * v + 2] = xyz[s3 + 2];
    }
  };

  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = a.generator;
  tinygltf::Value::Object info;
  info["rate_hz"] = tinygltf::Value(a.rate_hz);
  info["first_frame"] = tinygltf::Value(static_cast<int>(a.first_frame));
  info["frames"] = tinygltf::Value(static_cast<int>(n));
  info["vertices"] = tinygltf::Value(static_cast<int>(vertices));
  tinygltf::Value::Array seam_copies;
  for (std::size_t v = vertices; v < split.source.size(); ++v) seam_copies.emplace_back(static_cast<int>(split.source[v]));
  info["seam_copies"] = tinygltf::Value(std::move(seam_copies));
  tinygltf::Value::Object extras;
  extras["tetrig_export"] = tinygltf::Value(info);
  model.asset.extras = tinygltf::Value(extras);
  model.buffers.resize(1);
  const std::size_t per_vertex = normals ? 2 : 1;
  std::size_t bytes = split_values * 4 * per_vertex * (n + 1) + split.source.size() * 8 + a.triangles.size() * 4 + n * 4 + n * n * 4 + 64;
  model.buffers[0].data.reserve(bytes);

  // Materials: one per asset material; textures by URI (not embedded), one image per file.
  if (materials) {
    std::vector<std::string> image_uris;
    for (const ExportMaterial& em : surface.materials) {
      tinygltf::Material m;
      m.name = em.name;
      m.pbrMetallicRoughness.metallicFactor = 0.0;  // OBJ materials are diffuse (glTF's default is metal)
      m.pbrMetallicRoughness.roughnessFactor = 1.0;
      if (!em.texture_uri.empty()) {
        const auto found = std::find(image_uris.begin(), image_uris.end(), em.texture_uri);
        if (found == image_uris.end()) {
          tinygltf::Image image;
          image.uri = uriReference(em.texture_uri);
          model.images.push_back(image);
          tinygltf::Texture texture;
          texture.source = static_cast<int>(model.images.size() - 1);
          model.textures.push_back(texture);
          image_uris.push_back(em.texture_uri);
        }
        const auto image = std::find(image_uris.begin(), image_uris.end(), em.texture_uri) - image_uris.begin();
        m.pbrMetallicRoughness.baseColorTexture.index = static_cast<int>(image);  // texture k shows image k
        m.pbrMetallicRoughness.baseColorTexture.texCoord = 0;
      } else {
        m.pbrMetallicRoughness.baseColorFactor = {em.color[0], em.color[1], em.color[2], 1.0};
      }
      model.materials.push_back(std::move(m));
    }
  }

  std::map<std::string, int> attributes;
  std::vector<float> scratch;
  expand(a.rest.data(), scratch);
  attributes["POSITION"] = addVec3(model, scratch);
  if (normals) {
    expand(a.rest_normals.data(), scratch);
    attributes["NORMAL"] = addVec3(model, scratch);
  }
  if (uvs) {
    std::vector<float> texcoord(split.uvs);
    for (std::size_t i = 1; i < texcoord.size(); i += 2) texcoord[i] = 1.0f - texcoord[i];  // glTF: v down from the top
    const int view = addView(model, texcoord.data(), texcoord.size() * 4, TINYGLTF_TARGET_ARRAY_BUFFER);
    attributes["TEXCOORD_0"] = addAccessor(model, view, TINYGLTF_COMPONENT_TYPE_FLOAT, texcoord.size() / 2, TINYGLTF_TYPE_VEC2);
  }
  // One morph target per frame (POSITION deltas, and NORMAL deltas), shared by every primitive.
  std::vector<std::map<std::string, int>> targets;
  std::vector<float> delta(values);
  for (std::size_t k = 0; k < n; ++k) {
    std::map<std::string, int> target;
    const float* frame = a.frames.data() + k * values;
    for (std::size_t i = 0; i < values; ++i) delta[i] = frame[i] - a.rest[i];
    expand(delta.data(), scratch);
    target["POSITION"] = addVec3(model, scratch);
    if (normals) {
      const float* normal = a.frame_normals.data() + k * values;
      for (std::size_t i = 0; i < values; ++i) delta[i] = normal[i] - a.rest_normals[i];
      expand(delta.data(), scratch);
      target["NORMAL"] = addVec3(model, scratch);
    }
    targets.push_back(std::move(target));
  }
  // Primitives: one per material used (the triangles in their order), or one for all.
  tinygltf::Mesh mesh;
  mesh.name = a.name;
  const auto triangle_count = static_cast<std::int32_t>(a.triangles.size() / 3);
  const std::int32_t first_group = materials ? -1 : 0, end_group = materials ? static_cast<std::int32_t>(surface.materials.size()) : 1;
  for (std::int32_t group = first_group; group < end_group; ++group) {
    std::vector<std::uint32_t> indices;
    for (std::int32_t t = 0; t < triangle_count; ++t) {
      if (materials && surface.triangle_materials[static_cast<std::size_t>(t)] != group) continue;
      for (std::size_t k = 0; k < 3; ++k) indices.push_back(static_cast<std::uint32_t>(split.triangles[3 * static_cast<std::size_t>(t) + k]));
    }
    if (materials && indices.empty()) continue;  // a material no triangle uses
    tinygltf::Primitive prim;
    prim.mode = TINYGLTF_MODE_TRIANGLES;
    prim.attributes = attributes;
    prim.targets = targets;
    if (materials && group >= 0) prim.material = group;
    if (!indices.empty()) {
      const int view = addView(model, indices.data(), indices.size() * 4, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
      prim.indices = addAccessor(model, view, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, indices.size(), TINYGLTF_TYPE_SCALAR);
    }
    mesh.primitives.push_back(std::move(prim));
  }
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
  writer.SetImageWriter(keepImageUri, nullptr);
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
