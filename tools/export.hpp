// `tetrig export`: a C3D clip run offline through the live rig at full quality (no deadline; a fixed
// iteration count, or every frame iterated until the fine mesh stops moving) and the fine-mesh
// animation written in formats other tools read (docs/export.md):
//   FILE.pc2           PC2 point cache + FILE.rest.obj (the rest fine mesh) beside it
//   NAME_####.obj|ply  one OBJ or binary PLY per frame ('#'s: the clip frame index, zero-padded)
//   FILE.gltf|glb      glTF 2.0: one mesh, one morph target per frame, animated weights
// The clip is bound to the rig by label exactly as `tetrig run` binds a c3d: source, frames are
// filled as its playback fills them (ids, millimetres, the clip's time line) and occluded markers
// are predicted by the same LiveRig: an export with --iterations N is, bit for bit, LiveRig fed the
// playback's frames A, A+1, ... with StepBudget{N} (what a live run with N iterations publishes
// when no frame is dropped and no deadline hits, up to the blend clock of its first frame).
// Output is atomic: nothing appears unless every frame was solved and written (docs/export.md).
#pragma once

#include "tetrig/live_rig.hpp"
#include "tetrig/solver_settings.hpp"

#include <cstddef>
#include <cstdint>
#include "tetrig/rigbuild/tracking_measure.hpp"

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace tetrig::tools {

enum class ExportFormat { kPc2, kObjSequence, kPlySequence, kGltf, kGlb };

// What --out names. Throws std::invalid_argument (one line: what, and the accepted forms) for an
// unknown extension, a sequence name without a '#' run (or with two), '#'s in a directory name.
struct ExportTarget {
  ExportFormat format = ExportFormat::kPc2;
  std::filesystem::path path;      // as given (PC2, glTF) or the pattern (sequences)
  std::filesystem::path rest_obj;  // PC2 only: the rest mesh, FILE.rest.obj (rigbuild::pc2RestObjPath)
  std::string prefix, suffix;      // sequences: file name = prefix + zero-padded frame + suffix
  int digits = 0;                  // sequences: the length of the '#' run
};
ExportTarget parseExportTarget(const std::filesystem::path& out);
// Sequences: the file of clip frame `frame` (at least `digits` digits, more when needed).
std::filesystem::path sequenceFramePath(const ExportTarget& target, std::size_t frame);

// --frames "A:B": clip frames A (inclusive) to B (exclusive), 0-based; "A:" to the end, ":B" from
// the start, "" the whole clip. Throws std::invalid_argument naming the clip's frame count when
// the range is malformed, empty or outside the clip.
struct FrameRange {
  std::size_t first = 0, end = 0;  // [first, end)
};
FrameRange parseFrameRange(const std::string& text, std::size_t clip_frames);

struct ExportOptions {
  std::filesystem::path rig_path;       // rig file (tetrig build-rig)
  std::filesystem::path clip_path;      // C3D clip
  std::filesystem::path out;            // see ExportTarget
  std::string frames;                   // "A:B" (see FrameRange)
  int iterations = 0;                   // > 0: exactly this many per frame; 0: converge (below)
  double tolerance = 1e-4;              // converge: stop once no fine vertex moved more than this fraction
                                        // of the rest mesh's bounding-box diagonal in the last chunk
  int max_iterations = 300;             // converge: at most this many iterations per frame
  double occlusion_blend_ms = 150;      // as `tetrig run --occlusion-blend-ms`
  // The solver (tools/solver_flags.hpp: the flags of `tetrig run`). Iterating to convergence uses no
  // temporal prediction and no coarse level (they only set where a frame starts, and each converge
  // chunk calls processFrame on the same frame again); after_publish_iterations needs iterations > 0.
  SolverSettings solver;
  double rate_hz = 0;                   // > 0: overrides the clip's frame rate (needed for glTF without one)
  bool keep_zero_markers = false;       // as `tetrig run --keep-zero-markers`: samples at x = y = z = 0 with
                                        // residual 0 stay valid (default: gaps)
  std::filesystem::path report;         // optional: write the run's report here (JSON: the tracking measure, counts)
  bool force = false;                   // replace existing files tetrig did not write (never an input)
  bool quiet = false;                   // no progress and no summary
  bool simple_progress = false;         // plain progress lines even on a terminal
  // Called after each solved frame (done of total) on the calling thread; may throw to cancel (tests).
  std::function<void(std::size_t done, std::size_t total)> on_frame;
};

// Iterations per converge chunk: each chunk is one LiveRig::processFrame call on the same frame.
inline constexpr int kConvergeChunkIterations = 4;

struct ExportReport {
  ExportTarget target;
  std::vector<std::filesystem::path> files;  // every file written, in write order
  std::uint64_t bytes = 0;                    // their total size
  std::size_t first_frame = 0, frame_count = 0;
  double rate_hz = 0;                         // the clip's (or the override)
  std::int32_t vertices = 0, triangles = 0;
  std::int32_t markers_bound = 0, markers_missing = 0;
  std::uint64_t iterations = 0;               // summed over frames
  std::int32_t max_frame_iterations = 0;
  std::size_t capped_frames = 0;              // converge: frames that reached max_iterations
  double worst_last_change = 0;               // converge: largest last-chunk change of a capped frame, rig units
  std::size_t held_frames = 0;                // no rig marker measured: last pose kept
  std::size_t predicted_frames = 0;           // some rig marker predicted (occluded or never named)
  SolverSettings solver;                      // the settings the live rig ran with (the report's "solver")
  bool volume_not_kept = false;               // the volume constraint was asked for, but the fine mesh is not closed
  double solve_seconds = 0, write_seconds = 0;
  // The tracking measure over every exported frame (rigbuild/tracking_measure.hpp): the change of
  // each measured marker's distance to its skin point, mm; per rig marker in rig.markers order.
  rigbuild::Percentiles tracking_mm;
  std::vector<std::pair<std::string, rigbuild::Percentiles>> tracking_per_marker_mm;
};

// Runs the export. Throws (one clear line) on bad input: unknown format, frames out of range, a rig
// that does not load, a clip that does not read, a clip whose markers share no label with the
// rig, a range in which no frame measures a rig marker, glTF of more than kMaxGltfFrames frames or
// without a frame rate, a missing output directory; on any throw no output file was touched.
// Offline (allocates, I/O), calling thread; progress on stderr.
ExportReport exportClip(const ExportOptions& options);

// The command: exportClip and a summary on stdout. Returns the exit code.
int runExport(const ExportOptions& options);

}  // namespace tetrig::tools
