// A small rig made from generated data: a block tet mesh (.node/.ele, Kuhn subdivision of a grid),
// a C3D clip with markers just outside its faces and a rig description using every selection
// kind. Fast enough for truncation sweeps at every length.
#pragma once

#include "../drivers/c3d_test_writer.hpp"
#include "temp_dir.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/build_rig.hpp"

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace tetrig::test {

// Block [0, 0.3] x [0, 0.2] x [0, 0.2] (metres, y up) on an n_x x n_y x n_z grid of cells, six
// tets per cell (Kuhn subdivision). Writes NAME.node and NAME.ele, returns the .node path.
inline std::filesystem::path writeBlockTetMesh(const TempDir& dir, const std::string& name, int nx = 3, int ny = 2, int nz = 2) {
  const double sx = 0.3 / nx, sy = 0.2 / ny, sz = 0.2 / nz;
  auto id = [&](int i, int j, int k) { return (k * (ny + 1) + j) * (nx + 1) + i; };
  std::string node = std::to_string((nx + 1) * (ny + 1) * (nz + 1)) + " 3 0 0\n";
  for (int k = 0; k <= nz; ++k) {
    for (int j = 0; j <= ny; ++j) {
      for (int i = 0; i <= nx; ++i) {
        node += std::to_string(id(i, j, k)) + " " + std::to_string(i * sx) + " " + std::to_string(j * sy) + " " +
                std::to_string(k * sz) + "\n";
      }
    }
  }
  std::vector<std::array<int, 4>> tets;
  for (int k = 0; k < nz; ++k) {
    for (int j = 0; j < ny; ++j) {
      for (int i = 0; i < nx; ++i) {
        const int v000 = id(i, j, k), v111 = id(i + 1, j + 1, k + 1);
        // Six tets around the diagonal v000-v111, one per permutation of the axes.
        const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
        for (const auto& p : perms) {
          int c[3] = {i, j, k};
          std::array<int, 4> t{};
          t[0] = v000;
          for (int s = 0; s < 3; ++s) {
            ++c[p[s]];
            t[static_cast<std::size_t>(s + 1)] = id(c[0], c[1], c[2]);
          }
          (void)v111;
          tets.push_back(t);  // orientation fixed by the builder (inverted tets are re-oriented)
        }
      }
    }
  }
  std::string ele = std::to_string(tets.size()) + " 4 0\n";
  for (std::size_t t = 0; t < tets.size(); ++t) {
    ele += std::to_string(t) + " " + std::to_string(tets[t][0]) + " " + std::to_string(tets[t][1]) + " " + std::to_string(tets[t][2]) +
           " " + std::to_string(tets[t][3]) + "\n";
  }
  dir.write(name + ".ele", ele);
  return dir.write(name + ".node", node);
}

// Markers (device mm, y up like the block) 1-2 cm outside the block's faces.
inline std::vector<std::array<float, 3>> smallMarkerPositionsMm() {
  return {{150.f, 215.f, 100.f}, {-12.f, 100.f, 100.f}, {312.f, 120.f, 80.f}, {150.f, 100.f, 215.f}, {100.f, 60.f, -15.f}};
}

inline std::filesystem::path writeSmallClip(const TempDir& dir, const std::string& name = "small.c3d") {
  TestC3DSpec spec;
  spec.floating = true;
  spec.scale = 1.0f;
  spec.rate = 100.0f;
  spec.frames = 2;
  spec.labels = {"TOP", "LEFT", "RIGHT", "FRONT", "BACK"};
  for (std::size_t f = 0; f < spec.frames; ++f) {
    for (const auto& p : smallMarkerPositionsMm()) {
      spec.xyz.push_back(p);
      spec.valid.push_back(true);
    }
  }
  return dir.writeBytes(name, writeTestC3D(spec));
}

// Rig description exercising every selection kind: a region by box (bottom), a rigid group by
// sphere, stiffness by near_marker, a point handle; markers aligned by units only (y up, mm -> m).
inline std::string smallRigJson() {
  return R"({
  "format": "tetrig-rig", "version": 1, "name": "small block",
  "mesh_unit": "m", "mesh_up": "y",
  "region_handles": [ { "name": "floor", "select": { "box": { "min": [-1, -0.01, -1], "max": [1, 0.01, 1] }, "min_corners": 3 }, "oriented": true } ],
  "rigid_groups": [ { "name": "core", "select": { "sphere": { "center": [0.15, 0.1, 0.1], "radius": 0.08 }, "min_corners": 2 } } ],
  "stiffness": [ { "name": "soft top", "select": { "near_marker": "TOP", "radius": 0.12, "min_corners": 1 }, "value": 0.5 } ],
  "point_handles": [ { "name": "inside", "position": [0.2, 0.12, 0.1] } ],
  "markers": { "device_up": "y", "alignment": "units", "max_distance": 0.05, "faces_per_marker": 3, "invisible_stiffness": 0.1 }
})";
}

inline Rig buildSmallRig(const TempDir& dir, rigbuild::BuildRigReport* report = nullptr, double max_distance = 0.0) {
  rigbuild::BuildRigInputs in;
  in.mesh = writeBlockTetMesh(dir, "block");
  in.description = rigbuild::parseRigDescription(smallRigJson(), dir.path() / "small.json");
  in.clip = writeSmallClip(dir);
  if (max_distance > 0) in.max_marker_distance = max_distance;
  return rigbuild::buildRig(in, report);
}

}  // namespace tetrig::test
