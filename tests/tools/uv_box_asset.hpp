// A small UV-mapped OBJ asset for the export tests: the small rig's block ([0, 0.3] x [0, 0.2] x
// [0, 0.2] m, y up) as a closed surface of quads, each side with its own island in a 3 x 2 uv
// atlas (so every vertex on a box edge has several uvs: seams), two materials used side by side
// alternately ("paint": a colour; "skin": a texture, textures/skin.png, with map_Kd options) in
// box.mtl, and the OBJ features a reader must get right: quads, negative (relative) indices on one
// side, `v/vt/vn` on another, `o`, `s` and `g` lines (groups revisited). With seams = false every vertex has one uv
// (vt i is vertex i), one material. The rig is built from it with the small rig's markers
// (small_rig.hpp) and the description below.
#pragma once

#include "small_rig.hpp"

#include <array>
#include <charconv>
#include <cstdint>
#include <string>
#include <vector>

namespace tetrig::test {

struct UvBoxAsset {
  std::vector<std::array<double, 3>> vertices;       // file order
  std::vector<std::array<double, 2>> uvs;            // the vt lines, file order
  std::vector<std::vector<std::array<int, 2>>> faces;  // per face: (vertex, vt) per corner, 0-based, CCW from outside
  std::vector<std::string> face_materials;           // per face
  std::filesystem::path obj, mtl, texture;           // written files
};

// A 2 x 2 RGB PNG (valid: Blender and glTF readers load it).
inline std::vector<std::uint8_t> tinyPng() {
  return {0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00, 0x0d, 0x49, 0x48, 0x44, 0x52, 0x00, 0x00, 0x00,
          0x02, 0x00, 0x00, 0x00, 0x02, 0x08, 0x02, 0x00, 0x00, 0x00, 0xfd, 0xd4, 0x9a, 0x73, 0x00, 0x00, 0x00, 0x12, 0x49,
          0x44, 0x41, 0x54, 0x78, 0x9c, 0x63, 0xf8, 0xcf, 0xc0, 0xc0, 0x00, 0xc2, 0x0c, 0xff, 0x81, 0x00, 0x00, 0x1f, 0xee,
          0x05, 0xfb, 0x0b, 0xd9, 0x68, 0x8b, 0x00, 0x00, 0x00, 0x00, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82};
}

inline std::string shortest(double v) {
  char buf[40];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

// Writes box.obj, box.mtl and textures/skin.png into `dir`.
inline UvBoxAsset writeUvBoxAsset(const TempDir& dir, bool seams = true) {
  constexpr int n[3] = {3, 2, 2};
  constexpr double size[3] = {0.3, 0.2, 0.2};
  UvBoxAsset a;
  std::vector<int> id((n[0] + 1) * (n[1] + 1) * (n[2] + 1), -1);
  auto grid = [&](int i, int j, int k) -> int& { return id[static_cast<std::size_t>((k * (n[1] + 1) + j) * (n[0] + 1) + i)]; };
  for (int k = 0; k <= n[2]; ++k)
    for (int j = 0; j <= n[1]; ++j)
      for (int i = 0; i <= n[0]; ++i) {
        if (i != 0 && i != n[0] && j != 0 && j != n[1] && k != 0 && k != n[2]) continue;
        grid(i, j, k) = static_cast<int>(a.vertices.size());
        a.vertices.push_back({size[0] * i / n[0], size[1] * j / n[1], size[2] * k / n[2]});
      }
  // Sides: fixed axis, its end (0 or n), in-plane axes (u, w) with u x w pointing outward.
  struct Side {
    int axis, end, u, w;
  };
  const Side sides[6] = {{0, 0, 2, 1}, {0, n[0], 1, 2}, {1, 0, 0, 2}, {1, n[1], 2, 0}, {2, 0, 1, 0}, {2, n[2], 0, 1}};
  if (!seams) {
    for (const auto& p : a.vertices) a.uvs.push_back({0.1 + p[0] / size[0] * 0.8, 0.05 + (p[1] / size[1] * 0.6 + p[2] / size[2] * 0.3)});
  }
  for (int s = 0; s < 6; ++s) {
    const Side& side = sides[s];
    const int first_uv = static_cast<int>(a.uvs.size());
    const int nu = n[side.u], nw = n[side.w];
    if (seams) {
      for (int q = 0; q <= nw; ++q)
        for (int p = 0; p <= nu; ++p)
          a.uvs.push_back({(s % 3 + 0.05 + 0.9 * p / nu) / 3.0, (s / 3 + 0.05 + 0.9 * q / nw) / 2.0});
    }
    for (int q = 0; q < nw; ++q)
      for (int p = 0; p < nu; ++p) {
        std::vector<std::array<int, 2>> face;
        for (const auto& [dp, dq] : {std::pair{0, 0}, std::pair{1, 0}, std::pair{1, 1}, std::pair{0, 1}}) {
          int c[3];
          c[side.axis] = side.end;
          c[side.u] = p + dp;
          c[side.w] = q + dq;
          const int v = grid(c[0], c[1], c[2]);
          face.push_back({v, seams ? first_uv + (q + dq) * (nu + 1) + p + dp : v});
        }
        a.faces.push_back(face);
        a.face_materials.push_back(!seams || s % 2 == 1 ? "skin" : "paint");
      }
  }
  std::string obj = "# uv box for tetrig's tests\nmtllib box.mtl\no box\n";
  for (const auto& p : a.vertices) obj += "v " + shortest(p[0]) + " " + shortest(p[1]) + " " + shortest(p[2]) + "\n";
  for (const auto& t : a.uvs) obj += "vt " + shortest(t[0]) + " " + shortest(t[1]) + "\n";
  obj += "vn 0 0 1\ns 1\n";
  const int nv = static_cast<int>(a.vertices.size()), nt = static_cast<int>(a.uvs.size());
  std::string material;
  const std::size_t per_side = a.faces.size() / 6;
  for (std::size_t f = 0; f < a.faces.size(); ++f) {
    const std::size_t side = f / per_side;
    if (f % per_side == 0) obj += side % 2 == 0 ? "g even_sides\n" : "g odd_sides\n";  // groups revisited
    if (a.face_materials[f] != material) obj += "usemtl " + (material = a.face_materials[f]) + "\n";
    obj += "f";
    for (const auto& [v, t] : a.faces[f]) {
      // (appended piece by piece: GCC 12 sees a false -Wrestrict in " " + std::to_string(..))
      const bool relative = side == 5;  // relative to the lines read so far
      obj += ' ';
      obj += std::to_string(relative ? v - nv : v + 1);
      obj += '/';
      obj += std::to_string(relative ? t - nt : t + 1);
      if (side == 4) obj += "/1";
    }
    obj += "\n";
  }
  a.obj = dir.write("box.obj", obj);
  a.mtl = dir.write("box.mtl", "# two materials\nnewmtl paint\nKd 0.8 0.1 0.1\nnewmtl skin\nKd 1 1 1\nmap_Kd -s 1 1 1 textures/skin.png\n");
  std::filesystem::create_directories(dir.path() / "textures");
  a.texture = dir.writeBytes("textures/skin.png", tinyPng());
  return a;
}

inline std::string uvBoxRigJson() {
  return R"({ "format": "tetrig-rig", "version": 1, "name": "uv box", "mesh_unit": "m", "mesh_up": "y", "tet_vertices": 150,
  "markers": { "device_up": "y", "alignment": "units", "max_distance": 0.05, "faces_per_marker": 3 } })";
}

inline Rig buildUvBoxRig(const TempDir& dir, const UvBoxAsset& asset, rigbuild::BuildRigReport* report = nullptr) {
  rigbuild::BuildRigInputs in;
  in.mesh = asset.obj;
  in.description = rigbuild::parseRigDescription(uvBoxRigJson(), dir.path() / "uv.json");
  in.clip = writeSmallClip(dir, "uv_rest.c3d");
  return rigbuild::buildRig(in, report);
}

}  // namespace tetrig::test
