// `tetrig export` (tools/export.hpp): clip -> LiveRig (offline, full quality) -> animation files.
//
// Quality: no deadline. With --iterations N every frame gets exactly N solver iterations (one
// processFrame call, as the solver thread makes it). By default each frame is iterated to
// convergence: processFrame is called again on the same frame, kConvergeChunkIterations
// iterations at a time, until no fine vertex moved more than tolerance x the rest mesh's
// bounding-box diagonal during the last call, or max_iterations were run. Calling processFrame
// again with the same frame is the same as more iterations of that frame: the frame's timestamp
// does not advance the blend clock, measured markers stay measured, occluded ones keep their
// dropout offset, and every call re-predicts the occluded markers from the newest pose.
//
// Atomic output: every file is first written under a temporary name in its own directory and
// renamed into place only after every frame was solved and written. PC2: FILE.pc2 and FILE.rest.obj
// are two tetrig::AtomicFile (the point cache is streamed frame by frame, never held in memory),
// committed after the last frame, the OBJ first. Sequences: the frames go into a temporary
// directory beside them (one AtomicFile per frame would make each frame appear as it is written);
// once all are written the file system is synced (syncfs) and each file is renamed into place. glTF: the whole file is built in memory and written with writeFileAtomically. On any
// error or exception the temporaries are removed and no existing file is touched; the command
// (runExport) turns SIGINT/SIGTERM into such an exception at the next frame.
#include "export.hpp"

#include "export_formats.hpp"
#include "signal_scope.hpp"
#include "solver_flags.hpp"
#include "tetrig/atomic_file.hpp"
#include "tetrig/drivers/c3d_playback.hpp"
#include "tetrig/drivers/c3d_reader.hpp"
#include "tetrig/drivers/playback_sources.hpp"
#include "tetrig/live_rig.hpp"
#include "tetrig/printable_text.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/progress.hpp"
#include "tetrig/rigbuild/output_guard.hpp"
#include "tetrig/rigbuild/write_file_atomic.hpp"

#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace tetrig::tools {

namespace {

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// File-supplied text (rig name, clip name) in a comment line: control characters become '?'.
std::string commentText(const std::string& text) {
  std::string out = text;
  for (char& c : out) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '?';
  }
  return out;
}

std::string joinLabels(const std::vector<std::string>& labels, std::size_t max_shown = 12) {
  std::string out;
  for (std::size_t i = 0; i < labels.size() && i < max_shown; ++i) out += (i ? ", " : "") + labels[i];
  if (labels.size() > max_shown) out += ", ... (" + std::to_string(labels.size()) + " in all)";
  return out;
}

std::string megabytes(std::uint64_t bytes) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f MB", static_cast<double>(bytes) / 1e6);
  return buf;
}

std::filesystem::path directoryOf(const std::filesystem::path& path) {
  return path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
}

[[noreturn]] void throwSystem(const std::filesystem::path& path, const std::string& what, int err) {
  throw std::runtime_error(path.string() + ": " + what + ": " + std::strerror(err));
}

void writeAll(int fd, const std::uint8_t* data, std::size_t size, const std::filesystem::path& path) {
  std::size_t done = 0;
  while (done < size) {
    const ssize_t w = ::write(fd, data + done, size - done);
    if (w < 0) {
      if (errno == EINTR) continue;
      throwSystem(path, "write failed", errno);
    }
    done += static_cast<std::size_t>(w);
  }
}

void fsyncDirectory(const std::filesystem::path& dir) {
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
  if (dfd >= 0) {
    (void)::fsync(dfd);
    ::close(dfd);
  }
}

// A temporary directory beside a sequence's files; removed with whatever it holds unless emptied.
class StagedDirectory {
 public:
  explicit StagedDirectory(const ExportTarget& target) : dir_(directoryOf(target.path)) {
    std::string tmpl = (dir_ / ("." + target.prefix + "tetrig-export-XXXXXX")).string();
    std::vector<char> name(tmpl.begin(), tmpl.end());
    name.push_back('\0');
    if (mkdtemp(name.data()) == nullptr) throwSystem(target.path, "cannot create a temporary directory in " + dir_.string(), errno);
    tmp_ = name.data();
  }
  StagedDirectory(const StagedDirectory&) = delete;
  StagedDirectory& operator=(const StagedDirectory&) = delete;
  ~StagedDirectory() {
    std::error_code ec;
    std::filesystem::remove_all(tmp_, ec);
  }
  // Writes one file into the temporary directory; remembers where it goes.
  void write(const std::filesystem::path& final_path, std::span<const std::uint8_t> bytes) {
    const std::filesystem::path staged = tmp_ / final_path.filename();
    const int fd = ::open(staged.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);  // umask applies, as for AtomicFile
    if (fd < 0) throwSystem(staged, "cannot create", errno);
    try {
      writeAll(fd, bytes.data(), bytes.size(), staged);
    } catch (...) {
      ::close(fd);
      throw;
    }
    if (::close(fd) != 0) throwSystem(staged, "close failed", errno);
    files_.push_back({staged, final_path});
    bytes_ += bytes.size();
  }
  // Syncs the file system once, then renames every file into place and syncs the directory.
  void commit() {
    const int dfd = ::open(tmp_.c_str(), O_RDONLY | O_DIRECTORY);
    if (dfd < 0) throwSystem(tmp_, "cannot open", errno);
    const int synced = ::syncfs(dfd);
    const int err = errno;
    ::close(dfd);
    if (synced != 0) throwSystem(tmp_, "syncfs failed", err);
    for (const auto& [staged, final_path] : files_) {
      if (::rename(staged.c_str(), final_path.c_str()) != 0) throwSystem(final_path, "cannot rename the staged frame into place", errno);
    }
    fsyncDirectory(dir_);
  }
  std::uint64_t bytes() const { return bytes_; }
  std::vector<std::filesystem::path> finalPaths() const {
    std::vector<std::filesystem::path> out;
    for (const auto& f : files_) out.push_back(f.second);
    return out;
  }

 private:
  std::filesystem::path dir_, tmp_;
  std::vector<std::pair<std::filesystem::path, std::filesystem::path>> files_;
  std::uint64_t bytes_ = 0;
};

std::string formatName(ExportFormat f) {
  switch (f) {
    case ExportFormat::kPc2: return "PC2 point cache + OBJ rest mesh";
    case ExportFormat::kObjSequence: return "OBJ sequence";
    case ExportFormat::kPlySequence: return "PLY sequence";
    case ExportFormat::kGltf: return "glTF 2.0 (.gltf, embedded buffer)";
    case ExportFormat::kGlb: return "glTF 2.0 (.glb)";
  }
  return "?";
}

double maxChange(const std::vector<float>& a, const std::vector<float>& b) {
  double worst = 0.0;
  for (std::size_t i = 0; i + 2 < a.size(); i += 3) {
    const double dx = a[i] - b[i], dy = a[i + 1] - b[i + 1], dz = a[i + 2] - b[i + 2];
    worst = std::max(worst, dx * dx + dy * dy + dz * dz);
  }
  return std::sqrt(worst);
}

double restDiagonal(std::span<const float> rest) {
  float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (std::size_t i = 0; i < rest.size(); ++i) {
    lo[i % 3] = std::min(lo[i % 3], rest[i]);
    hi[i % 3] = std::max(hi[i % 3], rest[i]);
  }
  const double dx = hi[0] - lo[0], dy = hi[1] - lo[1], dz = hi[2] - lo[2];
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

std::string rateText(double hz) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", hz);
  return buf;
}

nlohmann::json percentilesJson(const rigbuild::Percentiles& p) {
  return {{"median", p.median}, {"p90", p.p90}, {"p99", p.p99}, {"max", p.max}, {"count", p.count}};
}

// --report: what the export did and how well the skin followed the markers (docs/export.md).
nlohmann::json reportJson(const ExportReport& r, const ExportOptions& o, const Rig& rig) {
  nlohmann::json per = nlohmann::json::object();
  for (const auto& [label, p] : r.tracking_per_marker_mm) per[label] = percentilesJson(p);
  nlohmann::json tracking = percentilesJson(r.tracking_mm);
  tracking["per_marker"] = std::move(per);
  nlohmann::json files = nlohmann::json::array();
  for (const auto& f : r.files) files.push_back(f.string());
  return {{"generator", "tetrig export"},
          {"rig", o.rig_path.string()},
          {"rig_name", rig.name},
          {"clip", o.clip_path.string()},
          {"first_frame", r.first_frame},
          {"frames", r.frame_count},
          {"rate_hz", r.rate_hz},
          {"iterations_per_frame", o.iterations},
          {"iterations", r.iterations},
          {"markers_bound", r.markers_bound},
          {"markers_missing", r.markers_missing},
          {"frames_held", r.held_frames},
          {"frames_with_predicted_markers", r.predicted_frames},
          {"solver", solverJson(r.solver)},
          {"volume_not_kept", r.volume_not_kept},
          {"files", std::move(files)},
          {"tracking_mm", std::move(tracking)}};
}

// A file of the rig's asset (relative to the asset's folder at build time, or absolute) as seen
// from `out_dir`: a relative path when the file is there now, else as the asset named it (and
// listed in `missing`).
std::string assetReference(const RigSurfaceAttributes& s, const std::string& file, const std::filesystem::path& out_dir,
                           std::vector<std::string>& missing) {
  if (file.empty()) return {};
  std::filesystem::path p(file);
  if (p.is_relative() && !s.asset.empty()) p = std::filesystem::path(s.asset).parent_path() / p;
  std::error_code ec;
  if (p.is_absolute() && std::filesystem::is_regular_file(p, ec)) {
    const std::filesystem::path base = std::filesystem::absolute(out_dir, ec);
    const std::filesystem::path relative = ec ? std::filesystem::path() : std::filesystem::relative(p, base, ec);
    return !ec && !relative.empty() ? relative.generic_string() : p.lexically_normal().generic_string();
  }
  missing.push_back(file);
  return file;
}

// The rig's texture coordinates and materials for files written into `out_dir` (the arrays are the rig's).
SurfaceLayout surfaceLayout(const Rig& rig, const std::filesystem::path& out_dir, std::vector<std::string>& missing) {
  const RigSurfaceAttributes& s = rig.surface;
  SurfaceLayout layout;
  if (s.empty()) return layout;
  for (const std::string& library : s.material_libraries) layout.material_libraries.push_back(assetReference(s, library, out_dir, missing));
  for (const RigMaterial& m : s.materials) {
    layout.materials.push_back(
        {m.name, assetReference(s, m.diffuse_texture, out_dir, missing), {m.diffuse_color.x(), m.diffuse_color.y(), m.diffuse_color.z()}});
  }
  layout.uvs = std::span<const double>(s.uvs.data(), static_cast<std::size_t>(s.uvs.size()));
  if (s.uvs.rows() > 0) layout.corner_uvs = std::span<const std::int32_t>(s.corner_uvs.data(), static_cast<std::size_t>(s.corner_uvs.size()));
  if (!s.materials.empty()) layout.triangle_materials = s.triangle_materials;
  return layout;
}

}  // namespace

ExportTarget parseExportTarget(const std::filesystem::path& out) {
  static const char* kForms =
      "FILE.pc2 (+ FILE.rest.obj beside it), NAME_####.obj or NAME_####.ply (a sequence: the #s become the frame number), "
      "FILE.gltf or FILE.glb";
  if (out.empty()) throw std::invalid_argument("--out is empty; give " + std::string(kForms));
  const std::string text = out.string();
  if (text.back() == '/' || std::filesystem::is_directory(out))
    throw std::invalid_argument("--out " + text + " is a directory; give a file name or a sequence pattern inside it, e.g. " +
                                (out / "frame_####.obj").string());
  ExportTarget t;
  t.path = out;
  const std::string ext = lower(out.extension().string());
  const std::string dir = out.has_parent_path() ? out.parent_path().string() : std::string();
  if (dir.find('#') != std::string::npos) throw std::invalid_argument("--out " + text + ": '#' belongs in the file name, not in a directory");
  const std::string name = out.filename().string();
  const std::size_t hash = name.find('#');
  if (ext == ".obj" || ext == ".ply") {
    t.format = ext == ".obj" ? ExportFormat::kObjSequence : ExportFormat::kPlySequence;
    if (hash == std::string::npos)
      throw std::invalid_argument("--out " + text + ": an " + ext.substr(1) + " sequence needs a frame-number pattern such as " +
                                  (out.parent_path() / (out.stem().string() + "_####" + out.extension().string())).string() +
                                  " (for one OBJ with a point cache use FILE.pc2)");
    std::size_t end = hash;
    while (end < name.size() && name[end] == '#') ++end;
    if (name.find('#', end) != std::string::npos)
      throw std::invalid_argument("--out " + text + ": one run of '#' only (it becomes the zero-padded frame number)");
    t.prefix = name.substr(0, hash);
    t.suffix = name.substr(end);
    t.digits = static_cast<int>(end - hash);
    return t;
  }
  if (hash != std::string::npos)
    throw std::invalid_argument("--out " + text + ": '#' frame patterns are for OBJ and PLY sequences only");
  if (ext == ".pc2") {
    t.format = ExportFormat::kPc2;
    t.rest_obj = rigbuild::pc2RestObjPath(out);
    return t;
  }
  if (ext == ".gltf") {
    t.format = ExportFormat::kGltf;
    return t;
  }
  if (ext == ".glb") {
    t.format = ExportFormat::kGlb;
    return t;
  }
  throw std::invalid_argument("--out " + text + ": unknown output format '" + (ext.empty() ? std::string("(no extension)") : ext) +
                              "'; known: " + kForms);
}

std::filesystem::path sequenceFramePath(const ExportTarget& target, std::size_t frame) {
  std::string number = std::to_string(frame);
  if (number.size() < static_cast<std::size_t>(target.digits)) number.insert(0, static_cast<std::size_t>(target.digits) - number.size(), '0');
  return directoryOf(target.path) / (target.prefix + number + target.suffix);
}

FrameRange parseFrameRange(const std::string& text, std::size_t clip_frames) {
  const std::string clip = "the clip has " + std::to_string(clip_frames) + " frames (0.." +
                           (clip_frames ? std::to_string(clip_frames - 1) : std::string("none")) + ")";
  if (clip_frames == 0) throw std::invalid_argument("the clip has no frames");
  FrameRange r{0, clip_frames};
  if (text.empty()) return r;
  const std::size_t colon = text.find(':');
  if (colon == std::string::npos || text.find(':', colon + 1) != std::string::npos)
    throw std::invalid_argument("--range " + text + ": expected A:B (first frame A, end B exclusive, 0-based; A: or :B allowed)");
  auto number = [&](const std::string& part, std::size_t fallback) -> std::size_t {
    if (part.empty()) return fallback;
    std::size_t value = 0;
    for (const char c : part) {
      if (c < '0' || c > '9' || value > 1'000'000'000'000ull)
        throw std::invalid_argument("--range " + text + ": '" + part + "' is not a frame number (A:B, 0-based)");
      value = value * 10 + static_cast<std::size_t>(c - '0');
    }
    return value;
  };
  r.first = number(text.substr(0, colon), 0);
  r.end = number(text.substr(colon + 1), clip_frames);
  if (r.first >= clip_frames) throw std::invalid_argument("--range " + text + ": first frame " + std::to_string(r.first) + " is past the end; " + clip);
  if (r.end > clip_frames) throw std::invalid_argument("--range " + text + ": end " + std::to_string(r.end) + " is past the end; " + clip);
  if (r.end <= r.first) throw std::invalid_argument("--range " + text + ": the range is empty (B is exclusive: A:B needs B > A)");
  return r;
}

namespace {

// Refuses iteration and solver settings that cannot work, before anything is read or written.
void checkExportSettings(const ExportOptions& o) {
  if (o.iterations < 0) throw std::invalid_argument("--iterations must be at least 1 (or omitted: iterate to convergence)");
  if (o.iterations == 0 && (!(o.tolerance > 0.0) || !std::isfinite(o.tolerance)))
    throw std::invalid_argument("--tolerance must be a positive number");
  if (o.iterations == 0 && o.max_iterations < 1) throw std::invalid_argument("--max-iterations must be at least 1");
  checkSolverSettings(o.solver);  // before anything is written
  if (o.solver.after_publish_iterations > 0 && o.iterations == 0)
    throw std::invalid_argument("--after-publish-iterations needs --iterations N: a frame solved to convergence has nothing left to refine");
}

// Every file this export would write, checked before any work: no input and no file tetrig
// did not write is replaced (without --force).
void checkOutputFiles(const ExportOptions& o, const ExportTarget& target, const FrameRange& range) {
  const std::filesystem::path inputs[] = {o.rig_path, o.clip_path};
  switch (target.format) {
    case ExportFormat::kPc2:
      rigbuild::checkOutputPath(target.path, rigbuild::OutputKind::kPc2, inputs, o.force);
      rigbuild::checkOutputPath(target.rest_obj, rigbuild::OutputKind::kObj, inputs, o.force, "--out's rest mesh");
      break;
    case ExportFormat::kObjSequence:
    case ExportFormat::kPlySequence: {
      const auto kind = target.format == ExportFormat::kObjSequence ? rigbuild::OutputKind::kObj : rigbuild::OutputKind::kPly;
      for (std::size_t f = range.first; f < range.end; ++f)
        rigbuild::checkOutputPath(sequenceFramePath(target, f), kind, inputs, o.force, "--out's frame");
      break;
    }
    case ExportFormat::kGltf:
    case ExportFormat::kGlb:
      rigbuild::checkOutputPath(target.path, target.format == ExportFormat::kGlb ? rigbuild::OutputKind::kGlb : rigbuild::OutputKind::kGltf,
                                inputs, o.force);
      break;
  }
  if (!o.report.empty()) rigbuild::checkOutputPath(o.report, rigbuild::OutputKind::kJson, inputs, o.force, "--report");
}

// glTF: the rig's up axis can be turned to +Y, and the clip has a frame rate (sample times).
void checkGltfInputs(const Rig& rig, double rate_hz) {
  std::vector<float> probe(3, 0.0f);
  rotateUpToY(rig.alignment.rig_up, probe);  // an unknown up axis is refused before any work
  if (!(rate_hz > 0.0))
    throw std::invalid_argument("the clip has no frame rate and glTF needs sample times: give --rate HZ");
}

// The live rig's options for an export: the solver flags, the occlusion blend, normals for glTF.
LiveRigOptions exportLiveOptions(const ExportOptions& o, bool gltf) {
  LiveRigOptions live_options;
  live_options.solver = o.solver;
  live_options.occlusion_blend_s = o.occlusion_blend_ms * 1e-3;
  // The temporal prediction and the rig's coarse level (docs/fidelity.md) only set where a frame
  // starts: with --iterations N (one call per frame) they run as in `tetrig run`; iterating to
  // convergence calls processFrame again on the same frame, where they would start the frame again,
  // so they are off.
  if (o.iterations == 0) {
    live_options.solver.rotation_extrapolation = 0.0;
    live_options.solver.use_coarse_level = false;
  }
  live_options.normals = gltf;  // glTF carries the live rig's vertex normals (base NORMAL and morph-target deltas)
  return live_options;
}

// The clip's marker labels, as a c3d: source names them to `tetrig run`.
std::vector<std::string> clipLabels(const std::shared_ptr<const drivers::C3DClip>& clip, const drivers::C3DPlaybackOptions& playback_options,
                                    const std::filesystem::path& clip_path) {
  std::vector<std::string> labels;
  const auto source = drivers::makeC3DSource(clip, playback_options, clip_path.string());
  (void)source->waitForLabels(std::chrono::milliseconds(0), labels);
  return labels;
}

// Refuses a clip that shares no marker or sensor label with the rig.
void requireSharedLabel(const MarkerBindingReport& binding, const Rig& rig, const std::vector<std::string>& labels,
                        const std::filesystem::path& clip_path) {
  if (binding.matched == 0 && binding.sensors_matched == 0) {
    std::vector<std::string> rig_labels, named;
    for (const RigMarker& m : rig.markers) rig_labels.push_back(m.label);
    for (const std::string& l : labels)
      if (!l.empty()) named.push_back(l);
    throw std::invalid_argument("the clip's markers share no label with the rig (rig: " + joinLabels(rig_labels) + "; clip " +
                                clip_path.filename().string() + ": " + (named.empty() ? std::string("none") : joinLabels(named)) +
                                "): export a clip of the marker set the rig was built from");
  }
}

// Comment lines of the OBJ/PLY files; the Blender add-on reads the key=value line.
std::vector<std::string> exportComment(const Rig& rig, const ExportOptions& o, const FrameRange& range, const ExportReport& report,
                                       const std::string& frames_text) {
  return {
      "tetrig export: " + commentText(rig.name) + ", clip " + commentText(o.clip_path.filename().string()) + " frames " + frames_text,
      "tetrig-export first_frame=" + std::to_string(range.first) + " frames=" + std::to_string(report.frame_count) +
          " rate_hz=" + rateText(report.rate_hz) + " unit=" + commentText(rig.unit) + " up=" + commentText(rig.alignment.rig_up) +
          " vertices=" + std::to_string(report.vertices)};
}

// A PLY sequence's per-vertex texture coordinates: none when the asset has none or has seams.
std::optional<std::vector<float>> plyVertexUvs(const ExportTarget& target, const SurfaceLayout& surface, const LiveRig& live,
                                               std::span<const std::int32_t> triangles, rigbuild::Progress& progress) {
  std::optional<std::vector<float>> ply_uvs;
  if (target.format == ExportFormat::kPlySequence && !surface.corner_uvs.empty()) {
    ply_uvs = perVertexUvs(static_cast<std::size_t>(live.fineVertexCount()), triangles, surface);
    if (!ply_uvs)
      progress.note("note: the asset's texture coordinates have seams (vertices with several uvs), which a PLY vertex cannot hold: "
                    "the PLY frames carry none (OBJ and glTF do)");
  }
  return ply_uvs;
}

// What the meshes of an export share: the fine triangles, the comment lines, the asset's surface
// (or nullptr) and a PLY sequence's per-vertex uvs.
struct ExportMeshes {
  std::span<const std::int32_t> triangles;
  const std::vector<std::string>& comment;
  const SurfaceLayout* surface;
  const std::optional<std::vector<float>>& ply_uvs;
};

// The output files: staged before solving, written frame by frame, put in place at the end.
struct ExportOutputs {
  explicit ExportOutputs(const ExportTarget& t) : target(t) {}

  const ExportTarget& target;
  std::optional<AtomicFile> pc2, rest_obj;
  std::uint64_t pc2_bytes = 0, rest_obj_bytes = 0;
  std::optional<StagedDirectory> sequence;
  std::vector<float> gltf_frames, gltf_normals;
  std::vector<std::uint8_t> sample;

  // Opens the outputs (a directory that refuses files fails now, not after minutes): PC2 with its
  // header and rest OBJ, a sequence's staging directory, or room for glTF's frames.
  void stage(const LiveRig& live, const FrameRange& range, const ExportReport& report, std::span<const float> rest, const ExportMeshes& m,
             std::size_t values, bool gltf) {
    if (target.format == ExportFormat::kPc2) {
      pc2.emplace(target.path);
      rest_obj.emplace(target.rest_obj);
      const auto header = pc2Header(live.fineVertexCount(), static_cast<float>(range.first), 1.0f, static_cast<std::int32_t>(report.frame_count));
      pc2->write(header.data(), header.size());
      pc2_bytes += header.size();
      std::vector<std::string> obj_comment = m.comment;
      obj_comment.insert(obj_comment.begin() + 1, "rest fine mesh; the animation is the point cache " + target.path.filename().string());
      const std::string text = objText(rest, m.triangles, obj_comment, m.surface);
      rest_obj->write(text.data(), text.size());
      rest_obj_bytes = text.size();
    } else if (!gltf) {
      sequence.emplace(target);
    } else {
      gltf_frames.reserve(report.frame_count * values);
      gltf_normals.reserve(report.frame_count * values);
    }
  }

  // Writes clip frame f's fine mesh x (and its normals, for glTF).
  void writeFrame(std::size_t f, const std::vector<float>& x, const std::vector<float>& normals, const ExportMeshes& m) {
    switch (target.format) {
      case ExportFormat::kPc2:
        sample.clear();
        appendPc2Sample(x, sample);
        pc2->write(sample.data(), sample.size());
        pc2_bytes += sample.size();
        break;
      case ExportFormat::kObjSequence: {
        const std::string text = objText(x, m.triangles, m.comment, m.surface);
        sequence->write(sequenceFramePath(target, f), std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
        break;
      }
      case ExportFormat::kPlySequence:
        sequence->write(sequenceFramePath(target, f),
                        plyBytes(x, m.triangles, m.comment, m.ply_uvs ? std::span<const float>(*m.ply_uvs) : std::span<const float>()));
        break;
      case ExportFormat::kGltf:
      case ExportFormat::kGlb:
        gltf_frames.insert(gltf_frames.end(), x.begin(), x.end());
        gltf_normals.insert(gltf_normals.end(), normals.begin(), normals.end());
        break;
    }
  }

  // Renames the staged files into place (glTF: writes the whole file); records the files and bytes.
  void finish(const Rig& rig, const LiveRig& live, std::span<const float> rest, const FrameRange& range, const ExportMeshes& m,
              ExportReport& report) {
    switch (target.format) {
      case ExportFormat::kPc2:
        rest_obj->commit();
        pc2->commit();
        report.files = {target.rest_obj, target.path};
        report.bytes = rest_obj_bytes + pc2_bytes;
        break;
      case ExportFormat::kObjSequence:
      case ExportFormat::kPlySequence:
        sequence->commit();
        report.files = sequence->finalPaths();
        report.bytes = sequence->bytes();
        break;
      case ExportFormat::kGltf:
      case ExportFormat::kGlb: {
        // glTF is +Y up: a rig with another up axis is turned (positions exact: axis permutations).
        std::vector<float> rest_y(rest.begin(), rest.end()), rest_normals_y(live.restNormals().begin(), live.restNormals().end());
        rotateUpToY(rig.alignment.rig_up, rest_y);
        rotateUpToY(rig.alignment.rig_up, gltf_frames);
        rotateUpToY(rig.alignment.rig_up, rest_normals_y);
        rotateUpToY(rig.alignment.rig_up, gltf_normals);
        GltfAnimation anim;
        anim.name = rig.name;
        anim.rest = rest_y;
        anim.triangles = m.triangles;
        anim.frames = gltf_frames;
        anim.rest_normals = rest_normals_y;
        anim.frame_normals = gltf_normals;
        anim.surface = m.surface;
        anim.frame_count = report.frame_count;
        anim.rate_hz = report.rate_hz;
        anim.first_frame = static_cast<std::int64_t>(range.first);
        const std::vector<std::uint8_t> bytes = gltfBytes(anim, target.format == ExportFormat::kGlb);
        rigbuild::writeFileAtomically(target.path, bytes);
        report.files = {target.path};
        report.bytes = bytes.size();
        break;
      }
    }
  }
};

// Solves the clip frame by frame into x (and the normals, for glTF); measures how closely the skin
// follows the markers.
struct FrameSolver {
  FrameSolver(LiveRig& l, const Rig& rig, const ExportOptions& options, double tol, std::span<const float> rest, std::size_t values, bool gltf)
      : live(l), o(options), tolerance(tol), x(rest.begin(), rest.end()), previous(values), normals(gltf ? values : 0),
        normals_out(gltf ? normals.data() : nullptr), tracking(rig) {}

  LiveRig& live;
  const ExportOptions& o;
  const double tolerance;  // convergence: a fine vertex that moved more than this (rig units) is still moving
  std::vector<float> x, previous, normals;
  float* const normals_out;
  MarkerFrame frame{};
  std::size_t measured_frames = 0;
  rigbuild::TrackingMeasure tracking;

  // Solves clip frame f (in `frame`): --iterations N, or to convergence (chunks of iterations until
  // no fine vertex moves more than `tolerance`, at most --max-iterations). Counts held, measured,
  // predicted and capped frames and the iterations; a rejected pose or target is an error.
  void solve(std::size_t f, ExportReport& report) {
    std::int32_t frame_iterations = 0;
    const int first_budget = o.iterations > 0 ? o.iterations : std::min(kConvergeChunkIterations, o.max_iterations);
    LiveFrameStats s = live.processFrame(frame, StepBudget{first_budget}, x.data(), normals_out);
    frame_iterations += s.step.iterations;
    if (s.flags & kLivePoseHeld) ++report.held_frames;
    else ++measured_frames;
    if (s.flags & kLiveMarkersPredicted) ++report.predicted_frames;
    if (o.iterations == 0 && !(s.flags & kLivePoseHeld)) {
      double change = INFINITY;
      while (frame_iterations < o.max_iterations) {
        previous.swap(x);
        const LiveFrameStats more =
            live.processFrame(frame, StepBudget{std::min(kConvergeChunkIterations, o.max_iterations - frame_iterations)}, x.data(), normals_out);
        s.flags |= more.flags;
        frame_iterations += more.step.iterations;
        change = maxChange(x, previous);
        if (change <= tolerance || more.step.iterations == 0) break;
      }
      if (change > tolerance && frame_iterations >= o.max_iterations) {
        ++report.capped_frames;
        report.worst_last_change = std::max(report.worst_last_change, change);
      }
    }
    if (s.flags & kLivePoseRejected)
      throw std::runtime_error("clip frame " + std::to_string(f) + ": the solver produced a non-finite or implausible pose (far outside its marker targets; a bug: please report it with the rig and the clip)");
    if (s.flags & kLiveTargetsRejected)
      throw std::runtime_error("clip frame " + std::to_string(f) + ": the solver rejected the marker targets as non-finite or absurd");
    tracking.addFrame(x, live);
    report.iterations += static_cast<std::uint64_t>(frame_iterations);
    report.max_frame_iterations = std::max(report.max_frame_iterations, frame_iterations);
  }
};

// Notes on stderr: an open fine mesh (its volume is not kept), rig markers the clip never names.
void noteBinding(rigbuild::Progress& progress, const LiveRig& live, const MarkerBindingReport& binding) {
  if (live.volumeNotKept())
    progress.note("note: the rig's fine mesh is not closed, so its volume is not kept (the volume constraint needs a watertight surface)");
  if (!binding.missing.empty())
    progress.note("note: " + std::to_string(binding.missing.size()) + " rig markers the clip never names are predicted in every frame: " +
                  joinLabels(binding.missing));
}

// --report: the JSON report, written atomically and counted among the files.
void writeReportFile(const ExportOptions& o, const Rig& rig, ExportReport& report) {
  const std::string text = reportJson(report, o, rig).dump(2) + "\n";
  rigbuild::writeFileAtomically(o.report, std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(text.data()), text.size()));
  report.files.push_back(o.report);
  report.bytes += text.size();
}

}  // namespace

ExportReport exportClip(const ExportOptions& o) {
  checkExportSettings(o);
  ExportReport report;
  report.target = parseExportTarget(o.out);
  const ExportTarget& target = report.target;
  const bool gltf = target.format == ExportFormat::kGltf || target.format == ExportFormat::kGlb;

  // 1. Rig, clip, range (everything that can be refused is refused before any work).
  const Rig rig = loadRigFile(o.rig_path);
  drivers::C3DReadOptions read_options;
  read_options.keep_zero_points = o.keep_zero_markers;
  auto clip = std::make_shared<const drivers::C3DClip>(drivers::C3DClip::load(o.clip_path, read_options));
  const FrameRange range = parseFrameRange(o.frames, clip->frameCount());
  report.first_frame = range.first;
  report.frame_count = range.end - range.first;
  drivers::C3DPlaybackOptions playback_options;
  playback_options.pacing = drivers::Pacing::kAsFastAsPossible;
  playback_options.rate_override_hz = o.rate_hz;
  const drivers::C3DPlayback playback(*clip, playback_options);
  report.rate_hz = playback.framePeriodNs() > 0 ? playback.frameRate() : 0.0;
  if (gltf && report.frame_count > kMaxGltfFrames)
    throw std::invalid_argument("glTF holds one morph target per frame and frames x frames animated weights: " +
                                std::to_string(report.frame_count) + " frames is more than " + std::to_string(kMaxGltfFrames) +
                                "; export a range with --range A:B, or use FILE.pc2 or an OBJ/PLY sequence");
  checkOutputFiles(o, target, range);
  if (gltf) checkGltfInputs(rig, report.rate_hz);

  // 2. The live rig and the binding, exactly as `tetrig run` binds a c3d: source.
  const LiveRigOptions live_options = exportLiveOptions(o, gltf);
  LiveRig live(rig, live_options);
  report.solver = live_options.solver;
  report.volume_not_kept = live.volumeNotKept();
  const std::vector<std::string> labels = clipLabels(clip, playback_options, o.clip_path);
  const MarkerBindingReport binding = live.bindLabels(labels);
  requireSharedLabel(binding, rig, labels, o.clip_path);
  report.markers_bound = binding.matched;
  report.markers_missing = static_cast<std::int32_t>(binding.missing.size());
  report.vertices = live.fineVertexCount();
  report.triangles = static_cast<std::int32_t>(live.fineTriangles().size() / 3);
  const std::size_t values = static_cast<std::size_t>(live.fineVertexCount()) * 3;
  const auto triangles = live.fineTriangles();
  const auto rest = live.restPositions();

  rigbuild::Progress progress("tetrig export", o.quiet ? rigbuild::Progress::Mode::kQuiet
                                                       : o.simple_progress ? rigbuild::Progress::Mode::kSimple
                                                                           : rigbuild::Progress::Mode::kAuto);
  noteBinding(progress, live, binding);

  std::string frames_text = std::to_string(range.first) + ".." + std::to_string(range.end - 1);
  const std::vector<std::string> comment = exportComment(rig, o, range, report, frames_text);

  // The asset's texture coordinates and materials (Rig::surface), files referenced from the output's folder.
  std::vector<std::string> missing_files;
  const SurfaceLayout surface = surfaceLayout(rig, directoryOf(target.path), missing_files);
  const SurfaceLayout* surface_ptr = rig.surface.empty() ? nullptr : &surface;
  for (const std::string& m : missing_files)
    progress.note("note: the asset's file " + printableText(m, 200) + " is not beside the asset the rig was built from (" +
                  printableText(rig.surface.asset, 200) + "): referenced as the asset names it");
  const std::optional<std::vector<float>> ply_uvs = plyVertexUvs(target, surface, live, triangles, progress);
  const ExportMeshes meshes{triangles, comment, surface_ptr, ply_uvs};

  // 3. Outputs staged before solving (a directory that refuses files fails now, not after minutes).
  ExportOutputs outputs(target);
  outputs.stage(live, range, report, rest, meshes, values, gltf);

  // 4. Solve frame by frame, write as we go.
  progress.begin("solving " + std::to_string(report.frame_count) + " frames (" +
                 (o.iterations > 0 ? std::to_string(o.iterations) + " iterations each" : std::string("to convergence")) + ")");
  const auto solve_start = std::chrono::steady_clock::now();
  double write_seconds = 0;
  FrameSolver solver(live, rig, o, o.tolerance * restDiagonal(rest), rest, values, gltf);
  for (std::size_t f = range.first; f < range.end; ++f) {
    playback.fillFrame(f, f, solver.frame);
    solver.solve(f, report);
    const auto write_start = std::chrono::steady_clock::now();
    outputs.writeFrame(f, solver.x, solver.normals, meshes);
    write_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - write_start).count();
    const std::size_t done = f - range.first + 1;
    progress.update(static_cast<double>(done) / static_cast<double>(report.frame_count));
    if (o.on_frame) o.on_frame(done, report.frame_count);
  }
  report.solve_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - solve_start).count() - write_seconds;
  char detail[160];
  std::snprintf(detail, sizeof detail, "%.2f iterations per frame (max %d)", static_cast<double>(report.iterations) / static_cast<double>(report.frame_count),
                report.max_frame_iterations);
  progress.end(detail);
  if (solver.measured_frames == 0)
    throw std::invalid_argument("no frame in " + frames_text + " measures any rig marker (every marker invalid or unnamed): "
                                "nothing to export; check the clip and --frames");

  // 5. Finish and rename into place.
  progress.begin("writing " + target.path.string());
  const auto finish_start = std::chrono::steady_clock::now();
  outputs.finish(rig, live, rest, range, meshes, report);
  report.tracking_mm = solver.tracking.all();
  for (std::size_t m = 0; m < rig.markers.size(); ++m) report.tracking_per_marker_mm.emplace_back(rig.markers[m].label, solver.tracking.marker(m));
  if (!o.report.empty()) writeReportFile(o, rig, report);
  report.write_seconds = write_seconds + std::chrono::duration<double>(std::chrono::steady_clock::now() - finish_start).count();
  progress.end(std::to_string(report.files.size()) + (report.files.size() == 1 ? " file, " : " files, ") + megabytes(report.bytes));
  return report;
}

int runExport(const ExportOptions& options) {
  const StopSignalScope signals;
  ExportOptions o = options;
  o.on_frame = [inner = options.on_frame](std::size_t done, std::size_t total) {
    if (const int stop = StopSignalScope::pending(); stop != 0)
      throw std::runtime_error(std::string(StopSignalScope::describe(stop)) + " after " +
                               std::to_string(done) + " of " + std::to_string(total) + " frames; nothing was written");
    if (inner) inner(done, total);
  };
  const ExportReport r = exportClip(o);
  if (options.quiet) return 0;
  std::printf("tetrig export: %s, clip frames %zu..%zu (%zu frames%s), %d vertices, %d triangles\n", formatName(r.target.format).c_str(),
              r.first_frame, r.first_frame + r.frame_count - 1, r.frame_count,
              r.rate_hz > 0 ? (", " + rateText(r.rate_hz) + " Hz").c_str() : ", no frame rate", r.vertices, r.triangles);
  std::printf("  markers: %d bound by label, %d never named (predicted); frames: %zu with predicted markers, %zu held (no marker measured)\n",
              r.markers_bound, r.markers_missing, r.predicted_frames, r.held_frames);
  if (options.iterations > 0) {
    std::printf("  solver: %d iterations per frame, no deadline; %.2f s\n", options.iterations, r.solve_seconds);
  } else {
    std::printf("  solver: to convergence (no vertex moving more than %g of the mesh size in %d iterations), %.2f iterations per frame, "
                "max %d; %.2f s\n",
                options.tolerance, kConvergeChunkIterations, static_cast<double>(r.iterations) / static_cast<double>(r.frame_count),
                r.max_frame_iterations, r.solve_seconds);
    if (r.capped_frames > 0)
      std::printf("  note: %zu frames stopped at --max-iterations %d still moving (largest last change %.3g rig units)\n", r.capped_frames,
                  options.max_iterations, r.worst_last_change);
  }
  if (r.files.size() <= 2) {
    for (const auto& f : r.files) std::printf("  wrote %s\n", f.string().c_str());
  } else {
    std::printf("  wrote %zu files %s .. %s\n", r.files.size(), r.files.front().string().c_str(), r.files.back().string().c_str());
  }
  std::printf("  tracking (change of each measured marker's distance to its skin point): median %.1f mm, p90 %.1f, p99 %.1f, max %.1f "
              "over %zu marker-frames\n",
              r.tracking_mm.median, r.tracking_mm.p90, r.tracking_mm.p99, r.tracking_mm.max, r.tracking_mm.count);
  std::printf("  %s in all, written in %.2f s\n", megabytes(r.bytes).c_str(), r.write_seconds);
  return 0;
}

}  // namespace tetrig::tools
