// `tetrig demo` (tools/demo.hpp): the live path on the project's own data or on real data.
#include "demo.hpp"

#include "run.hpp"
#include "tetrig/rigbuild/demo_bar_rig.hpp"
#include "tetrig/rigbuild/build_rig.hpp"
#include "tetrig/rigbuild/progress.hpp"
#include "tetrig/rigbuild/write_file_atomic.hpp"
#include "tetrig/tet_mesh_io.hpp"

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include <unistd.h>

namespace tetrig::tools {

namespace {

std::filesystem::path assetsDir() {
  if (const char* env = std::getenv("TETRIG_ASSETS_DIR"); env != nullptr && env[0] != '\0') return env;
  return TETRIG_ASSETS_DIR;
}

// The directory of the running executable (tetrig-shm-cat is built beside tetrig).
std::filesystem::path exeDir() {
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::filesystem::current_path() : self.parent_path();
}

std::filesystem::path cacheDir() {
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x != nullptr && x[0] != '\0') return std::filesystem::path(x) / "tetrig" / "rigs";
  if (const char* h = std::getenv("HOME"); h != nullptr && h[0] != '\0') return std::filesystem::path(h) / ".cache" / "tetrig" / "rigs";
  return std::filesystem::temp_directory_path() / "tetrig-rigs";
}

// A cache key from both inputs' absolute paths, sizes and modification times.
std::string cacheKey(const std::filesystem::path& mesh, const std::filesystem::path& clip) {
  std::string key;
  for (const auto& p : {mesh, clip}) {
    const auto abs = std::filesystem::absolute(p);
    key += abs.string() + "|" + std::to_string(std::filesystem::file_size(abs)) + "|" +
           std::to_string(std::filesystem::last_write_time(abs).time_since_epoch().count()) + "|";
  }
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016zx", std::hash<std::string>{}(key));
  return std::string(hex);
}

}  // namespace

int runDemo(const DemoOptions& options) {
  if (options.mesh.empty() != options.c3d.empty()) throw std::invalid_argument("--mesh and --c3d go together (a mesh and the clip that drives it)");
  RunOptions run;
  run.iterations = options.iterations;
  run.budget_ms = options.frame_budget_ms;
  run.quiet = options.quiet;
  run.final_obj = options.out_obj;
  run.publish = options.publish.empty() ? "tetrig-demo-" + std::to_string(getpid()) : options.publish;
  const std::filesystem::path consumer = exeDir() / "tetrig-shm-cat";
  if (std::filesystem::exists(consumer)) run.consumer_command = consumer.string() + " --quiet --timeout-ms 10000";
  if (options.mesh.empty()) {
    run.rig = rigbuild::makeDemoBarRig(readTetGen(assetsDir() / "bar_4x4x33.node"));
    run.source = "synthetic";
    run.frames = options.frames != 0 ? options.frames : 600;
  } else {
    // "-checked": rigs cached by builders before the alignment checks (and the relative distance
    // limit that 0 now means) are not reused.
    const std::filesystem::path cached =
        cacheDir() / (cacheKey(options.mesh, options.c3d) + "-" + std::to_string(options.max_marker_distance) + "-checked.rig");
    if (std::filesystem::exists(cached)) {
      if (!options.quiet) std::printf("tetrig demo: reusing the rig %s\n", cached.string().c_str());
    } else {
      rigbuild::BuildRigInputs in;
      in.mesh = options.mesh;
      in.clip = options.c3d;
      if (options.max_marker_distance > 0) in.max_marker_distance = options.max_marker_distance;
      rigbuild::Progress progress("tetrig demo", options.quiet ? rigbuild::Progress::Mode::kQuiet : rigbuild::Progress::Mode::kAuto);
      const Rig rig = rigbuild::buildRig(in, nullptr, &progress);
      std::filesystem::create_directories(cached.parent_path());
      rigbuild::writeFileAtomically(cached, serializeRig(rig));
      if (!options.quiet) std::printf("tetrig demo: rig cached in %s\n", cached.string().c_str());
    }
    run.rig_path = cached.string();
    run.source = "c3d:" + options.c3d;
    run.frames = options.frames;
  }
  return runLive(run);
}

}  // namespace tetrig::tools
