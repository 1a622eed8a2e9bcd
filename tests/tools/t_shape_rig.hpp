// A T-shaped body made from generated data, for the marker alignment checks and --frame auto
// without the real data: a "T-pose" tet mesh (voxels of 0.1 m, Kuhn subdivision: a torso 0.4 m
// wide and 1.8 m tall, arms spanning 1.8 m at shoulder height 1.3-1.5 m, 0.2 m deep; metres,
// y up) and marker sets 1.5 cm off its faces in two poses: arms out (the mesh's pose) and arms
// down beside the torso. Clips are written in device millimetres, z up, shifted, like a capture.
#pragma once

#include "small_rig.hpp"

#include <Eigen/Core>

#include <array>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace tetrig::test {

// Writes NAME.node / NAME.ele of the T (coordinates times `scale`, e.g. 100 for centimetres);
// returns the .node path.
inline std::filesystem::path writeTTetMesh(const TempDir& dir, const std::string& name, double scale = 1.0) {
  auto filled = [](int i, int j, int k) {
    if (k < -1 || k >= 1 || j < 0 || j >= 18) return false;
    const bool torso = i >= -2 && i < 2;
    const bool arms = j >= 13 && j < 15 && i >= -9 && i < 9;
    return torso || arms;
  };
  std::map<std::array<int, 3>, int> ids;
  std::string node_lines;
  auto vertex = [&](int i, int j, int k) {
    const std::array<int, 3> key{i, j, k};
    const auto it = ids.find(key);
    if (it != ids.end()) return it->second;
    const int id = static_cast<int>(ids.size());
    ids.emplace(key, id);
    node_lines += std::to_string(id) + " " + std::to_string(0.1 * i * scale) + " " + std::to_string(0.1 * j * scale) + " " +
                  std::to_string(0.1 * k * scale) + "\n";
    return id;
  };
  std::string ele_lines;
  int tets = 0;
  const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  for (int k = -1; k < 1; ++k) {
    for (int j = 0; j < 18; ++j) {
      for (int i = -9; i < 9; ++i) {
        if (!filled(i, j, k)) continue;
        for (const auto& p : perms) {  // six tets around the cell diagonal (conforming across cells)
          int c[3] = {i, j, k};
          int t[4];
          t[0] = vertex(i, j, k);
          for (int s = 0; s < 3; ++s) {
            ++c[p[s]];
            t[s + 1] = vertex(c[0], c[1], c[2]);
          }
          ele_lines += std::to_string(tets++) + " " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) + " " +
                       std::to_string(t[3]) + "\n";
        }
      }
    }
  }
  dir.write(name + ".ele", std::to_string(tets) + " 4 0\n" + ele_lines);
  return dir.write(name + ".node", std::to_string(ids.size()) + " 3 0 0\n" + node_lines);
}

using LabelledPoints = std::vector<std::pair<std::string, Eigen::Vector3d>>;

// Markers in the mesh's pose (rig metres, y up), each 1.5 cm off a face of the T.
inline LabelledPoints tPoseMarkers() {
  return {{"HEAD", {0.0, 1.815, 0.05}},   {"LHND", {-0.915, 1.40, 0.0}}, {"RHND", {0.915, 1.40, 0.0}},  {"LELB", {-0.55, 1.515, 0.0}},
          {"RELB", {0.55, 1.515, 0.0}},   {"LSHO", {-0.25, 1.515, 0.05}}, {"RSHO", {0.25, 1.515, 0.05}}, {"CHST", {0.0, 1.1, 0.115}},
          {"BACK", {0.05, 1.0, -0.115}},  {"LHIP", {-0.215, 0.9, 0.0}},  {"RHIP", {0.215, 0.9, 0.0}},   {"LKNE", {-0.1, 0.5, 0.115}},
          {"RKNE", {0.1, 0.5, 0.115}},    {"LANK", {-0.215, 0.08, 0.0}}, {"RANK", {0.215, 0.08, 0.0}},  {"LTOE", {-0.1, 0.03, 0.115}},
          {"RTOE", {0.1, 0.03, 0.115}}};
}

// The same markers with the arms hanging beside the torso (not the mesh's pose).
inline LabelledPoints armsDownMarkers() {
  LabelledPoints m = tPoseMarkers();
  const std::map<std::string, Eigen::Vector3d> arms = {{"LSHO", {-0.3, 1.45, 0.0}}, {"RSHO", {0.3, 1.45, 0.0}}, {"LELB", {-0.3, 1.15, 0.0}},
                                                       {"RELB", {0.3, 1.15, 0.0}},  {"LHND", {-0.3, 0.85, 0.0}}, {"RHND", {0.3, 0.85, 0.0}}};
  for (auto& [label, p] : m) {
    if (arms.count(label)) p = arms.at(label);
  }
  return m;
}

// A clip (device mm, z up: device = 1000 (x, -z, y) * body_scale + a shift) with one frame per
// entry of `frames`; frame f's markers are moved by a deterministic +-1 mm jitter.
inline std::filesystem::path writeTClip(const TempDir& dir, const std::string& name, const std::vector<LabelledPoints>& frames,
                                        double body_scale = 1.0) {
  TestC3DSpec spec;
  spec.floating = true;
  spec.scale = 1.0f;
  spec.rate = 100.0f;
  spec.frames = frames.size();
  for (const auto& [label, p] : frames.front()) spec.labels.push_back(label);
  const Eigen::Vector3d shift(420.0, -1300.0, 15.0);
  for (std::size_t f = 0; f < frames.size(); ++f) {
    for (std::size_t m = 0; m < frames[f].size(); ++m) {
      const Eigen::Vector3d& p = frames[f][m].second;
      const double jitter = static_cast<double>(static_cast<int>((f * 7 + m * 3) % 3) - 1);
      const Eigen::Vector3d d = 1000.0 * body_scale * Eigen::Vector3d(p.x(), -p.z(), p.y()) + shift + Eigen::Vector3d::Constant(jitter);
      spec.xyz.push_back({static_cast<float>(d.x()), static_cast<float>(d.y()), static_cast<float>(d.z())});
      spec.valid.push_back(true);
    }
  }
  return dir.writeBytes(name, writeTestC3D(spec));
}

}  // namespace tetrig::test
