// The accuracy cost of capping the pose-transfer rows: two rig files that differ only in B (the
// same mesh, clip and settings, one built with "pose_transfer": {"max_nonzeros_per_row": N}), both
// driven through LiveRig::processFrame by every frame of a C3D clip (3 iterations per frame, no
// deadline: both deform identically), compared fine vertex by fine vertex. FULL's pose transfer
// uses the rig's double B as stored; CAPPED's the live rig's default, B's compact copy (float
// weights, 16-bit columns). Given the same rig twice, it measures what the compact copy alone costs.
//   build/release/tetrig_pose_cap_error FULL.rig CAPPED.rig CLIP.c3d
// bench/latency.sh --cap N builds both rigs and runs it.
#include "tetrig/drivers/c3d_playback.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/rig_file.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <memory>
#include <vector>

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: tetrig_pose_cap_error FULL.rig CAPPED.rig CLIP.c3d\n");
    return 2;
  }
  try {
    const tetrig::Rig full = tetrig::loadRigFile(argv[1]);
    const tetrig::Rig capped = tetrig::loadRigFile(argv[2]);
    if (full.tet_mesh.vertices != capped.tet_mesh.vertices || full.fine_vertices != capped.fine_vertices) {
      std::fprintf(stderr, "tetrig_pose_cap_error: the rigs differ in more than B (tet or fine vertices)\n");
      return 1;
    }
    const auto clip = tetrig::drivers::C3DClip::load(argv[3]);
    tetrig::drivers::C3DPlaybackOptions options;
    options.pacing = tetrig::drivers::Pacing::kAsFastAsPossible;
    const tetrig::drivers::C3DPlayback playback(clip, options);
    std::vector<std::string> labels(static_cast<std::size_t>(clip.pointCount()));
    for (const int p : playback.selectedPoints()) labels[static_cast<std::size_t>(p)] = clip.labels()[static_cast<std::size_t>(p)];
    tetrig::LiveRigOptions reference_options;
    reference_options.compact_pose_transfer = false;
    tetrig::LiveRig a(full, reference_options), b(capped);
    a.bindLabels(labels);
    b.bindLabels(labels);
    const std::size_t n = static_cast<std::size_t>(a.fineVertexCount()) * 3;
    std::vector<float> xa(n), xb(n);
    auto frame = std::make_unique<tetrig::MarkerFrame>();
    double sum2 = 0.0;
    std::size_t count = 0;
    std::vector<double> frame_max;
    for (std::size_t k = 0; k < clip.frameCount(); ++k) {
      playback.fillFrame(k, k, *frame);
      a.processFrame(*frame, tetrig::StepBudget{3}, xa.data(), nullptr);
      b.processFrame(*frame, tetrig::StepBudget{3}, xb.data(), nullptr);
      double worst = 0.0;
      for (std::size_t i = 0; i < n; i += 3) {
        const double dx = xa[i] - xb[i], dy = xa[i + 1] - xb[i + 1], dz = xa[i + 2] - xb[i + 2];
        const double d2 = dx * dx + dy * dy + dz * dz;
        worst = std::max(worst, std::sqrt(d2));
        sum2 += d2;
        ++count;
      }
      frame_max.push_back(worst);
    }
    std::sort(frame_max.begin(), frame_max.end());
    const auto at = [&frame_max](double q) { return frame_max[static_cast<std::size_t>(q * static_cast<double>(frame_max.size() - 1))]; };
    std::printf("B %.1f -> %.1f entries per row; fine-vertex difference over %zu frames (rig units): RMS %.6g, per-frame max: median %.6g, p99 %.6g, max %.6g\n",
                static_cast<double>(full.pose_transfer.nonzeros()) / full.pose_transfer.rows,
                static_cast<double>(capped.pose_transfer.nonzeros()) / capped.pose_transfer.rows, clip.frameCount(),
                std::sqrt(sum2 / static_cast<double>(count)), at(0.5), at(0.99), frame_max.back());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tetrig_pose_cap_error: %s\n", e.what());
    return 1;
  }
  return 0;
}
