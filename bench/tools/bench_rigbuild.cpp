// Rig builder benchmarks on the 43k-vertex Armadillo (../shared/data/meshes/libigl-tutorial-data):
//   BM_BuildRig/armadillo43k            import + validate + decimate (2500 V) + self-intersection
//                                       repair + TetGen + pose-transfer weights B
//   BM_PoseTransferWeights/armadillo43k B alone (r = 5 % of the diagonal, no cap)
//   BM_PoseTransfer/armadillo43k        per-frame x_fine = B x_tet (runtime, float weights,
//                                       double tet positions in, float vertices out)
#include "bench_data.hpp"

#include "tetrig/pose_transfer.hpp"
#include "tetrig/rigbuild/import_surface.hpp"
#include "tetrig/rigbuild/pose_transfer_weights.hpp"
#include "tetrig/rigbuild/rig_geometry.hpp"
#include "tetrig/rigbuild/tetrahedralize_surface.hpp"
#include "tetrig/rigbuild/validate_surface.hpp"

#include <benchmark/benchmark.h>

#include <sys/resource.h>

#include <memory>
#include <string>

namespace {

using namespace tetrig::rigbuild;

constexpr std::int32_t kTetVertexBudget = 2500;

struct ArmadilloRig {
  SurfaceMesh fine;
  CoarseRig coarse;
  Eigen::SparseMatrix<double, Eigen::RowMajor> b;
  Eigen::SparseMatrix<double, Eigen::RowMajor> b_cap16;  // at most 16 non-zeros per row (whole tets)
  PoseTransferStats stats;
};

// Built once, shared by the benchmarks that only time one step. Null when the data is absent.
const ArmadilloRig* armadilloRig(const std::string& relative, std::string& error) {
  return tetrig::bench::buildOnce<ArmadilloRig>(
      [&] {
        const auto path = tetrig::bench::requireBenchData(relative);
        auto r = std::make_unique<ArmadilloRig>();
        r->fine = importSurface(path);
        requireUsableSurface(validateSurface(r->fine), path.string());
        DecimateOptions d;
        d.target_vertices = kTetVertexBudget;
        r->coarse = buildCoarseTetMesh(r->fine, d);
        r->b = poseTransferWeights(r->fine.vertices, r->coarse.tets.mesh, {}, &r->stats);
        PoseTransferOptions cap;
        cap.max_nonzeros_per_row = 16;
        cap.cap_mode = WeightCap::kDropFarTets;
        r->b_cap16 = poseTransferWeights(r->fine.vertices, r->coarse.tets.mesh, cap);
        return r;
      },
      error);
}

void BM_BuildRig(benchmark::State& state, const char* relative) {
  const auto path = tetrig::bench::benchDataPath(relative);
  if (!std::filesystem::exists(path)) {
    state.SkipWithError(tetrig::bench::benchDataMissing(path).c_str());
    return;
  }
  std::int32_t tets = 0;
  std::int32_t tet_vertices = 0;
  double nnz_per_row = 0.0;
  RigGeometryOptions options;
  options.decimate.target_vertices = kTetVertexBudget;
  // TetGen runs in child processes (see tetrahedralize_surface.hpp): their CPU time is reported
  // separately, since the benchmark's CPU column counts this process only.
  auto childCpuSeconds = [] {
    rusage usage{};
    getrusage(RUSAGE_CHILDREN, &usage);
    return static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
           1e-6 * static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
  };
  const double child_cpu_start = childCpuSeconds();
  for (auto _ : state) {
    try {
      const RigGeometry g = buildRigGeometry(path, options);
      benchmark::DoNotOptimize(g.b.nonZeros());
      tets = g.coarse.tets.mesh.tetCount();
      tet_vertices = g.coarse.tets.mesh.vertexCount();
      nnz_per_row = g.b_stats.mean_nonzeros_per_row;
    } catch (const std::exception& e) {
      state.SkipWithError(e.what());
      return;
    }
  }
  state.counters["tetgen_child_cpu_s"] = (childCpuSeconds() - child_cpu_start) / static_cast<double>(state.iterations());
  state.counters["tets"] = tets;
  state.counters["tet_vertices"] = tet_vertices;
  state.counters["B_nnz_per_row"] = nnz_per_row;
}
BENCHMARK_CAPTURE(BM_BuildRig, armadillo43k, "meshes/libigl-tutorial-data/armadillo.obj")
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_PoseTransferWeights(benchmark::State& state, const char* relative) {
  std::string error;
  const ArmadilloRig* rig = armadilloRig(relative, error);
  if (rig == nullptr) {
    state.SkipWithError(error.c_str());
    return;
  }
  PoseTransferStats stats;
  for (auto _ : state) {
    const auto b = poseTransferWeights(rig->fine.vertices, rig->coarse.tets.mesh, {}, &stats);
    benchmark::DoNotOptimize(b.nonZeros());
  }
  state.counters["B_nnz_per_row"] = stats.mean_nonzeros_per_row;
  state.counters["fine_vertices"] = static_cast<double>(rig->fine.vertexCount());
}
BENCHMARK_CAPTURE(BM_PoseTransferWeights, armadillo43k, "meshes/libigl-tutorial-data/armadillo.obj")
    ->Unit(benchmark::kMillisecond);

void BM_PoseTransfer(benchmark::State& state, const char* relative, bool capped) {
  std::string error;
  const ArmadilloRig* rig = armadilloRig(relative, error);
  if (rig == nullptr) {
    state.SkipWithError(error.c_str());
    return;
  }
  const tetrig::PoseTransferCsr<float> csr = tetrig::makePoseTransferCsr<float>(capped ? rig->b_cap16 : rig->b);
  const auto view = csr.view();
  const tetrig::Vertices& x_tet = rig->coarse.tets.mesh.vertices;  // #tetV by 3, row-major double
  std::vector<float> x_fine(static_cast<size_t>(rig->fine.vertexCount()) * 3);
  for (auto _ : state) {
    tetrig::applyPoseTransfer(view, x_tet.data(), x_fine.data());
    benchmark::DoNotOptimize(x_fine.data());
    benchmark::ClobberMemory();
  }
  state.counters["B_bytes_per_fine_vertex"] = static_cast<double>(csr.bytes()) / rig->fine.vertexCount();
  state.counters["B_nnz_per_row"] = static_cast<double>(csr.nonzeros()) / rig->fine.vertexCount();
  state.counters["fine_vertices"] = static_cast<double>(rig->fine.vertexCount());
  state.SetItemsProcessed(state.iterations() * rig->fine.vertexCount());
}
BENCHMARK_CAPTURE(BM_PoseTransfer, armadillo43k, "meshes/libigl-tutorial-data/armadillo.obj", false)
    ->Unit(benchmark::kMicrosecond);
// The same with B capped at 16 non-zeros per row (WeightCap::kDropFarTets: still exact at rest).
BENCHMARK_CAPTURE(BM_PoseTransfer, armadillo43k_cap16, "meshes/libigl-tutorial-data/armadillo.obj", true)
    ->Unit(benchmark::kMicrosecond);

}  // namespace
