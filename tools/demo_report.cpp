// The report folder of `tetrig demo` (tools/demo_report.hpp, docs/demo.md).
#include "demo_report.hpp"

#include "tetrig/printable_text.hpp"
#include "tetrig/render/picture_sheet.hpp"
#include "tetrig/rigbuild/write_file_atomic.hpp"
#include "tetrig_shm.h"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <system_error>

#include <fcntl.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

extern char** environ;

namespace tetrig::tools {

namespace {

TetrigShmReader* shmReader(void* p) { return static_cast<TetrigShmReader*>(p); }

// A private temporary directory (mkdtemp, mode 0700), removed with its contents at the end.
class PrivateTempDir {
 public:
  explicit PrivateTempDir(const char* prefix) {
    std::string tmpl = (std::filesystem::temp_directory_path() / (std::string(prefix) + "-XXXXXX")).string();
    if (::mkdtemp(tmpl.data()) == nullptr)
      throw std::runtime_error("cannot create a temporary directory " + tmpl + ": " + std::strerror(errno));
    path_ = tmpl;
  }
  ~PrivateTempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  PrivateTempDir(const PrivateTempDir&) = delete;
  PrivateTempDir& operator=(const PrivateTempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

std::string readText(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::vector<std::uint8_t> readBytes(const std::filesystem::path& path) {
  const std::string text = readText(path);
  return {text.begin(), text.end()};
}

// Runs `argv` with stdin from /dev/null and stdout + stderr into `log`; kills it after `timeout`.
// Returns its exit status, or a negative value when it could not run or was killed.
int runChild(const std::vector<std::string>& args, const std::filesystem::path& log, std::chrono::seconds timeout) {
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) return -1;
  const auto end = std::chrono::steady_clock::now() + timeout;
  int status = 0;
  while (true) {
    const pid_t r = waitpid(pid, &status, WNOHANG);
    if (r == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : -2;
    if (r < 0 && errno != EINTR) return -1;
    if (std::chrono::steady_clock::now() > end) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      return -3;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

// Text inside a gnuplot double-quoted string: printable, without quotes or backslashes.
std::string gnuplotText(const std::string& text) {
  std::string out;
  for (char c : printableText(text, 120))
    if (c != '"' && c != '\\') out += c;
  return out;
}

bool isExecutableFile(const std::filesystem::path& p) {
  std::error_code ec;
  return std::filesystem::is_regular_file(p, ec) && ::access(p.c_str(), X_OK) == 0;
}

// 0, 1 or 2 from the rig's up axis ("y", "-z", ...); 2 when it names none.
int upAxisIndex(const std::string& rig_up) {
  for (auto it = rig_up.rbegin(); it != rig_up.rend(); ++it) {
    if (*it == 'x' || *it == 'X') return 0;
    if (*it == 'y' || *it == 'Y') return 1;
    if (*it == 'z' || *it == 'Z') return 2;
  }
  return 2;
}

double phaseMs(const nlohmann::json& stats, const char* phase, const char* key) {
  const auto& l = stats.at("latency_us").at(phase);
  return l.at(key).get<double>() * 1e-3;
}

}  // namespace

// --- SegmentFrameCapture ---

SegmentFrameCapture::SegmentFrameCapture(std::string segment_name, int frames)
    : name_(segment_name.empty() || segment_name.front() == '/' ? std::move(segment_name) : "/" + segment_name),
      frames_(std::max(1, frames)),
      reader_(new TetrigShmReader{}) {}

SegmentFrameCapture::~SegmentFrameCapture() {
  stop();
  delete shmReader(reader_);
}

void SegmentFrameCapture::start() {
  if (thread_.joinable()) return;
  stop_.store(false);
  kept_.reserve(static_cast<std::size_t>(4 * frames_ + 1));
  thread_ = std::thread([this] {
    try {
      run();
    } catch (const std::exception& e) {  // out of memory: the report says so, the run goes on
      error_ = std::string("the segment's reader stopped: ") + e.what();
    }
  });
}

void SegmentFrameCapture::stop() {
  if (!thread_.joinable()) return;
  stop_.store(true);
  thread_.join();
  if (opened_) {
    try {
      captureNewest();  // the end of the run (the producer keeps the last frame in the segment)
    } catch (const std::exception& e) {
      error_ = std::string("the segment's reader stopped: ") + e.what();
    }
    tetrig_shm_close(shmReader(reader_));
    opened_ = false;
  } else if (error_.empty()) {
    error_ = "the segment " + name_ + " was never readable";
  }
}

void SegmentFrameCapture::run() {
  TetrigShmReader* r = shmReader(reader_);
  const pid_t self = getpid();
  while (!stop_.load()) {
    if (!opened_) {
      const int rc = tetrig_shm_open(r, name_.c_str());
      if (rc == TETRIG_SHM_OK && r->producer_pid == self) {
        opened_ = true;
        const std::uint32_t* tris = tetrig_shm_triangles(r);
        triangles_.assign(tris, tris + static_cast<std::size_t>(tetrig_shm_triangle_count(r)) * 3);
      } else {
        if (rc == TETRIG_SHM_OK) tetrig_shm_close(r);  // a leftover of another producer: wait for ours
        else if (rc != TETRIG_SHM_E_NOT_FOUND && rc != TETRIG_SHM_E_NOT_READY)
          error_ = std::string("cannot read the segment ") + name_ + ": " + tetrig_shm_status_string(rc);
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
        continue;
      }
    }
    if (tetrig_shm_latest_frame_id(r) >= next_id_) captureNewest();
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
}

void SegmentFrameCapture::captureNewest() {
  TetrigShmReader* r = shmReader(reader_);
  CapturedFrame f;
  f.positions.resize(static_cast<std::size_t>(tetrig_shm_vertex_count(r)) * 3);
  TetrigShmFrameInfo info{};
  if (tetrig_shm_read_latest(r, f.positions.data(), f.positions.size(), nullptr, 0, &info) != TETRIG_SHM_OK) return;
  if (!kept_.empty() && info.frame_id <= kept_.back().frame_id) return;
  f.frame_id = info.frame_id;
  f.source_frame = info.source_frame;
  f.device_ns = info.device_ns;
  f.receive_ns = info.receive_ns;
  kept_.push_back(std::move(f));
  if (kept_.size() >= static_cast<std::size_t>(4 * frames_)) {
    // Full: keep every other one (the first stays) and take frames twice as far apart from now on.
    std::size_t w = 0;
    for (std::size_t i = 0; i < kept_.size(); i += 2, ++w)
      if (w != i) kept_[w] = std::move(kept_[i]);
    kept_.resize(w);
    stride_ *= 2;
  }
  next_id_ = kept_.back().frame_id + stride_;
}

std::vector<CapturedFrame> SegmentFrameCapture::pick() const {
  const std::size_t m = kept_.size(), k = static_cast<std::size_t>(frames_);
  if (m <= k) return kept_;
  // For each of k frame ids evenly spaced from the first copy's to the last's, the nearest copy
  // not taken yet (the copies are in frame-id order and m > k, so there always is one).
  std::vector<CapturedFrame> out;
  const double first = static_cast<double>(kept_.front().frame_id), last = static_cast<double>(kept_.back().frame_id);
  std::size_t next = 0;  // copies before it are taken or skipped
  for (std::size_t i = 0; i < k; ++i) {
    const double target = k == 1 ? last : first + (last - first) * static_cast<double>(i) / static_cast<double>(k - 1);
    const std::size_t latest_allowed = m - (k - i);  // leave one copy for each frame still to pick
    std::size_t at = next;
    while (at < latest_allowed && std::abs(static_cast<double>(kept_[at + 1].frame_id) - target) <=
                                      std::abs(static_cast<double>(kept_[at].frame_id) - target))
      ++at;
    out.push_back(kept_[at]);
    next = at + 1;
  }
  return out;
}

// --- checks ---

void checkDemoReportTarget(const std::filesystem::path& dir) {
  std::error_code ec;
  const auto st = std::filesystem::symlink_status(dir, ec);
  if (!ec && std::filesystem::exists(st)) {
    if (!std::filesystem::is_directory(std::filesystem::status(dir, ec)))
      throw std::invalid_argument("--report " + printableText(dir.string()) +
                                  ": exists and is not a directory (the report is a folder: give a new or existing folder, or --no-report)");
  }
  // The folder, or the nearest folder above it that exists (it is created at the end), must be writable:
  // refused now rather than after the run.
  std::filesystem::path existing = std::filesystem::absolute(dir);
  while (!std::filesystem::exists(existing, ec) && existing.has_parent_path() && existing.parent_path() != existing)
    existing = existing.parent_path();
  if (!std::filesystem::is_directory(existing, ec) || ::access(existing.c_str(), W_OK | X_OK) != 0)
    throw std::invalid_argument("--report " + printableText(dir.string()) + ": cannot be written (" + printableText(existing.string()) +
                                (std::filesystem::is_directory(existing, ec) ? " is not writable" : " is not a directory") +
                                "): give another folder, or --no-report");
  (void)findGnuplot();
}

std::filesystem::path findGnuplot() {
  if (const char* env = std::getenv("TETRIG_GNUPLOT"); env != nullptr && env[0] != '\0') {
    if (!isExecutableFile(env))
      throw std::runtime_error(std::string("TETRIG_GNUPLOT=") + printableText(env) + " is not an executable file");
    return env;
  }
  const char* path = std::getenv("PATH");
  std::string dirs = path != nullptr && path[0] != '\0' ? path : "/usr/local/bin:/usr/bin:/bin";
  std::size_t start = 0;
  while (start <= dirs.size()) {
    const std::size_t end = std::min(dirs.find(':', start), dirs.size());
    const std::filesystem::path dir = dirs.substr(start, end - start);
    if (!dir.empty() && isExecutableFile(dir / "gnuplot")) return dir / "gnuplot";
    start = end + 1;
  }
  throw std::runtime_error(
      "the latency plot needs gnuplot, which is not on PATH: install it (apt-get install gnuplot-nox) or run with --no-report");
}

// --- the latency plot ---

std::vector<std::uint8_t> plotLatency(const RunOutcome& run, const std::string& title) {
  const std::filesystem::path gnuplot = findGnuplot();
  // One row per frame measured after the start (the frames before it waited for the set-up).
  std::int64_t t0 = 0;
  std::string data = "# t_s receive_to_published_ms step_ms pose_transfer_ms\n";
  std::size_t rows = 0;
  char line[128];
  for (const FrameLogEntry& e : run.frame_log) {
    if (e.flags & kFrameLogBeforeStart) continue;
    if (rows == 0) t0 = e.receive_ns;
    const double t = static_cast<double>(e.receive_ns - t0) * 1e-9;
    const double total = static_cast<double>(e.published_ns - e.receive_ns) * 1e-6;
    const double step = static_cast<double>(e.step_ns) * 1e-6, pose = static_cast<double>(e.pose_transfer_ns) * 1e-6;
    // Log scale: a phase that took no time (a held pose's step) is a gap, not a point at zero.
    auto value = [](double v) { return v > 0 ? std::to_string(v) : std::string("?"); };
    std::snprintf(line, sizeof line, "%.6f ", t);
    data += line + value(total) + " " + value(step) + " " + value(pose) + "\n";
    ++rows;
  }
  if (rows == 0) throw std::runtime_error("the latency plot has no frame to show (no frame was solved after the solver started)");

  const PrivateTempDir tmp("tetrig-plot");
  const std::filesystem::path dat = tmp.path() / "latency.dat", png = tmp.path() / "latency.png", gp = tmp.path() / "latency.gp",
                              log = tmp.path() / "gnuplot.log";
  { std::ofstream(dat, std::ios::binary) << data; }
  auto legend = [&](const char* name, const char* phase) {
    char text[160];
    std::snprintf(text, sizeof text, "%s: p50 %.3f ms, p99 %.3f ms", name, phaseMs(run.stats, phase, "p50"), phaseMs(run.stats, phase, "p99"));
    return std::string(text);
  };
  char budget[64];
  std::snprintf(budget, sizeof budget, "budget %.2f ms", run.budget_ms);
  std::ostringstream script;
  script << "set terminal pngcairo size 1400,600 font 'DejaVu Sans,10' noenhanced\n"
         << "set output '" << png.string() << "'\n"
         << "set datafile missing '?'\n"
         << "set title \"" << gnuplotText(title) << "\"\n"
         << "set xlabel 'time since the first frame (s)'\n"
         << "set ylabel 'latency (ms, log scale)'\n"
         << "set logscale y\n"
         << "set grid\n"
         << "set key outside right top vertical Left reverse width 2\n"
         << "plot '" << dat.string() << "' using 1:2 with lines lw 1.2 lc rgb '#1f5fa8' title \""
         << legend("receive -> published", "receive_to_published") << "\", \\\n"
         << "     '' using 1:3 with lines lw 1 lc rgb '#3a9a3a' title \"" << legend("step", "step") << "\", \\\n"
         << "     '' using 1:4 with lines lw 1 lc rgb '#e08a1e' title \"" << legend("pose transfer", "pose_transfer") << "\", \\\n"
         << "     " << (run.budget_ms > 0 ? run.budget_ms : 1.0) << " with lines dt 2 lw 2 lc rgb '#c0392b' title \"" << budget << "\"\n";
  { std::ofstream(gp, std::ios::binary) << script.str(); }
  const int status = runChild({gnuplot.string(), gp.string()}, log, std::chrono::seconds(60));
  std::string message = readText(log);
  while (!message.empty() && (message.back() == '\n' || message.back() == ' ')) message.pop_back();
  if (status != 0) {
    throw std::runtime_error("gnuplot (" + gnuplot.string() + ") " +
                             (status == -1 ? std::string("could not be started")
                              : status == -3 ? std::string("took more than 60 s and was stopped")
                                             : "failed (status " + std::to_string(status) + ")") +
                             (message.empty() ? "" : ": " + printableText(message, 400)));
  }
  std::vector<std::uint8_t> bytes = readBytes(png);
  static const std::uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (bytes.size() < 8 || std::memcmp(bytes.data(), kPngSignature, 8) != 0)
    throw std::runtime_error("gnuplot wrote no PNG (is the pngcairo terminal there? gnuplot-nox has it)" +
                             (message.empty() ? std::string() : ": " + printableText(message, 400)));
  return bytes;
}

// --- the report ---

std::vector<std::filesystem::path> writeDemoReport(const DemoReportOptions& options, const RunOutcome& run,
                                                   const std::vector<CapturedFrame>& frames,
                                                   const std::vector<std::int32_t>& triangles) {
  if (frames.empty() || triangles.empty())
    throw std::runtime_error("the picture sheet has no frame: the segment's reader copied none (was any frame published?)");
  // 1. The picture sheet: the captured frames, the source's markers of each from the frame log.
  const bool device_times = std::any_of(frames.begin(), frames.end(), [](const CapturedFrame& f) { return f.device_ns != 0; });
  const std::int64_t t0 = !run.frame_log.empty() ? run.frame_log.front().receive_ns : frames.front().receive_ns;
  std::vector<render::SheetFrame> tiles;
  nlohmann::json sheet_frames = nlohmann::json::array();
  for (const CapturedFrame& f : frames) {
    render::SheetFrame tile;
    tile.positions = f.positions;
    const double t = device_times ? static_cast<double>(f.device_ns) * 1e-9 : static_cast<double>(f.receive_ns - t0) * 1e-9;
    char caption[96];
    std::snprintf(caption, sizeof caption, "frame %llu  t = %.2f s", static_cast<unsigned long long>(f.source_frame), t);
    tile.caption = caption;
    const std::size_t index = static_cast<std::size_t>(f.frame_id - 1);
    int shown = 0;
    if (f.frame_id >= 1 && index < run.frame_log.size() && run.frame_log[index].frame_id == f.frame_id) {
      for (const FrameLogMarker& m : run.frame_log_markers[index]) {
        if (!m.valid) continue;
        const Eigen::Vector3d p = run.alignment.apply(Eigen::Vector3d(m.position_mm[0], m.position_mm[1], m.position_mm[2]));
        if (!p.allFinite()) continue;
        tile.markers.insert(tile.markers.end(), {static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z())});
        ++shown;
      }
    }
    sheet_frames.push_back({{"frame_id", f.frame_id}, {"source_frame", f.source_frame}, {"t_s", t}, {"markers", shown}});
    tiles.push_back(std::move(tile));
  }
  render::SheetOptions sheet_options;
  sheet_options.columns = std::min<int>(options.sheet_columns, static_cast<int>(tiles.size()));
  sheet_options.tile_width = sheet_options.tile_height = options.tile_size;
  sheet_options.up_axis = upAxisIndex(run.alignment.rig_up);
  const render::Image sheet = render::renderPictureSheet(tiles, triangles, sheet_options);

  // 2. The latency plot.
  const std::string rig_name = printableText(run.rig_name, 80);
  const std::vector<std::uint8_t> plot =
      plotLatency(run, "tetrig demo: latency per frame (" + rig_name + ", " + std::to_string(run.frame_log.size()) + " frames)");

  // 3. The summary: the run's --stats-json keys, then what the report adds.
  nlohmann::json summary = run.stats;
  const int rows = (static_cast<int>(tiles.size()) + sheet_options.columns - 1) / sheet_options.columns;
  summary["report"] = {
      {"files", {"summary.json", "sheet.png", "latency.png"}},
      {"sheet", {{"file", "sheet.png"}, {"columns", sheet_options.columns}, {"rows", rows}, {"tile_px", options.tile_size},
                 {"width", sheet.width}, {"height", sheet.height}, {"frames", sheet_frames}}},
      {"latency_plot", {{"file", "latency.png"}, {"frames", run.frame_log.size()}}},
      {"frame_log", {{"frames", run.frame_log.size()}, {"dropped", run.frame_log_dropped}}}};
  if (!options.demo.is_null()) summary["demo"] = options.demo;
  const std::string text = summary.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";

  // 4. Every part is made: write them.
  std::filesystem::create_directories(options.dir);
  const std::filesystem::path summary_path = options.dir / "summary.json", sheet_path = options.dir / "sheet.png",
                              plot_path = options.dir / "latency.png";
  // summary.json last: a folder whose summary.json is new holds a complete new report.
  render::writePng(sheet_path, sheet);
  rigbuild::writeFileAtomically(plot_path, plot);
  rigbuild::writeFileAtomically(summary_path, std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
  return {summary_path, sheet_path, plot_path};
}

}  // namespace tetrig::tools
