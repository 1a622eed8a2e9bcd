// The C API (capi/include/tetrig.h) over the C++ runtime: tetrig_rig wraps a loaded Rig and its
// LiveRig, tetrig_clip a C3DClip and its C3DPlayback. Every entry point is noexcept and catches
// everything: an exception becomes a status and this thread's error text (tetrig_last_error).
//
// A frame through the C API is the frame `tetrig export` gives the live rig (tools/export.cpp):
// marker i of the caller's array becomes MarkerFrame marker i with id i (the index of its label in
// the bound label table), valid unless a coordinate is NaN, device_timestamp_ns = the caller's
// timestamp (receive_timestamp_ns 0), then LiveRig::processFrame with StepBudget{max_iterations,
// deadline}. Fed a clip's frames (tetrig_clip_frame) with the same iteration count and no budget,
// the positions equal `tetrig export --iterations N`'s bit for bit (tests/capi/test_capi_ctypes.py).
#include "tetrig.h"

#include "tetrig/clock.hpp"
#include "tetrig/drivers/c3d_playback.hpp"
#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/marker_frame.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/solver_settings.hpp"
#include "tetrig/version.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <exception>
#include <limits>
#include <memory>
#include <new>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

static_assert(TETRIG_FRAME_POSE_HELD == tetrig::kLivePoseHeld);
static_assert(TETRIG_FRAME_MARKERS_PREDICTED == tetrig::kLiveMarkersPredicted);
static_assert(TETRIG_FRAME_MARKERS_BLENDING == tetrig::kLiveMarkersBlending);
static_assert(TETRIG_FRAME_DEADLINE_HIT == tetrig::kLiveDeadlineHit);
static_assert(TETRIG_FRAME_TARGETS_REJECTED == tetrig::kLiveTargetsRejected);
static_assert(TETRIG_FRAME_POSE_REJECTED == tetrig::kLivePoseRejected);
static_assert(TETRIG_FRAME_MARKERS_REJECTED == tetrig::kLiveMarkersRejected);

// A loaded rig and its live solver. Members are destroyed in reverse order: the LiveRig (which
// refers to the Rig) before the Rig.
struct tetrig_rig {
  std::unique_ptr<tetrig::Rig> rig;
  std::unique_ptr<tetrig::LiveRig> live;
  bool normals = false;              // opened with tetrig_rig_options::normals
  std::size_t bound_count = 0;       // labels of the last tetrig_rig_bind_labels
  tetrig::MarkerFrame frame{};       // the frame handed to the live rig (ids set when binding)
  tetrig_frame_stats last{};         // the last frame's statistics
};

// A clip in memory and its playback (which refers to the clip: the struct is never moved).
struct tetrig_clip {
  tetrig::drivers::C3DClip clip;
  std::unique_ptr<tetrig::drivers::C3DPlayback> playback;
  std::vector<std::string> labels;   // per output marker: the stored label, or "point<index>"
  mutable tetrig::MarkerFrame frame{};  // fillFrame's output (one thread at a time per handle)
};

namespace {

// This thread's last error text: a fixed buffer, so reporting an error cannot fail or allocate.
thread_local char t_error[512] = "";

// Records a failure (printf-style text) and returns its status.
[[gnu::format(printf, 2, 3)]] tetrig_status fail(tetrig_status status, const char* format, ...) noexcept {
  va_list args;
  va_start(args, format);
  std::vsnprintf(t_error, sizeof t_error, format, args);
  va_end(args);
  return status;
}

// The status and text of the exception being handled (call inside a catch block only).
tetrig_status failFromException(const char* function) noexcept {
  try {
    throw;
  } catch (const std::bad_alloc&) {
    return fail(TETRIG_ERROR_OUT_OF_MEMORY, "%s: out of memory", function);
  } catch (const tetrig::RigFileError& e) {
    return fail(TETRIG_ERROR_FILE, "%s: %s", function, e.what());
  } catch (const tetrig::drivers::C3DError& e) {
    return fail(TETRIG_ERROR_FILE, "%s: %s", function, e.what());
  } catch (const std::invalid_argument& e) {
    return fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: %s", function, e.what());
  } catch (const std::exception& e) {
    return fail(TETRIG_ERROR_INTERNAL, "%s: %s", function, e.what());
  } catch (...) {
    return fail(TETRIG_ERROR_INTERNAL, "%s: unknown exception", function);
  }
}

tetrig_status nullHandle(const char* function, const char* what) noexcept {
  return fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: the %s handle is NULL", function, what);
}

// Copies `from` into a caller buffer of `count` entries, which must hold all of it.
template <class T>
tetrig_status copyOut(const char* function, std::span<const T> from, T* to, size_t count, const char* what) noexcept {
  if (to == nullptr) return fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: the %s buffer is NULL", function, what);
  if (count < from.size()) {
    return fail(TETRIG_ERROR_BUFFER_SIZE, "%s: the buffer holds %zu %s entries; the rig needs %zu", function, count, what, from.size());
  }
  std::copy(from.begin(), from.end(), to);
  return TETRIG_OK;
}

}  // namespace

// ---- library ----

extern "C" const char* tetrig_version(void) noexcept { return TETRIG_VERSION_STRING; }

extern "C" const char* tetrig_last_error(void) noexcept { return t_error; }

extern "C" int64_t tetrig_now_ns(void) noexcept { return tetrig::monotonicNowNs(); }

// ---- rig: load ----

extern "C" void tetrig_rig_options_init(tetrig_rig_options* options) noexcept {
  if (options == nullptr) {
    fail(TETRIG_ERROR_INVALID_ARGUMENT, "tetrig_rig_options_init: options is NULL");
    return;
  }
  *options = tetrig_rig_options{};
  options->struct_size = sizeof(tetrig_rig_options);
  options->fast_settings = 0;
  options->occlusion_blend_ms = tetrig::LiveRigOptions{}.occlusion_blend_s * 1e3;  // 150
  options->normals = 0;
}

extern "C" tetrig_rig* tetrig_rig_open(const char* path, const tetrig_rig_options* options) noexcept {
  static const char* kFn = "tetrig_rig_open";
  if (path == nullptr) {
    fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: path is NULL", kFn);
    return nullptr;
  }
  tetrig_rig_options o;
  tetrig_rig_options_init(&o);
  if (options != nullptr) {
    if (options->struct_size != sizeof(tetrig_rig_options)) {
      fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: options->struct_size is %u, not sizeof(tetrig_rig_options) = %zu (initialise the options "
           "with tetrig_rig_options_init)", kFn, options->struct_size, sizeof(tetrig_rig_options));
      return nullptr;
    }
    o = *options;
  }
  if ((o.fast_settings != 0 && o.fast_settings != 1) || (o.normals != 0 && o.normals != 1)) {
    fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: options->fast_settings and options->normals must be 0 or 1", kFn);
    return nullptr;
  }
  if (!std::isfinite(o.occlusion_blend_ms) || o.occlusion_blend_ms < 0.0 || o.occlusion_blend_ms > 60000.0) {
    fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: options->occlusion_blend_ms must be between 0 and 60000", kFn);
    return nullptr;
  }
  try {
    auto handle = std::make_unique<tetrig_rig>();
    handle->rig = std::make_unique<tetrig::Rig>(tetrig::loadRigFile(path));  // RigFileError: missing, unreadable, corrupt
    tetrig::LiveRigOptions live;
    live.solver = o.fast_settings ? tetrig::SolverSettings::plain() : tetrig::SolverSettings{};
    live.occlusion_blend_s = o.occlusion_blend_ms * 1e-3;
    live.normals = o.normals != 0;
    try {
      handle->live = std::make_unique<tetrig::LiveRig>(*handle->rig, live);
    } catch (const std::invalid_argument& e) {
      // The file parsed but the live rig refuses it (fails validateRig, a bad coarse level): a file problem.
      fail(TETRIG_ERROR_FILE, "%s: %s: %s", kFn, path, e.what());
      return nullptr;
    }
    handle->normals = o.normals != 0;
    return handle.release();
  } catch (...) {
    failFromException(kFn);
    return nullptr;
  }
}

extern "C" void tetrig_rig_close(tetrig_rig* rig) noexcept { delete rig; }

// ---- rig: what it holds ----

extern "C" int32_t tetrig_rig_marker_count(const tetrig_rig* rig) noexcept {
  if (rig == nullptr) {
    nullHandle("tetrig_rig_marker_count", "rig");
    return -1;
  }
  return static_cast<int32_t>(rig->rig->markers.size());
}

extern "C" const char* tetrig_rig_marker_label(const tetrig_rig* rig, int32_t i) noexcept {
  if (rig == nullptr) {
    nullHandle("tetrig_rig_marker_label", "rig");
    return nullptr;
  }
  if (i < 0 || static_cast<std::size_t>(i) >= rig->rig->markers.size()) {
    fail(TETRIG_ERROR_OUT_OF_RANGE, "tetrig_rig_marker_label: marker %d is out of range (the rig has %zu markers)", i, rig->rig->markers.size());
    return nullptr;
  }
  return rig->rig->markers[static_cast<std::size_t>(i)].label.c_str();
}

extern "C" int32_t tetrig_rig_vertex_count(const tetrig_rig* rig) noexcept {
  if (rig == nullptr) {
    nullHandle("tetrig_rig_vertex_count", "rig");
    return -1;
  }
  return rig->live->fineVertexCount();
}

extern "C" int32_t tetrig_rig_triangle_count(const tetrig_rig* rig) noexcept {
  if (rig == nullptr) {
    nullHandle("tetrig_rig_triangle_count", "rig");
    return -1;
  }
  return static_cast<int32_t>(rig->live->fineTriangles().size() / 3);
}

extern "C" const char* tetrig_rig_unit(const tetrig_rig* rig) noexcept {
  if (rig == nullptr) {
    nullHandle("tetrig_rig_unit", "rig");
    return nullptr;
  }
  return rig->rig->unit.c_str();
}

extern "C" const char* tetrig_rig_up_axis(const tetrig_rig* rig) noexcept {
  if (rig == nullptr) {
    nullHandle("tetrig_rig_up_axis", "rig");
    return nullptr;
  }
  return rig->rig->alignment.rig_up.c_str();
}

extern "C" tetrig_status tetrig_rig_triangles(const tetrig_rig* rig, int32_t* triangles, size_t count) noexcept {
  if (rig == nullptr) return nullHandle("tetrig_rig_triangles", "rig");
  return copyOut<int32_t>("tetrig_rig_triangles", rig->live->fineTriangles(), triangles, count, "triangle index");
}

extern "C" tetrig_status tetrig_rig_rest_positions(const tetrig_rig* rig, float* positions, size_t count) noexcept {
  if (rig == nullptr) return nullHandle("tetrig_rig_rest_positions", "rig");
  return copyOut<float>("tetrig_rig_rest_positions", rig->live->restPositions(), positions, count, "position");
}

// ---- rig: bind a source ----

extern "C" int32_t tetrig_rig_bind_labels(tetrig_rig* rig, const char* const* labels, size_t count) noexcept {
  static const char* kFn = "tetrig_rig_bind_labels";
  if (rig == nullptr) {
    nullHandle(kFn, "rig");
    return -1;
  }
  if (labels == nullptr && count > 0) {
    fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: labels is NULL", kFn);
    return -1;
  }
  if (count > static_cast<size_t>(tetrig::kMaxMarkers)) {
    fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: %zu labels; a frame holds at most %d markers", kFn, count, tetrig::kMaxMarkers);
    return -1;
  }
  try {
    // Label i names source id i; NULL names nothing.
    std::vector<std::string> by_id(count);
    for (size_t i = 0; i < count; ++i) {
      if (labels[i] != nullptr) by_id[i] = labels[i];
    }
    const tetrig::MarkerBindingReport report = rig->live->bindLabels(by_id);
    // The frame's marker i carries id i from now on.
    rig->bound_count = count;
    rig->frame.marker_count = static_cast<std::uint16_t>(count);
    for (size_t i = 0; i < count; ++i) {
      rig->frame.markers[i] = tetrig::Marker{};
      rig->frame.markers[i].id = static_cast<std::uint16_t>(i);
    }
    return report.matched;
  } catch (...) {
    failFromException(kFn);
    return -1;
  }
}

// ---- rig: one frame ----

extern "C" tetrig_status tetrig_rig_process_frame(tetrig_rig* rig, const float* markers_xyz, size_t marker_count, int64_t timestamp_ns,
                                                  int32_t max_iterations, int64_t budget_ns, float* positions, size_t positions_count,
                                                  float* normals, size_t normals_count, tetrig_frame_stats* stats) noexcept {
  static const char* kFn = "tetrig_rig_process_frame";
  const auto start = std::chrono::steady_clock::now();
  if (rig == nullptr) return nullHandle(kFn, "rig");
  // Every argument is checked before anything changes.
  if (marker_count != rig->bound_count) {
    return fail(TETRIG_ERROR_NOT_BOUND, "%s: %zu markers given; the labels bound were %zu (tetrig_rig_bind_labels)", kFn, marker_count,
                rig->bound_count);
  }
  if (markers_xyz == nullptr && marker_count > 0) return fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: markers_xyz is NULL", kFn);
  if (max_iterations < 1) return fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: max_iterations is %d; it must be at least 1", kFn, max_iterations);
  if (budget_ns < 0) return fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: budget_ns must be 0 (no limit) or positive", kFn);
  const size_t values = static_cast<size_t>(rig->live->fineVertexCount()) * 3;
  if (positions == nullptr) return fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: positions is NULL", kFn);
  if (positions_count < values) {
    return fail(TETRIG_ERROR_BUFFER_SIZE, "%s: positions holds %zu floats; the rig's %zu vertices need %zu", kFn, positions_count, values / 3,
                values);
  }
  if (normals != nullptr && !rig->normals) {
    return fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: normals asked for, but the rig was opened without them (tetrig_rig_options::normals = 1)",
                kFn);
  }
  if (normals != nullptr && normals_count < values) {
    return fail(TETRIG_ERROR_BUFFER_SIZE, "%s: normals holds %zu floats; the rig's %zu vertices need %zu", kFn, normals_count, values / 3, values);
  }

  // The frame: marker i is the caller's i-th xyz (its id i was set when binding); NaN = occluded.
  tetrig::MarkerFrame& frame = rig->frame;
  frame.frame_counter = rig->last.frames;
  frame.device_timestamp_ns = timestamp_ns;
  frame.receive_timestamp_ns = 0;
  for (size_t i = 0; i < marker_count; ++i) {
    tetrig::Marker& m = frame.markers[i];
    const float* p = markers_xyz + 3 * i;
    const bool occluded = std::isnan(p[0]) || std::isnan(p[1]) || std::isnan(p[2]);
    m.valid = static_cast<std::uint8_t>(occluded ? 0 : 1);
    for (std::size_t c = 0; c < 3; ++c) m.position_mm[c] = occluded ? 0.0f : p[c];
  }
  tetrig::StepBudget budget;
  budget.max_iterations = max_iterations;
  if (budget_ns > 0) budget.deadline = start + std::chrono::nanoseconds(budget_ns);
  const tetrig::LiveFrameStats s = rig->live->processFrame(frame, budget, positions, normals);  // noexcept, allocates nothing

  tetrig_frame_stats& out = rig->last;
  out.frames += 1;
  out.iterations = s.step.iterations;
  out.flags = s.flags;
  out.energy = s.step.energy;
  out.step_ns = s.step.total_ns;
  out.pose_transfer_ns = s.pose_transfer_ns;
  out.measured_markers = s.measured_markers;
  out.occluded_markers = s.occluded_markers;
  out.blending_markers = s.blending_markers;
  out.unknown_markers = s.unknown_markers;
  out.rejected_marker_samples = s.rejected_marker_samples;
  out.total_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - start).count();
  if (stats != nullptr) *stats = out;
  return TETRIG_OK;
}

extern "C" int64_t tetrig_rig_prepare_next_frame(tetrig_rig* rig, int64_t budget_ns) noexcept {
  static const char* kFn = "tetrig_rig_prepare_next_frame";
  if (rig == nullptr) {
    nullHandle(kFn, "rig");
    return -1;
  }
  if (budget_ns < 0) {
    fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: budget_ns must be 0 (no limit) or positive", kFn);
    return -1;
  }
  const auto deadline = budget_ns > 0 ? std::chrono::steady_clock::now() + std::chrono::nanoseconds(budget_ns)
                                      : std::chrono::steady_clock::time_point::max();
  return rig->live->prepareNextFrame(deadline);
}

extern "C" tetrig_status tetrig_rig_frame_stats(const tetrig_rig* rig, tetrig_frame_stats* stats) noexcept {
  if (rig == nullptr) return nullHandle("tetrig_rig_frame_stats", "rig");
  if (stats == nullptr) return fail(TETRIG_ERROR_INVALID_ARGUMENT, "tetrig_rig_frame_stats: stats is NULL");
  *stats = rig->last;
  return TETRIG_OK;
}

// ---- clip ----

extern "C" tetrig_clip* tetrig_clip_open(const char* path) noexcept {
  static const char* kFn = "tetrig_clip_open";
  if (path == nullptr) {
    fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: path is NULL", kFn);
    return nullptr;
  }
  try {
    // As `tetrig run --clip` and `tetrig export` read and play it: zero samples are gaps, the
    // physical markers only, millimetres in the file's axes.
    tetrig::drivers::C3DReadOptions read_options;
    read_options.keep_zero_points = false;
    auto handle = std::unique_ptr<tetrig_clip>(new tetrig_clip{tetrig::drivers::C3DClip::load(path, read_options), nullptr, {}, {}});
    tetrig::drivers::C3DPlaybackOptions play;
    play.pacing = tetrig::drivers::Pacing::kAsFastAsPossible;
    handle->playback = std::make_unique<tetrig::drivers::C3DPlayback>(handle->clip, play);
    // Labels as the playback source names its markers (tetrig::drivers::makeC3DSource).
    const auto& points = handle->playback->selectedPoints();
    for (std::size_t k = 0; k < handle->playback->markerCount(); ++k)
      handle->labels.push_back(tetrig::drivers::c3dPointLabel(handle->clip, points[k]));
    return handle.release();
  } catch (...) {
    failFromException(kFn);
    return nullptr;
  }
}

extern "C" void tetrig_clip_close(tetrig_clip* clip) noexcept { delete clip; }

extern "C" int32_t tetrig_clip_marker_count(const tetrig_clip* clip) noexcept {
  if (clip == nullptr) {
    nullHandle("tetrig_clip_marker_count", "clip");
    return -1;
  }
  return static_cast<int32_t>(clip->labels.size());
}

extern "C" const char* tetrig_clip_marker_label(const tetrig_clip* clip, int32_t i) noexcept {
  if (clip == nullptr) {
    nullHandle("tetrig_clip_marker_label", "clip");
    return nullptr;
  }
  if (i < 0 || static_cast<std::size_t>(i) >= clip->labels.size()) {
    fail(TETRIG_ERROR_OUT_OF_RANGE, "tetrig_clip_marker_label: marker %d is out of range (the clip has %zu markers)", i, clip->labels.size());
    return nullptr;
  }
  return clip->labels[static_cast<std::size_t>(i)].c_str();
}

extern "C" int64_t tetrig_clip_frame_count(const tetrig_clip* clip) noexcept {
  if (clip == nullptr) {
    nullHandle("tetrig_clip_frame_count", "clip");
    return -1;
  }
  return static_cast<int64_t>(clip->clip.frameCount());
}

extern "C" double tetrig_clip_rate_hz(const tetrig_clip* clip) noexcept {
  if (clip == nullptr) {
    nullHandle("tetrig_clip_rate_hz", "clip");
    return -1.0;
  }
  return clip->playback->framePeriodNs() > 0 ? clip->playback->frameRate() : 0.0;
}

extern "C" tetrig_status tetrig_clip_frame(const tetrig_clip* clip, int64_t frame, float* xyz, size_t count, int64_t* timestamp_ns) noexcept {
  static const char* kFn = "tetrig_clip_frame";
  if (clip == nullptr) return nullHandle(kFn, "clip");
  const auto frames = static_cast<int64_t>(clip->clip.frameCount());
  if (frame < 0 || frame >= frames) {
    return fail(TETRIG_ERROR_OUT_OF_RANGE, "%s: frame %lld is out of range (the clip has %lld frames)", kFn, static_cast<long long>(frame),
                static_cast<long long>(frames));
  }
  const size_t markers = clip->labels.size();
  if (xyz == nullptr) return fail(TETRIG_ERROR_INVALID_ARGUMENT, "%s: xyz is NULL", kFn);
  if (count < markers * 3) {
    return fail(TETRIG_ERROR_BUFFER_SIZE, "%s: xyz holds %zu floats; the clip's %zu markers need %zu", kFn, count, markers, markers * 3);
  }
  // The playback's frame with counter = frame index, so device time = frame * period, as in `tetrig export`.
  tetrig::MarkerFrame& f = clip->frame;
  clip->playback->fillFrame(static_cast<std::size_t>(frame), static_cast<std::uint64_t>(frame), f);
  for (size_t k = 0; k < markers; ++k) {
    const tetrig::Marker& m = f.markers[k];
    for (std::size_t c = 0; c < 3; ++c) xyz[3 * k + c] = m.valid ? m.position_mm[c] : std::numeric_limits<float>::quiet_NaN();
  }
  if (timestamp_ns != nullptr) *timestamp_ns = f.device_timestamp_ns;
  return TETRIG_OK;
}
