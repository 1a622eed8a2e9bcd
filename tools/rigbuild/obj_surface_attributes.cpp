// Texture coordinates and materials of Wavefront OBJ files (the OBJ and MTL formats as published
// with Wavefront's Advanced Visualizer, Appendix B1/B2: `v`, `vt`, `f v/vt/vn` with 1-based or
// negative (relative) indices, `usemtl`, `mtllib`; `newmtl`, `Kd`, `map_Kd` with its options),
// matched onto the rig builder's fine mesh (obj_surface_attributes.hpp).
#include "tetrig/rigbuild/obj_surface_attributes.hpp"

#include "tetrig/printable_text.hpp"
#include "tetrig/rigbuild/surface_mesh.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <numeric>
#include <system_error>

namespace tetrig::rigbuild {
namespace {

constexpr std::size_t kMaxMaterials = 4096;             // more is not a character asset; materials are then dropped
constexpr std::uintmax_t kMaxMtlBytes = 64ull << 20;     // a .mtl larger than this is not read
constexpr std::size_t kMaxNameBytes = 65536;             // the rig file's string limit

bool blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

std::string_view trim(std::string_view s) {
  while (!s.empty() && blank(s.front())) s.remove_prefix(1);
  while (!s.empty() && blank(s.back())) s.remove_suffix(1);
  return s;
}

// Splits off the first blank-separated token of `s`.
std::string_view nextToken(std::string_view& s) {
  s = trim(s);
  std::size_t end = 0;
  while (end < s.size() && !blank(s[end])) ++end;
  const std::string_view token = s.substr(0, end);
  s.remove_prefix(end);
  return token;
}

bool parseDouble(std::string_view token, double& out) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);  // from_chars refuses a leading '+'
  const auto [ptr, ec] = std::from_chars(token.data(), token.data() + token.size(), out);
  return ec == std::errc() && ptr == token.data() + token.size() && std::isfinite(out);
}

bool parseIndex(std::string_view token, std::int64_t& out) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  const auto [ptr, ec] = std::from_chars(token.data(), token.data() + token.size(), out);
  return ec == std::errc() && ptr == token.data() + token.size();
}

// Calls `line(keyword, rest)` for every logical line of an OBJ/MTL text (`\` continuations joined,
// `#` comment lines skipped).
template <class F>
void forEachLine(std::string_view text, F&& line) {
  std::string joined;
  std::size_t at = 0;
  while (at < text.size()) {
    std::size_t end = text.find('\n', at);
    if (end == std::string_view::npos) end = text.size();
    std::string_view piece = text.substr(at, end - at);
    at = end + 1;
    while (!piece.empty() && blank(piece.back())) piece.remove_suffix(1);
    if (!piece.empty() && piece.back() == '\\') {
      joined.append(piece.substr(0, piece.size() - 1));
      joined += ' ';
      continue;
    }
    std::string_view full = piece;
    if (!joined.empty()) {
      joined.append(piece);
      full = joined;
    }
    std::string_view rest = full;
    const std::string_view keyword = nextToken(rest);
    if (!keyword.empty() && keyword.front() != '#') line(keyword, trim(rest));
    joined.clear();
  }
}

std::string readSmallFile(const std::filesystem::path& path, std::uintmax_t limit, bool& ok) {
  ok = false;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return {};
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (ec || size > limit) return {};
  std::ifstream in(path, std::ios::binary);
  if (!in) return {};
  std::string bytes(static_cast<std::size_t>(size), '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(size));
  bytes.resize(static_cast<std::size_t>(in.gcount()));
  ok = true;
  return bytes;
}

std::string plural(std::size_t n, const char* one, const char* many) { return std::to_string(n) + " " + (n == 1 ? one : many); }

}  // namespace

std::optional<ObjSurfaceData> readObjSurfaceData(std::string_view text, std::string* why) {
  ObjSurfaceData d;
  std::string error;
  std::int32_t material = -1;
  std::map<std::string, std::int32_t, std::less<>> material_index;
  std::vector<std::pair<std::int64_t, std::int64_t>> corners;  // (v, vt) as resolved, checked at the end
  std::int64_t vt_lines = 0;
  forEachLine(text, [&](std::string_view keyword, std::string_view rest) {
    if (!error.empty()) return;
    if (keyword == "v") {
      ++d.vertices;
    } else if (keyword == "vt") {
      std::array<double, 2> uv{0.0, 0.0};
      std::string_view r = rest;
      if (!parseDouble(nextToken(r), uv[0])) {
        error = "a vt line has no number";
        return;
      }
      const std::string_view v = nextToken(r);
      if (!v.empty() && !parseDouble(v, uv[1])) {
        error = "a vt line has a malformed number";
        return;
      }
      d.uvs.push_back(uv);
      ++vt_lines;
    } else if (keyword == "f") {
      std::string_view r = rest;
      const std::size_t first = d.corner_vertex.size();
      for (std::string_view token = nextToken(r); !token.empty(); token = nextToken(r)) {
        const std::size_t slash = token.find('/');
        std::int64_t v = 0, t = 0;
        if (!parseIndex(token.substr(0, slash), v) || v == 0) {
          error = "a face has a malformed vertex index '" + printableText(token, 40) + "'";
          return;
        }
        if (slash != std::string_view::npos) {
          std::string_view uv = token.substr(slash + 1);
          uv = uv.substr(0, uv.find('/'));
          if (!uv.empty() && (!parseIndex(uv, t) || t == 0)) {
            error = "a face has a malformed texture index '" + printableText(token, 40) + "'";
            return;
          }
        }
        // 1-based, or negative: relative to the lines read so far.
        const std::int64_t vi = v > 0 ? v - 1 : d.vertices + v;
        const std::int64_t ti = t > 0 ? t - 1 : t < 0 ? vt_lines + t : -1;
        if (vi < 0 || (t != 0 && ti < 0)) {
          error = "a face has a relative index before the first vertex or texture coordinate";
          return;
        }
        corners.emplace_back(vi, ti);
        d.corner_vertex.push_back(0);
      }
      const std::size_t n = d.corner_vertex.size() - first;
      if (n < 3) {  // points and lines: not surface faces (the importer skips them too)
        d.corner_vertex.resize(first);
        corners.resize(first);
        return;
      }
      if (d.corner_vertex.size() > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max())) {
        error = "too many face corners";
        return;
      }
      d.faces.push_back({static_cast<std::int32_t>(first), static_cast<std::int32_t>(n), material});
    } else if (keyword == "usemtl") {
      const std::string name(rest);
      const auto [it, fresh] = material_index.try_emplace(name, static_cast<std::int32_t>(d.materials.size()));
      if (fresh) d.materials.push_back(name);
      material = it->second;
    } else if (keyword == "mtllib") {
      if (!rest.empty() && std::find(d.material_libraries.begin(), d.material_libraries.end(), rest) == d.material_libraries.end())
        d.material_libraries.emplace_back(rest);
    }
  });
  if (error.empty()) {
    d.corner_uv.resize(corners.size());
    for (std::size_t c = 0; c < corners.size(); ++c) {
      const auto [v, t] = corners[c];
      if (v >= d.vertices || t >= static_cast<std::int64_t>(d.uvs.size())) {
        error = "a face names " + (v >= d.vertices ? "vertex " + std::to_string(v + 1) + " of " + std::to_string(d.vertices)
                                                   : "texture coordinate " + std::to_string(t + 1) + " of " + std::to_string(d.uvs.size()));
        break;
      }
      d.corner_vertex[c] = static_cast<std::int32_t>(v);
      d.corner_uv[c] = static_cast<std::int32_t>(t);
    }
  }
  if (!error.empty()) {
    if (why) *why = error;
    return std::nullopt;
  }
  return d;
}

std::vector<MtlMaterial> readMtl(std::string_view text) {
  std::vector<MtlMaterial> out;
  forEachLine(text, [&](std::string_view keyword, std::string_view rest) {
    if (keyword == "newmtl") {
      out.push_back({std::string(rest), std::nullopt, {}});
      return;
    }
    if (out.empty()) return;
    if (keyword == "Kd") {
      Eigen::Vector3d c;
      std::string_view r = rest;
      for (int k = 0; k < 3; ++k) {
        if (!parseDouble(nextToken(r), c[k])) return;  // "Kd spectral ..." and "Kd xyz ..." are not read
      }
      out.back().diffuse_color = c;
    } else if (keyword == "map_Kd") {
      // Options before the file name: -o/-s/-t take up to three numbers, the others one word.
      std::string_view r = rest;
      while (true) {
        std::string_view probe = r;
        const std::string_view option = nextToken(probe);
        if (option.size() < 2 || option.front() != '-') break;
        r = probe;
        int words = 1;
        if (option == "-o" || option == "-s" || option == "-t") words = 3;
        if (option == "-mm") words = 2;
        for (int k = 0; k < words; ++k) {
          std::string_view look = r;
          const std::string_view value = nextToken(look);
          double ignored = 0;
          if (value.empty() || (k > 0 && !parseDouble(value, ignored))) break;
          r = look;
        }
      }
      std::string file(trim(r));
      std::replace(file.begin(), file.end(), '\\', '/');
      out.back().diffuse_texture = file;
    }
  });
  return out;
}

std::optional<RigSurfaceAttributes> objSurfaceAttributes(const std::filesystem::path& path, std::span<const std::int32_t> file_to_fine,
                                                         Triangles& fine_triangles, std::string* note) {
  auto say = [note](const std::string& text) {
    if (note) *note = text;
  };
  say("");
  bool read = false;
  const std::string text = readSmallFile(path, std::numeric_limits<std::uintmax_t>::max(), read);
  if (!read) {
    say("texture coordinates: " + path.filename().string() + " could not be read again; none kept");
    return std::nullopt;
  }
  std::string why;
  const std::optional<ObjSurfaceData> obj = readObjSurfaceData(text, &why);
  if (!obj) {
    say("texture coordinates not kept: " + path.filename().string() + ": " + why);
    return std::nullopt;
  }
  if (obj->uvs.empty() && obj->materials.empty()) return std::nullopt;
  if (static_cast<std::size_t>(obj->vertices) != file_to_fine.size()) {
    say("texture coordinates not kept: the file has " + std::to_string(obj->vertices) + " vertices, the import " +
        std::to_string(file_to_fine.size()));
    return std::nullopt;
  }

  if (fine_triangles.rows() == 0) return std::nullopt;
  // Faces by fine vertex (each face listed once per distinct fine vertex), in file order.
  const auto fine_count = static_cast<std::size_t>(std::max<Eigen::Index>(fine_triangles.maxCoeff() + 1, 0));
  auto fineOf = [&](std::int32_t corner) {
    return file_to_fine[static_cast<std::size_t>(obj->corner_vertex[static_cast<std::size_t>(corner)])];
  };
  std::vector<std::int32_t> start(fine_count + 1, 0), list;
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<std::int32_t> fill(start.begin(), start.end() - 1);
    for (std::size_t p = 0; p < obj->faces.size(); ++p) {
      const ObjFace& face = obj->faces[p];
      for (std::int32_t c = face.first_corner; c < face.first_corner + face.corners; ++c) {
        const std::int32_t v = fineOf(c);
        if (v < 0 || static_cast<std::size_t>(v) >= fine_count) continue;
        bool seen = false;
        for (std::int32_t e = face.first_corner; e < c && !seen; ++e) seen = fineOf(e) == v;
        if (seen) continue;
        if (pass == 0) {
          ++start[static_cast<std::size_t>(v) + 1];
        } else {
          list[static_cast<std::size_t>(fill[static_cast<std::size_t>(v)]++)] = static_cast<std::int32_t>(p);
        }
      }
    }
    if (pass == 0) {
      std::partial_sum(start.begin(), start.end(), start.begin());
      list.resize(static_cast<std::size_t>(start.back()));
    }
  }
  // The corner of `face` at fine vertex v, or -1.
  auto cornerAt = [&](const ObjFace& face, std::int32_t v) {
    for (std::int32_t c = face.first_corner; c < face.first_corner + face.corners; ++c) {
      if (fineOf(c) == v) return c;
    }
    return std::int32_t{-1};
  };
  const auto triangles = static_cast<std::size_t>(fine_triangles.rows());
  std::vector<std::int32_t> face_of(triangles, -1);
  Triangles corner_uvs(fine_triangles.rows(), 3);
  std::size_t unmatched = 0;
  for (std::size_t t = 0; t < triangles; ++t) {
    const auto row = static_cast<Eigen::Index>(t);
    const std::int32_t a = fine_triangles(row, 0);
    for (std::int32_t k = start[static_cast<std::size_t>(a)]; k < start[static_cast<std::size_t>(a) + 1] && face_of[t] < 0; ++k) {
      const ObjFace& face = obj->faces[static_cast<std::size_t>(list[static_cast<std::size_t>(k)])];
      std::int32_t c[3];
      for (int i = 0; i < 3; ++i) c[i] = cornerAt(face, fine_triangles(row, i));
      if (c[0] < 0 || c[1] < 0 || c[2] < 0) continue;
      face_of[t] = list[static_cast<std::size_t>(k)];
      for (int i = 0; i < 3; ++i) corner_uvs(row, i) = obj->corner_uv[static_cast<std::size_t>(c[i])];
    }
    if (face_of[t] < 0) ++unmatched;
  }
  if (unmatched > 0) {
    say("texture coordinates not kept: " + plural(unmatched, "fine triangle lies", "fine triangles lie") + " on no face of " +
        path.filename().string() + " (the surface was repaired)");
    return std::nullopt;
  }

  // The file's face order (stable within a face).
  std::vector<std::int32_t> order(triangles);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::int32_t x, std::int32_t y) { return face_of[static_cast<std::size_t>(x)] < face_of[static_cast<std::size_t>(y)]; });
  RigSurfaceAttributes out;
  const Triangles sorted_before = fine_triangles;
  out.corner_uvs.resize(fine_triangles.rows(), 3);
  out.triangle_materials.resize(triangles);
  for (std::size_t t = 0; t < triangles; ++t) {
    const auto from = static_cast<Eigen::Index>(order[t]);
    fine_triangles.row(static_cast<Eigen::Index>(t)) = sorted_before.row(from);
    out.corner_uvs.row(static_cast<Eigen::Index>(t)) = corner_uvs.row(from);
    out.triangle_materials[t] = obj->faces[static_cast<std::size_t>(face_of[static_cast<std::size_t>(from)])].material;
  }
  out.uvs.resize(static_cast<Eigen::Index>(obj->uvs.size()), 2);
  for (std::size_t i = 0; i < obj->uvs.size(); ++i) out.uvs.row(static_cast<Eigen::Index>(i)) << obj->uvs[i][0], obj->uvs[i][1];

  std::error_code ec;
  const std::filesystem::path absolute = std::filesystem::absolute(path, ec).lexically_normal();
  out.asset = !ec && isWellFormedUtf8(absolute.string()) && absolute.string().size() <= kMaxNameBytes ? absolute.string() : std::string();

  // Materials: names, then Kd and map_Kd from the first library that defines each.
  std::string material_note;
  bool keep_materials = !obj->materials.empty() && obj->materials.size() <= kMaxMaterials;
  if (obj->materials.size() > kMaxMaterials) material_note = "; " + std::to_string(obj->materials.size()) + " materials are too many: none kept";
  if (keep_materials) {
    // `mtllib` lists files separated by blanks; a line that names one existing file whole is that file.
    for (const std::string& line : obj->material_libraries) {
      std::error_code exists_ec;
      std::vector<std::string> files;
      if (std::filesystem::is_regular_file(path.parent_path() / std::filesystem::path(line), exists_ec)) {
        files.push_back(line);
      } else {
        std::string_view r = line;
        for (std::string_view token = nextToken(r); !token.empty(); token = nextToken(r)) files.emplace_back(token);
      }
      for (std::string& f : files) {
        if (std::find(out.material_libraries.begin(), out.material_libraries.end(), f) == out.material_libraries.end())
          out.material_libraries.push_back(std::move(f));
      }
    }
    for (const std::string& name : obj->materials) out.materials.push_back({name, {}, Eigen::Vector3d::Ones()});
    std::vector<char> defined(out.materials.size(), 0);
    std::vector<std::string> missing;
    for (const std::string& library : out.material_libraries) {
      bool ok = false;
      const std::filesystem::path library_path = path.parent_path() / std::filesystem::path(library);
      const std::string mtl = readSmallFile(library_path, kMaxMtlBytes, ok);
      if (!ok) {
        missing.push_back(library);
        continue;
      }
      const std::filesystem::path folder = std::filesystem::path(library).parent_path();
      for (const MtlMaterial& m : readMtl(mtl)) {
        const auto it = std::find(obj->materials.begin(), obj->materials.end(), m.name);
        if (it == obj->materials.end()) continue;
        const auto i = static_cast<std::size_t>(it - obj->materials.begin());
        if (defined[i]) continue;
        defined[i] = 1;
        if (m.diffuse_color) out.materials[i].diffuse_color = *m.diffuse_color;
        if (!m.diffuse_texture.empty()) out.materials[i].diffuse_texture = (folder / m.diffuse_texture).lexically_normal().generic_string();
      }
    }
    // Every string goes into the rig file as UTF-8 of at most 64 KiB.
    auto fits = [](const std::string& s) { return s.size() <= kMaxNameBytes && isWellFormedUtf8(s); };
    bool all_fit = std::all_of(out.material_libraries.begin(), out.material_libraries.end(), fits);
    for (const RigMaterial& m : out.materials) all_fit = all_fit && fits(m.name) && fits(m.diffuse_texture);
    if (!all_fit) {
      keep_materials = false;
      material_note = "; material names or files are not UTF-8: materials not kept";
    } else {
      const auto named = static_cast<std::size_t>(std::count(defined.begin(), defined.end(), 1));
      if (!missing.empty()) material_note += "; material library " + printableText(missing.front(), 80) + " not found";
      if (named < out.materials.size())
        material_note += "; " + plural(out.materials.size() - named, "material has", "materials have") + " no definition (name kept)";
    }
  }
  if (!keep_materials) {
    out.material_libraries.clear();
    out.materials.clear();
    std::fill(out.triangle_materials.begin(), out.triangle_materials.end(), -1);
  }
  if (out.empty()) {
    say("texture coordinates: " + path.filename().string() + " has none" + material_note);
    out.asset.clear();
    return std::nullopt;
  }
  std::size_t textured = 0;
  for (Eigen::Index f = 0; f < out.corner_uvs.rows(); ++f) textured += (out.corner_uvs.row(f).array() >= 0).all() ? 1 : 0;
  std::size_t maps = 0;
  for (const RigMaterial& m : out.materials) maps += m.diffuse_texture.empty() ? 0 : 1;
  say("texture coordinates and materials of " + path.filename().string() + " kept: " +
      plural(static_cast<std::size_t>(out.uvs.rows()), "uv", "uvs") + " on " +
      std::to_string(textured) + " of " + std::to_string(triangles) + " triangles, " + plural(out.materials.size(), "material", "materials") +
      " (" + std::to_string(maps) + " with a texture)" + material_note);
  return out;
}

}  // namespace tetrig::rigbuild
