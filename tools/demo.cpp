// `tetrig demo`: drives the project's own demo bar (assets/bar_4x4x33.{node,ele}) through a
// scripted motion -- the far end twists a full turn while swinging sideways -- with oriented
// region handles on both ends, so rotation extraction, rotation interpolation and the
// deadline-bounded frame step all run. Reports per-frame step latency; optionally writes the
// final surface as OBJ (atomically: temporary file, then rename).
#include "demo.hpp"

#include "tetrig/deformer.hpp"
#include "tetrig/tet_mesh_io.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <stdexcept>
#include <vector>

namespace tetrig::tools {

namespace {

std::filesystem::path assetsDir() {
  if (const char* env = std::getenv("TETRIG_ASSETS_DIR"); env != nullptr && env[0] != '\0') return env;
  return TETRIG_ASSETS_DIR;
}

// Boundary faces of a tet mesh (faces used by exactly one tet), oriented outwards.
std::vector<std::array<std::int32_t, 3>> boundaryFaces(const TetMesh& mesh) {
  std::map<std::array<std::int32_t, 3>, std::pair<int, std::array<std::int32_t, 3>>> faces;
  static constexpr int kFace[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};  // outward for positive tets
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    for (const auto& f : kFace) {
      std::array<std::int32_t, 3> oriented{mesh.tets(t, f[0]), mesh.tets(t, f[1]), mesh.tets(t, f[2])};
      auto key = oriented;
      std::sort(key.begin(), key.end());
      auto& entry = faces[key];
      ++entry.first;
      entry.second = oriented;
    }
  }
  std::vector<std::array<std::int32_t, 3>> out;
  for (const auto& [key, entry] : faces)
    if (entry.first == 1) out.push_back(entry.second);
  return out;
}

void writeObjAtomically(const std::filesystem::path& path, std::span<const double> positions,
                        const std::vector<std::array<std::int32_t, 3>>& faces) {
  const std::filesystem::path tmp = path.string() + ".tmp";
  {
    std::ofstream out(tmp);
    if (!out) throw std::runtime_error("cannot write " + tmp.string());
    out << "# tetrig demo: deformed bar surface\n";
    for (size_t i = 0; i < positions.size(); i += 3)
      out << "v " << positions[i] << ' ' << positions[i + 1] << ' ' << positions[i + 2] << '\n';
    for (const auto& f : faces) out << "f " << f[0] + 1 << ' ' << f[1] + 1 << ' ' << f[2] + 1 << '\n';
    if (!out.flush()) throw std::runtime_error("write failed: " + tmp.string());
  }
  std::filesystem::rename(tmp, path);
}

double percentile(std::vector<double> values, double p) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const auto i = static_cast<size_t>(std::clamp(p, 0.0, 1.0) * static_cast<double>(values.size() - 1));
  return values[i];
}

}  // namespace

int runDemo(const DemoOptions& options) {
  if (options.frames < 1 || options.iterations < 1 || !(options.frame_budget_ms > 0.0)) {
    std::fprintf(stderr, "tetrig demo: error: --frames and --iterations must be >= 1 and --budget-ms > 0\n");
    return 2;
  }
  const std::filesystem::path node = assetsDir() / "bar_4x4x33.node";
  TetMesh mesh;
  try {
    mesh = readTetGen(node);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tetrig demo: error: %s (set TETRIG_ASSETS_DIR to the repository's assets/ folder)\n",
                 e.what());
    return 1;
  }
  // Handles: the tets within the first and last 5 % of the bar's length (along z).
  const double z_min = mesh.vertices.col(2).minCoeff(), z_max = mesh.vertices.col(2).maxCoeff();
  const double length = z_max - z_min;
  RegionHandle near, far;
  for (std::int32_t t = 0; t < mesh.tetCount(); ++t) {
    bool all_near = true, all_far = true;
    for (int c = 0; c < 4; ++c) {
      const double z = mesh.vertices(mesh.tets(t, c), 2);
      all_near = all_near && z <= z_min + 0.05 * length + 1e-9;
      all_far = all_far && z >= z_max - 0.05 * length - 1e-9;
    }
    if (all_near) near.tets.push_back(t);
    if (all_far) far.tets.push_back(t);
  }
  DeformerSetup setup;
  setup.region_handles = {near, far};
  Deformer deformer(mesh, setup);
  const Eigen::Vector3d axis(0.5 * (mesh.vertices.col(0).minCoeff() + mesh.vertices.col(0).maxCoeff()),
                             0.5 * (mesh.vertices.col(1).minCoeff() + mesh.vertices.col(1).maxCoeff()), z_max);

  std::vector<RigidTransform> transforms(2);
  HandleTargets targets;
  targets.region_transforms = transforms;
  std::vector<double> step_ms;
  step_ms.reserve(static_cast<size_t>(options.frames));
  long iterations = 0, deadline_hits = 0;
  StepStats last;
  for (int frame = 1; frame <= options.frames; ++frame) {
    const double phase = static_cast<double>(frame) / options.frames;
    // Far end: a full turn about the bar's axis, swinging sideways by up to a quarter length.
    const Eigen::Quaterniond twist(Eigen::AngleAxisd(2.0 * M_PI * phase, Eigen::Vector3d::UnitZ()));
    const Eigen::Vector3d swing(0.25 * length * std::sin(2.0 * M_PI * phase), 0.0, 0.0);
    transforms[1].rotation = twist;
    transforms[1].translation = axis - (twist * axis) + swing;
    StepBudget budget{options.iterations,
                      std::chrono::steady_clock::now() +
                          std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                              std::chrono::duration<double, std::milli>(options.frame_budget_ms))};
    last = deformer.step(targets, budget);
    step_ms.push_back(static_cast<double>(last.total_ns) * 1e-6);
    iterations += last.iterations;
    if (last.flags & kStepDeadlineHit) ++deadline_hits;
  }
  for (double p : deformer.positions()) {
    if (!std::isfinite(p)) {
      std::fprintf(stderr, "tetrig demo: error: non-finite position produced (a bug: please report)\n");
      return 3;
    }
  }
  if (!options.quiet) {
    std::printf("tetrig demo: %d V / %d tets, %d frames, up to %d iterations and %.2f ms per frame\n",
                mesh.vertexCount(), mesh.tetCount(), options.frames, options.iterations, options.frame_budget_ms);
    std::printf("  step time: median %.3f ms, p99 %.3f ms, max %.3f ms; %.2f iterations/frame; deadline hit in %ld "
                "frames\n",
                percentile(step_ms, 0.5), percentile(step_ms, 0.99), percentile(step_ms, 1.0),
                static_cast<double>(iterations) / options.frames, deadline_hits);
    std::printf("  final energy %.4g (sum of vol * ||F - R||^2), factor %lld non-zeros\n", last.energy,
                static_cast<long long>(deformer.factorNonZeros()));
  }
  if (!options.out_obj.empty()) {
    try {
      writeObjAtomically(options.out_obj, deformer.positions(), boundaryFaces(mesh));
    } catch (const std::exception& e) {
      std::fprintf(stderr, "tetrig demo: error: %s\n", e.what());
      return 1;
    }
    if (!options.quiet) std::printf("  wrote %s\n", options.out_obj.c_str());
  }
  return 0;
}

}  // namespace tetrig::tools
