// The report folder of `tetrig demo` (docs/demo.md): what a run of the live path leaves for a
// person to look at and keep.
//
//   summary.json  the `tetrig run --stats-json` object of the run (tools/run.cpp builds it), plus
//                 a "report" object: the files, the frames on the sheet, the frame log's size
//   sheet.png     frames across the performance as the segment published them, read by an
//                 in-process reader of runtime/include/tetrig_shm.h (SegmentFrameCapture: the
//                 newest frame, at frame ids spaced across the run), drawn headless with the
//                 source's markers of the same frames (from the solver's frame log) by
//                 render::renderPictureSheet
//   latency.png   receive -> published, step and pose transfer per frame over the run (the
//                 solver's frame log), with the budget and p50/p99 in the legend, plotted by
//                 gnuplot (pngcairo) run as a child process on a script and a data file in a
//                 private temporary directory
//
// Every part is made first (in memory or in the temporary directory); only when all of them
// succeeded are the three files written, each atomically (tetrig::AtomicFile). A part that
// fails (no gnuplot, no OpenGL) throws one clear line and nothing is written: an existing report
// in the folder stays as it was.
//
// Tools only: allocates, throws std::runtime_error / std::invalid_argument.
#pragma once

#include "run.hpp"

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

namespace tetrig::tools {

// One frame copied out of the segment: its header fields and fine-mesh positions (rig units).
struct CapturedFrame {
  std::uint64_t frame_id = 0, source_frame = 0;
  std::int64_t device_ns = 0, receive_ns = 0;
  std::vector<float> positions;  // x, y, z per fine vertex
};

// A reader of the segment the run publishes, on its own thread, in this process: it opens the
// segment by name once this process's producer has made it (retrying until then), copies the
// newest frame whenever the segment's frame id reaches its next target, and keeps at most
// 4 * `frames` copies: when full it drops every other one and doubles the spacing, so that at
// any time what it holds is spread evenly over the run so far. stop() takes the newest frame
// once more (the end of the run), then pick() chooses `frames` of them evenly spaced.
class SegmentFrameCapture {
 public:
  SegmentFrameCapture(std::string segment_name, int frames);
  ~SegmentFrameCapture();  // stop()
  SegmentFrameCapture(const SegmentFrameCapture&) = delete;
  SegmentFrameCapture& operator=(const SegmentFrameCapture&) = delete;

  void start();
  void stop();
  // After stop(): up to `frames` captures evenly spaced over the run, first and last included.
  [[nodiscard]] std::vector<CapturedFrame> pick() const;
  // After stop(): every copy held (up to 4 * `frames`, spread evenly over the run, in frame order).
  [[nodiscard]] const std::vector<CapturedFrame>& captured() const { return kept_; }
  // After stop(): the segment's triangles (empty if the segment was never opened), and why not.
  [[nodiscard]] const std::vector<std::int32_t>& triangles() const { return triangles_; }
  [[nodiscard]] const std::string& error() const { return error_; }

 private:
  void run();
  void captureNewest();
  std::string name_;
  int frames_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  bool opened_ = false;
  void* reader_ = nullptr;  // TetrigShmReader (tetrig_shm.h is C: kept out of this header)
  std::vector<CapturedFrame> kept_;
  std::uint64_t stride_ = 1, next_id_ = 1;
  std::vector<std::int32_t> triangles_;
  std::string error_;
};

struct DemoReportOptions {
  std::filesystem::path dir;      // the report folder (created if missing)
  int sheet_columns = 4;
  int tile_size = 320;            // pixels, square tiles
  nlohmann::json demo;            // what the demo ran ("data", "mesh", "c3d"): added to summary.json
};

// Before the run: refuses a report path that exists and is not a directory (left untouched) and
// finds gnuplot. Throws one line saying what to do.
void checkDemoReportTarget(const std::filesystem::path& dir);

// The gnuplot executable ($TETRIG_GNUPLOT, else `gnuplot` on PATH). Throws (install gnuplot-nox).
std::filesystem::path findGnuplot();

// The latency plot of a run's frame log as PNG bytes (gnuplot, pngcairo). Throws when gnuplot
// fails (its message included) or the log holds no frame measured after the start.
std::vector<std::uint8_t> plotLatency(const RunOutcome& run, const std::string& title);

// Makes every part, then writes summary.json, sheet.png and latency.png into options.dir.
// `frames` from SegmentFrameCapture::pick(). Returns the paths written.
std::vector<std::filesystem::path> writeDemoReport(const DemoReportOptions& options, const RunOutcome& run,
                                                   const std::vector<CapturedFrame>& frames,
                                                   const std::vector<std::int32_t>& triangles);

}  // namespace tetrig::tools
