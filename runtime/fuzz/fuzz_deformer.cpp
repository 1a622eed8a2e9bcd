// libFuzzer target for the deformation core's load step and frame step (tetrig::Deformer).
//
// The input bytes build a small bar of cubes (scenes::makeBarScene, tests/support: 5 tets per
// cube), jitter its vertices (slivers and inverted tets included, sometimes a raw
// double: NaN, infinity, huge), choose vertex, region and point handles, rigid groups, stiffness
// and options, then drive step() with targets read from the rest of the input (again sometimes
// raw doubles: rejected targets, and absurd but finite moves).
//
// Contract checked: the constructor either succeeds or throws std::invalid_argument (bad setup)
// or std::runtime_error (a part without a handle); step() never publishes a non-finite position,
// reports a finite energy, runs 1..max_iterations iterations, and flags rejected targets. Any
// other exception, a crash, a trap or a sanitizer report is a bug.
// Build: cmake --preset fuzz && cmake --build --preset fuzz;
// run:   build/fuzz/runtime/fuzz_deformer -max_total_time=300 [corpus dir].
#include "scenes.hpp"
#include "tetrig/deformer.hpp"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <vector>

namespace {

class Bytes {
 public:
  Bytes(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  bool empty() const { return pos_ >= size_; }
  std::uint8_t byte() { return pos_ < size_ ? data_[pos_++] : 0; }
  // In [-1, 1].
  double signedUnit() { return (static_cast<double>(byte()) - 127.5) / 127.5; }
  double rawDouble() {
    std::uint8_t b[8];
    for (auto& v : b) v = byte();
    double d;
    std::memcpy(&d, b, sizeof d);
    return d;
  }
  // Mostly a small offset; 1 in 32 a raw double (NaN, infinity, huge, denormal).
  double coordinate(double rest, double scale) {
    const std::uint8_t mode = byte();
    if (mode < 8) return rawDouble();
    return rest + scale * signedUnit();
  }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t pos_ = 0;
};

void requireFinitePositions(const tetrig::Deformer& deformer) {
  for (const double p : deformer.positions())
    if (!std::isfinite(p)) __builtin_trap();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Bytes in(data, size);
  const int nx = 1 + in.byte() % 3, ny = 1 + in.byte() % 2, nz = 1 + in.byte() % 4;
  tetrig::TetMesh mesh = tetrig::scenes::makeBarScene(nx, ny, nz).mesh;
  const std::int32_t vertex_count = mesh.vertexCount(), tet_count = mesh.tetCount();

  // Jitter: 0, a little, up to half a cube (slivers, inversions), or far.
  static constexpr double kJitter[4] = {0.0, 0.05, 0.5, 3.0};
  const double jitter = kJitter[in.byte() % 4];
  if (jitter > 0.0)
    for (std::int32_t v = 0; v < vertex_count; ++v)
      for (int c = 0; c < 3; ++c) mesh.vertices(v, c) = in.coordinate(mesh.vertices(v, c), jitter);

  tetrig::DeformerSetup setup;
  const std::uint8_t flags = in.byte();
  setup.options.update_rotations = (flags & 1u) == 0;
  setup.options.interpolate_rotations = (flags & 2u) == 0;
  static constexpr double kVolumeWeight[4] = {0.0, 0.0, 0.5, 0.95};  // the volume term on half the inputs
  setup.options.volume_weight = kVolumeWeight[(flags >> 2) & 3u];
  static constexpr double kGuard[4] = {0.0, 0.0, 0.5, 1.0};  // the inversion guard on half the inputs
  setup.options.inversion_guard = kGuard[(flags >> 4) & 3u];
  setup.options.inversion_guard_threshold = (flags & 64u) != 0 ? 0.9 : 0.5;
  setup.options.rotation_steps = static_cast<int>(in.byte() % 6);
  // Handles: each vertex free, a vertex handle, or (rarely) claimed twice.
  for (std::int32_t v = 0; v < vertex_count; ++v) {
    const std::uint8_t role = in.byte() % 8;
    if (role == 1) setup.vertex_handles.push_back(v);
    if (role == 2 && !setup.vertex_handles.empty()) setup.vertex_handles.push_back(setup.vertex_handles.front());
  }
  const int region_count = in.byte() % 3;
  for (int r = 0; r < region_count; ++r) {
    tetrig::RegionHandle region;
    region.oriented = (in.byte() & 1u) != 0;
    const int n = in.byte() % 4;
    for (int i = 0; i < n; ++i) region.tets.push_back(static_cast<std::int32_t>(in.byte()) % (tet_count + 1));
    setup.region_handles.push_back(region);
  }
  const int point_count = in.byte() % 3;
  for (int p = 0; p < point_count; ++p) {
    tetrig::PointHandle point;
    point.tet = static_cast<std::int32_t>(in.byte()) % (tet_count + 1);
    for (int c = 0; c < 4; ++c) point.barycentric[c] = static_cast<double>(in.byte());
    const double sum = point.barycentric.sum();
    if (sum > 0.0 && (in.byte() & 1u) != 0) point.barycentric /= sum;  // else (mostly) not summing to 1
    setup.point_handles.push_back(point);
  }
  const int group_count = in.byte() % 3;
  for (int g = 0; g < group_count; ++g) {
    tetrig::RigidGroup group;
    const int n = in.byte() % 5;
    for (int i = 0; i < n; ++i) group.tets.push_back(static_cast<std::int32_t>(in.byte()) % tet_count);
    setup.rigid_groups.push_back(group);
  }
  if ((in.byte() & 3u) == 0) {
    for (std::int32_t t = 0; t < tet_count; ++t) setup.stiffness.push_back(in.byte() < 4 ? in.rawDouble() : 0.1 + in.byte());
  }
  if ((flags & 128u) != 0) {  // per-tet volume weights (a rig's volume regions), rarely out of [0, 1) or of the wrong count
    const std::int32_t n = tet_count + (in.byte() == 0 ? 1 : 0);
    for (std::int32_t t = 0; t < n; ++t) setup.volume_weights.push_back(in.byte() < 4 ? in.rawDouble() : in.byte() / 256.0);
  }

  std::unique_ptr<tetrig::Deformer> deformer;
  try {
    deformer = std::make_unique<tetrig::Deformer>(mesh, setup);
  } catch (const std::invalid_argument&) {
    return 0;
  } catch (const std::runtime_error&) {
    return 0;
  }
  requireFinitePositions(*deformer);

  std::vector<Eigen::Vector3d> vertex_targets(setup.vertex_handles.size());
  std::vector<tetrig::RigidTransform> region_targets(setup.region_handles.size());
  std::vector<Eigen::Vector3d> point_targets(setup.point_handles.size());
  for (int frame = 0; frame < 6 && !in.empty(); ++frame) {
    const double scale = kJitter[in.byte() % 4] + 0.1;
    for (size_t h = 0; h < vertex_targets.size(); ++h) {
      const auto v = static_cast<Eigen::Index>(setup.vertex_handles[h]);
      for (int c = 0; c < 3; ++c) vertex_targets[h][c] = in.coordinate(mesh.vertices(v, c), scale);
    }
    for (auto& t : region_targets) {
      t.rotation = Eigen::Quaterniond(in.signedUnit(), in.signedUnit(), in.signedUnit(), in.signedUnit());
      if (in.byte() < 8) t.rotation.w() = in.rawDouble();
      for (int c = 0; c < 3; ++c) t.translation[c] = in.coordinate(0.0, scale);
    }
    for (auto& p : point_targets)
      for (int c = 0; c < 3; ++c) p[c] = in.coordinate(1.0, scale);
    tetrig::HandleTargets targets;
    targets.vertex_positions = vertex_targets;
    targets.region_transforms = region_targets;
    targets.point_positions = point_targets;
    tetrig::StepBudget budget;
    budget.max_iterations = 1 + in.byte() % 8;
    const tetrig::StepStats stats = deformer->step(targets, budget);
    requireFinitePositions(*deformer);
    if (stats.iterations < 1 || stats.iterations > budget.max_iterations) __builtin_trap();
    if (setup.options.update_rotations && !std::isfinite(stats.energy)) __builtin_trap();
    if ((stats.flags & tetrig::kStepTargetsWrongSize) != 0) __builtin_trap();  // sizes always match here
  }
  return 0;
}
