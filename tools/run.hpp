// `tetrig run`: the live path as a command. A marker source (device, C3D clip, raw recording,
// synthetic) on its driver thread -> FrameMailbox -> the solver thread (FrameLoop: LiveRig step +
// pose transfer straight into the shared-memory slot) -> engines reading the segment.
// Keys of --stats-json: docs/live.md.
#pragma once

#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/frame_loop.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/solver_settings.hpp"

#include <nlohmann/json.hpp>

#include <cstddef>
#include <cstdint>

#include <optional>
#include <string>
#include <vector>

namespace tetrig::tools {

// One performer of a stage (`tetrig run --performer ...` or `--stage FILE`; docs/live.md,
// "Several performers"): a rig driven by a source, or by one subject of a source that carries
// several ("alice:LFHD"), published into its own segment by its own solver thread.
struct PerformerSpec {
  std::string name;             // in messages and stats (default: the subject, else the segment name)
  std::string rig_path;
  std::string coarse_rig_path;  // optional coarse level (as RunOptions::coarse_rig_path)
  std::string source;           // as RunOptions::source; performers naming the same source share it (read once)
  std::string subject;          // only the source's labels "subject:NAME" (empty: every label)
  std::string publish;          // the performer's segment name (unique in the stage)
  int cpu = -1;                 // pin its solver thread here (-1: one CPU per performer when there are enough)
};

struct RunOptions {
  std::string rig_path;                 // rig file (ignored when `rig` is set)
  std::string coarse_rig_path;          // optional coarse level: the same mesh and markers with fewer tet vertices
                                        // (docs/fidelity.md, "Coarse level")
  SolverSettings solver;                // the solver (tools/solver_flags.hpp; SolverSettings{}: the accurate settings)
  std::optional<tetrig::Rig> rig;       // an already built rig (tetrig demo)
  std::string source = "synthetic";     // c3d:PATH, replay:PATH, synthetic[:N], hid:VID:PID, usb:VID:PID, hydra[:SERIAL]
  std::string publish = "tetrig";       // shared-memory segment name (without the leading '/')
  std::uint64_t frames = 0;             // stop after this many solved frames (0: until the source ends or SIGINT)
  int iterations = 3;
  double budget_ms = 0;                 // 0: derived from the source rate (0.9 of its period; 8 ms when unknown)
  double stale_ms = 250;
  bool as_fast_as_possible = false;
  double speed = 1.0;
  std::uint16_t rate_hz = 0;            // devices: SET_RATE; c3d: overrides the clip's rate; synthetic: its rate
  bool loop = false;
  bool keep_zero_markers = false;       // c3d: samples at x = y = z = 0 with residual 0 stay valid (default: gaps)
  bool normals = false;
  bool dds = false;                     // also publish over DDS (topics named from `publish`; docs/dds.md)
  int pose_threads = 1;                 // pose transfer threads: 1, or 2 (the solver + one worker; docs/live.md)
  double occlusion_blend_ms = 150;
  double label_timeout_ms = 3000;
  std::string stats_json;               // write the run's statistics here (atomically; a file tetrig did not write is kept)
  bool force = false;                   // replace an existing stats_json or final_obj that tetrig did not write (an input never)
  int cpu = -1;
  bool fifo = false;
  double spin_before_frame_us = 500.0;  // FrameLoopOptions::spin_before_frame_ns (0: sleep until the frame comes)
  bool lock_memory = true;
  unsigned shm_permissions = 0600;
  bool quiet = false;
  bool status_line = true;              // a live status line on a terminal (stderr)
  std::string final_obj;                // write the last published fine surface here as OBJ (atomically)
  std::string consumer_command;         // demo: started after the segment exists, with the segment name appended; waited for at the end
  std::size_t frame_log_capacity = 0;   // demo report: the solver's per-frame log (FrameLoopOptions::frame_log_capacity)
  int frame_log_markers = 0;            // demo report: markers kept per logged frame
  bool frame_log_positions_crc = false; // tests: each logged frame's CRC-32C of its published positions
  // Several performers: when not empty, these replace rig_path, coarse_rig_path, source, publish and
  // cpu above (every other option applies to each performer); final_obj and consumer_command take
  // one performer only.
  std::vector<PerformerSpec> performers;
};

// What a run leaves for the caller (tetrig demo's report): the --stats-json object, the frame log
// (tetrig/frame_loop.hpp) with the markers kept per frame, and the rig's alignment (device mm ->
// rig units, its up axis).
struct RunOutcome {
  nlohmann::json stats;  // several performers: {"performers": [one object each], "totals": {...}, ...}
  std::vector<tetrig::FrameLogEntry> frame_log;
  std::vector<std::vector<tetrig::FrameLogMarker>> frame_log_markers;  // one list per frame_log entry
  std::uint64_t frame_log_dropped = 0;
  tetrig::RigAlignment alignment;
  std::string rig_name;
  double budget_ms = 0;
  std::vector<RunOutcome> performers;  // several performers: one outcome each (stats: that performer's object)
};

// Where a clip run is: its frame count and rate, and how long it starts with a still pose.
struct ClipPosition {
  std::size_t frames = 0;
  double rate_hz = 0;
  double still_s = 0;
};

// Frames at the start of a clip in which no physical marker moved more than threshold_mm from
// where it was first seen (a performer standing in the calibration pose before the take).
std::size_t stillLeadFrames(const drivers::C3DClip& clip, double threshold_mm = 20.0);

// Runs until the source ends, `frames` frames were solved, or SIGINT/SIGTERM. Prints a summary
// on stdout. Returns the process exit code; throws (one clear line) on bad input: a rig that does
// not load, a source that cannot open, a segment name in use by a live producer, a source whose
// markers share no label with the rig.
// With `outcome`, also fills it (after the run, whatever its exit code).
// Several performers (options.performers): each gets its own live rig, mailbox, solver thread and
// segment; a source named by several is opened once and its frames fanned out to each
// (FrameMailbox::forwardTo); the run ends when every performer has ended.
int runLive(const RunOptions& options, RunOutcome* outcome = nullptr);

// "rig=PATH,source=SPEC,publish=NAME[,subject=S][,name=N][,coarse-rig=PATH][,cpu=K]" (--performer).
// Throws std::invalid_argument naming the bad key or value.
PerformerSpec parsePerformerSpec(const std::string& text);
// A stage file (JSON, docs/live.md "Several performers"): {"performers": [{"rig": ..., "source": ...,
// "publish": ..., "subject": ..., "name": ..., "coarse_rig": ..., "cpu": ...}, ...]}; relative paths
// (rig, coarse_rig, and c3d:/replay: sources) are relative to the file's folder. Throws one clear line.
std::vector<PerformerSpec> loadStageFile(const std::string& path);
// Refuses a stage that cannot run: no performers, a performer without rig, source or segment,
// two performers on one segment or with one name. Fills default names. Two performers may share
// a source and subject (one performer driving two characters); a source carrying several subjects
// needs each performer's subject (refused at binding otherwise).
void checkStage(std::vector<PerformerSpec>& performers);

}  // namespace tetrig::tools
