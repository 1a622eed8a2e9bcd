// Deformation core benchmarks: one iteration on the bars, the factorization, and one solve
// with the factor in double and in float.
//
// Bars of 4x4x33 (850 V / 2640 tets) and 8x8x85 (6966 V / 27200 tets) unit cubes, 5 tets each;
// vertex handles: every vertex within the first and last 5 % of the length; the far handle is
// rotated 90 degrees about the long axis and shifted by (1, 1, 2). The deformer is warmed up with
// 30 iterations, then each benchmark iteration is one step() of one iteration (solve + rotations
// + right-hand side), i.e. the steady state of a running frame loop. _volume: with the volume term
// (DeformerOptions::volume_weight 0.9), whose cost is in the rotation pass.
#include "scenes.hpp"
#include "tetrig/deformer.hpp"
#include "tetrig/laplacian.hpp"
#include "tetrig/ldlt_factor.hpp"
#include "tetrig/rotation_kernel.hpp"

#include <benchmark/benchmark.h>

#include <cmath>
#include <memory>

namespace {

using namespace tetrig;

struct BarBench {
  scenes::BarScene bar;
  std::vector<Eigen::Vector3d> targets;
  std::unique_ptr<Deformer> deformer;
};

BarBench makeBarBench(int nx, int ny, int nz, double volume_weight = 0.0) {
  BarBench b{scenes::makeBarScene(nx, ny, nz), {}, nullptr};
  DeformerSetup setup;
  setup.options.volume_weight = volume_weight;
  setup.vertex_handles = b.bar.near_vertices;
  setup.vertex_handles.insert(setup.vertex_handles.end(), b.bar.far_vertices.begin(), b.bar.far_vertices.end());
  b.targets = scenes::transformedPositions(b.bar.mesh, b.bar.near_vertices, Eigen::Isometry3d::Identity());
  const auto far = scenes::transformedPositions(
      b.bar.mesh, b.bar.far_vertices, scenes::barAxisTransform(b.bar, 0.5 * M_PI, Eigen::Vector3d(1, 1, 2)));
  b.targets.insert(b.targets.end(), far.begin(), far.end());
  b.deformer = std::make_unique<Deformer>(b.bar.mesh, setup);
  return b;
}

void iterationBenchmark(benchmark::State& state, int nx, int ny, int nz, double volume_weight = 0.0) {
  BarBench b = makeBarBench(nx, ny, nz, volume_weight);
  HandleTargets targets;
  targets.vertex_positions = b.targets;
  b.deformer->step(targets, StepBudget{30});
  std::int64_t solve = 0, rotation = 0;
  for (auto _ : state) {
    const StepStats stats = b.deformer->step(targets, StepBudget{1});
    solve += stats.solve_ns;
    rotation += stats.rotation_ns;
    benchmark::DoNotOptimize(b.deformer->positions().data());
  }
  const auto n = static_cast<double>(state.iterations());
  state.counters["solve_us"] = static_cast<double>(solve) / n * 1e-3;
  state.counters["rotations_rhs_us"] = static_cast<double>(rotation) / n * 1e-3;
  state.counters["ns_per_tet_rotations"] = static_cast<double>(rotation) / n / b.bar.mesh.tetCount();
  state.counters["vertices"] = b.bar.mesh.vertexCount();
  state.counters["tets"] = b.bar.mesh.tetCount();
  state.counters["factor_nnz"] = static_cast<double>(b.deformer->factorNonZeros());
  state.SetLabel(std::string("kernel isa: ") + rotationKernelInstructionSet());
}

// The bar's Laplacian with the rows and columns of its handle vertices removed (what Deformer factors).
Eigen::SparseMatrix<double> reducedBarLaplacian(int nx, int ny, int nz) {
  const auto bar = scenes::makeBarScene(nx, ny, nz);
  const TetRestFrames frames = computeRestFrames(bar.mesh);
  const Eigen::SparseMatrix<double> l = assembleLaplacian(bar.mesh, frames, tetWeights(frames, {}));
  // The reduced matrix: rows/columns of the handle vertices removed.
  std::vector<char> fixed(static_cast<size_t>(bar.mesh.vertexCount()), 0);
  for (auto v : bar.near_vertices) fixed[static_cast<size_t>(v)] = 1;
  for (auto v : bar.far_vertices) fixed[static_cast<size_t>(v)] = 1;
  std::vector<int> index(fixed.size(), -1);
  int free_count = 0;
  for (size_t v = 0; v < fixed.size(); ++v)
    if (!fixed[v]) index[v] = free_count++;
  std::vector<Eigen::Triplet<double>> triplets;
  for (int c = 0; c < l.outerSize(); ++c)
    for (Eigen::SparseMatrix<double>::InnerIterator it(l, c); it; ++it)
      if (index[static_cast<size_t>(it.row())] >= 0 && index[static_cast<size_t>(c)] >= 0)
        triplets.emplace_back(index[static_cast<size_t>(it.row())], index[static_cast<size_t>(c)], it.value());
  Eigen::SparseMatrix<double> reduced(free_count, free_count);
  reduced.setFromTriplets(triplets.begin(), triplets.end());
  return reduced;
}

void factorizeBenchmark(benchmark::State& state, int nx, int ny, int nz) {
  const Eigen::SparseMatrix<double> reduced = reducedBarLaplacian(nx, ny, nz);
  const auto free_count = static_cast<double>(reduced.rows());
  SplitLdlt factor;
  for (auto _ : state) {
    factor.factorize(reduced);
    benchmark::DoNotOptimize(factor.factorNonZeros());
  }
  state.counters["unknowns"] = free_count;
  state.counters["factor_nnz"] = static_cast<double>(factor.factorNonZeros());
}

BENCHMARK_CAPTURE(iterationBenchmark, bar_4x4x33, 4, 4, 33)->Name("BM_Iteration/bar_4x4x33")->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(iterationBenchmark, bar_8x8x85, 8, 8, 85)->Name("BM_Iteration/bar_8x8x85")->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(iterationBenchmark, bar_8x8x85_volume, 8, 8, 85, 0.9)
    ->Name("BM_Iteration/bar_8x8x85_volume")
    ->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(factorizeBenchmark, bar_8x8x85, 8, 8, 85)->Name("BM_Factorize/bar_8x8x85")->Unit(benchmark::kMillisecond);

// One solve with the factor (three right-hand sides, x, y, z), in double (/0, every global step's)
// or with its float copy (/1, the implicit inversion guard's), the right-hand side refilled untimed.
template <typename T>
void solveLoop(benchmark::State& state, SplitLdlt& factor) {
  const auto n = static_cast<std::size_t>(factor.size()) * kVectorStride;
  std::vector<T> rhs(n, T(0)), x(n);
  for (std::size_t i = 0; i < n; ++i)
    if (i % kVectorStride != 3) rhs[i] = static_cast<T>(std::sin(0.37 * static_cast<double>(i)));
  for (auto _ : state) {
    state.PauseTiming();
    std::copy(rhs.begin(), rhs.end(), x.begin());
    state.ResumeTiming();
    factor.solveInPlace(x.data());
    benchmark::DoNotOptimize(x.data());
  }
}

void solveBenchmark(benchmark::State& state, int nx, int ny, int nz) {
  SplitLdlt factor;
  factor.factorize(reducedBarLaplacian(nx, ny, nz));
  if (state.range(0) != 0) {
    factor.prepareFloatSolve();
    solveLoop<float>(state, factor);
  } else {
    solveLoop<double>(state, factor);
  }
  state.counters["unknowns"] = factor.size();
  state.counters["factor_nnz"] = static_cast<double>(factor.factorNonZeros());
}
BENCHMARK_CAPTURE(solveBenchmark, bar_4x4x33, 4, 4, 33)->Name("BM_Solve/bar_4x4x33")->DenseRange(0, 1)->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(solveBenchmark, bar_8x8x85, 8, 8, 85)->Name("BM_Solve/bar_8x8x85")->DenseRange(0, 1)->Unit(benchmark::kMicrosecond);

}  // namespace
