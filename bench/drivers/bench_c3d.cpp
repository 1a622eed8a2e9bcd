// C3D reader throughput: BM_C3DRead/hdm05 loads the real HDM05 clip (2.8 MB, 44 points x 3990
// frames, Intel float) from disk and decodes it completely, per iteration. items_per_second is
// decoded frames per second. Skips with a clear message when the data is absent.
#include <benchmark/benchmark.h>

#include <filesystem>
#include <string>

#include "bench_data.hpp"
#include "tetrig/drivers/c3d_reader.hpp"

namespace {

void BM_C3DRead(benchmark::State& state, const char* relative) {
  const std::filesystem::path path = tetrig::bench::benchDataPath(relative);
  if (!std::filesystem::exists(path)) {
    state.SkipWithError(tetrig::bench::benchDataMissing(path).c_str());
    return;
  }
  std::size_t frames = 0;
  for (auto _ : state) {
    const tetrig::drivers::C3DClip clip = tetrig::drivers::C3DClip::load(path);
    frames = clip.frameCount();
    benchmark::DoNotOptimize(clip.positions(0));
  }
  state.SetItemsProcessed(static_cast<std::int64_t>(frames) * static_cast<std::int64_t>(state.iterations()));
  state.counters["frames"] = static_cast<double>(frames);
}

BENCHMARK_CAPTURE(BM_C3DRead, hdm05, "mocap/hdm05/HDM_mm_01-02_03_120.c3d")->Unit(benchmark::kMillisecond);

}  // namespace
