// An outside C++20 program on the installed runtime and drivers (tetrig::drivers, or pkg-config
// tetrig-drivers): the same frames as consumer.c through LiveRig and C3DPlayback directly, as
// `tetrig export` drives them; writes the last frame's positions (raw floats) to OUT.
// usage: consumer_cpp RIG CLIP FRAMES OUT
#include <tetrig/drivers/c3d_playback.hpp>
#include <tetrig/drivers/c3d_reader.hpp>
#include <tetrig/live_rig.hpp>
#include <tetrig/rig_file.hpp>
#include <tetrig/version.h>

#ifdef EIGEN_RUNTIME_NO_MALLOC
#error "EIGEN_RUNTIME_NO_MALLOC reached a consumer of tetrig: it must stay private to the runtime"
#endif

#include <cstdio>
#include <exception>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  if (argc != 5) {
    std::fprintf(stderr, "usage: consumer_cpp RIG CLIP FRAMES OUT\n");
    return 2;
  }
  try {
    const tetrig::Rig rig = tetrig::loadRigFile(argv[1]);
    tetrig::LiveRig live(rig);  // the default (accurate) settings, as tetrig_rig_open
    const tetrig::drivers::C3DClip clip = tetrig::drivers::C3DClip::load(argv[2]);
    tetrig::drivers::C3DPlaybackOptions options;
    options.pacing = tetrig::drivers::Pacing::kAsFastAsPossible;
    const tetrig::drivers::C3DPlayback playback(clip, options);
    if (live.bindLabels(clip.labels()).matched <= 0) throw std::runtime_error("no marker bound");
    std::vector<float> x(static_cast<std::size_t>(live.fineVertexCount()) * 3);
    tetrig::MarkerFrame frame{};
    const long frames = std::stol(argv[3]);
    for (long f = 0; f < frames; ++f) {
      playback.fillFrame(static_cast<std::size_t>(f), static_cast<std::uint64_t>(f), frame);
      live.processFrame(frame, tetrig::StepBudget{3}, x.data(), nullptr);
    }
    std::ofstream out(argv[4], std::ios::binary);
    out.write(reinterpret_cast<const char*>(x.data()), static_cast<std::streamsize>(x.size() * sizeof(float)));
    if (!out) throw std::runtime_error(std::string("cannot write ") + argv[4]);
    std::printf("consumer_cpp: tetrig %s, %ld frames, %d vertices\n", TETRIG_VERSION_STRING, frames, live.fineVertexCount());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "consumer_cpp: %s\n", e.what());
    return 1;
  }
  return 0;
}
