// The `tetrig` command: build-rig, inspect, run, demo, export, pose, make-character, view. Every subcommand has --help; errors print one
// line "tetrig <cmd>: error: ..." on stderr and exit non-zero; no partial output file is left.
#include "character/make_character.hpp"
#include "demo.hpp"
#include "export.hpp"
#include "pose.hpp"
#include "run.hpp"
#include "solver_flags.hpp"
#include "view.hpp"
#include "tetrig/drivers/character_performance.hpp"
#include "tetrig/printable_text.hpp"
#include "tetrig/rig_file.hpp"
#include "tetrig/rigbuild/build_rig.hpp"
#include "tetrig/rigbuild/describe_rig.hpp"
#include "tetrig/rigbuild/output_guard.hpp"
#include "tetrig/rigbuild/progress.hpp"
#include "tetrig/rigbuild/rig_description.hpp"
#include "tetrig/rigbuild/write_file_atomic.hpp"
#include "tetrig/version.h"

#include <CLI/CLI.hpp>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace {

using namespace tetrig;
using namespace tetrig::rigbuild;

struct BuildArgs {
  std::string mesh, out, rig_json, markers;
  std::int32_t tet_vertices = 0;
  std::int32_t coarse_tet_vertices = -1;  // > 0: also build the coarse level; 0: none; -1: the default (kDefaultCoarseTetVertices)
  std::string frame;                 // "" (the description's, default 0), a 0-based frame, or "auto"
  double max_marker_distance = 0;
  double min_fit_scale = 0, max_fit_scale = 0;
  bool accept_implausible_alignment = false, accept_pose_mismatch = false;
  std::string mesh_unit, mesh_up, device_up, alignment;
  bool quiet = false, simple = false, list_markers = false, keep_zero_markers = false, force = false;
};

std::string joinWords(const std::vector<std::string>& words) {
  std::string out;
  for (const std::string& w : words) out += (out.empty() ? "" : ", ") + w;
  return out;
}

// What build-rig's user does next: whether the rig is ready, the markers worth a look, the next
// commands.
std::string buildVerdict(const Rig& rig, const std::string& out, const std::string& clip) {
  std::string text = "\nverdict: ";
  if (rig.markers.empty()) {
    return text + "built, with no markers: handles and regions move it (tetrig pose " + out + " --region NAME=FILE.def --out posed.obj)\n";
  }
  const double mm = rig.alignment.rig_units_per_mm > 0 ? 1.0 / rig.alignment.rig_units_per_mm : 1.0;
  std::vector<std::pair<double, std::string>> far;
  std::vector<double> distances;
  for (const RigMarker& m : rig.markers) distances.push_back(m.surface_distance * mm);
  std::vector<double> sorted = distances;
  std::sort(sorted.begin(), sorted.end());
  const double median = sorted[sorted.size() / 2];
  // A marker well beyond the others' distance from the skin: placed elsewhere on the performer
  // than on the character, or a body of other proportions there.
  for (std::size_t i = 0; i < rig.markers.size(); ++i) {
    if (distances[i] > std::max(30.0, 2.5 * median)) far.emplace_back(distances[i], rig.markers[i].label);
  }
  std::sort(far.rbegin(), far.rend());
  char line[200];
  std::snprintf(line, sizeof line, "the rig is ready: %zu markers, %.0f mm from the skin (median)", rig.markers.size(), median);
  text += line;
  if (far.empty()) {
    text += ", none far from it.\n";
  } else {
    text += "; further (check where they sit on the performer and on the character):";
    for (std::size_t i = 0; i < far.size() && i < 6; ++i) {
      std::snprintf(line, sizeof line, " %s %.0f mm", printableText(far[i].second, 40).c_str(), far[i].first);
      text += line;
    }
    text += far.size() > 6 ? " ...\n" : "\n";
  }
  const std::string c = clip.empty() ? std::string("CLIP.c3d") : clip;
  text += "next:    tetrig run --rig " + out + " --clip " + c + "      (live, into the shared memory an engine reads)\n";
  text += "         tetrig export --rig " + out + " --clip " + c + " --out " +
          std::filesystem::path(out).replace_extension(".pc2").string() + " --report " +
          std::filesystem::path(out).replace_extension(".json").string() + "   (offline; the report says how closely the skin follows)\n";
  return text;
}

int buildRigCommand(const BuildArgs& a) {
  RigDescription desc;
  if (!a.rig_json.empty()) desc = readRigDescription(a.rig_json);
  if (!a.mesh_unit.empty()) {
    if (a.mesh_unit != "auto") (void)rigUnitsPerMm(a.mesh_unit);
    desc.mesh_unit = a.mesh_unit;
  }
  if (!a.mesh_up.empty()) desc.mesh_up = a.mesh_up;
  if (!a.device_up.empty()) desc.markers.device_up = a.device_up;
  if (!a.alignment.empty()) desc.markers.alignment = a.alignment;
  if (a.keep_zero_markers) desc.markers.keep_zero_points = true;
  {
    // The rig is written only at the end: its path is checked before minutes of work.
    const std::filesystem::path inputs[] = {a.mesh, a.rig_json, a.markers, desc.markers.clip};
    checkOutputPath(a.out, OutputKind::kRig, inputs, a.force);
  }
  BuildRigInputs in;
  in.mesh = a.mesh;
  in.description = desc;
  if (!a.markers.empty()) in.clip = a.markers;
  if (a.tet_vertices > 0) in.tet_vertices = a.tet_vertices;
  if (a.coarse_tet_vertices > 0) {
    in.coarse_tet_vertices = a.coarse_tet_vertices;
  } else if (a.coarse_tet_vertices < 0 && !rigbuild::isTetMeshPath(a.mesh) && (!a.markers.empty() || !desc.markers.clip.empty()) &&
             desc.vertex_handles.empty() && desc.region_handles.empty() && desc.point_handles.empty()) {
    // The coarse level by default for a rig driven by markers (what tetrig run plays) from a surface
    // mesh several times finer (a description's own handles may select too little for a coarse mesh:
    // it asks for the level itself).
    const std::int32_t fine = a.tet_vertices > 0 ? a.tet_vertices : desc.tet_vertices;
    if (fine >= 4 * kDefaultCoarseTetVertices) in.coarse_tet_vertices = kDefaultCoarseTetVertices;
  }
  if (a.frame == "auto") {
    in.frame_auto = true;
  } else if (!a.frame.empty()) {
    in.frame = std::stoll(a.frame);  // checked by the option's validator
  }
  if (a.min_fit_scale > 0) in.min_fit_scale = a.min_fit_scale;
  if (a.max_fit_scale > 0) in.max_fit_scale = a.max_fit_scale;
  in.accept_implausible_alignment = a.accept_implausible_alignment;
  in.accept_pose_mismatch = a.accept_pose_mismatch;
  if (a.max_marker_distance > 0) in.max_marker_distance = a.max_marker_distance;
  Progress progress("tetrig build-rig", a.quiet ? Progress::Mode::kQuiet : a.simple ? Progress::Mode::kSimple : Progress::Mode::kAuto);
  BuildRigReport report;
  const Rig rig = buildRig(in, &report, &progress);
  progress.begin("writing " + a.out);
  const std::vector<std::uint8_t> bytes = serializeRig(rig);
  writeFileAtomically(a.out, bytes);
  progress.end(std::to_string(bytes.size()) + " bytes");
  for (const std::string& n : report.notes) progress.note("note: " + printableText(n));  // notes may quote labels from the clip
  if (!a.quiet) {
    std::printf("%s", describeRig(rig, static_cast<std::int64_t>(bytes.size()), a.list_markers).c_str());
    std::printf("%s", buildVerdict(rig, a.out, a.markers.empty() ? desc.markers.clip.string() : a.markers).c_str());
  }
  return 0;
}

int inspectCommand(const std::string& path, bool list_markers) {
  const Rig rig = loadRigFile(path);
  std::printf("%s", describeRig(rig, static_cast<std::int64_t>(std::filesystem::file_size(path)), list_markers).c_str());
  return 0;
}

// Edit distance (insertions, deletions, substitutions) between two short words.
std::size_t editDistance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0u : 1u)});
      diagonal = up;
    }
  }
  return row[b.size()];
}

// The known word nearest to `word` when it is near enough to be a slip (a third of its length),
// else "".
std::string nearestWord(const std::string& word, const std::vector<std::string>& known) {
  std::string best;
  std::size_t best_distance = std::max<std::size_t>(1, word.size() / 3) + 1;
  for (const std::string& k : known) {
    const std::size_t d = editDistance(word, k);
    if (d < best_distance) {
      best_distance = d;
      best = k;
    }
  }
  return best;
}

bool looksLikeNumber(const std::string& s) {
  char* end = nullptr;
  (void)std::strtod(s.c_str(), &end);
  return !s.empty() && end == s.c_str() + s.size();
}

// A mistake on the command line: one line that names it (a misspelt option or command with the
// nearest known one, else the parser's own words) and how to see the rest, exit status 2.
// --help and --version print as usual and exit 0.
int commandLineError(CLI::App& app, const CLI::ParseError& e, int argc, char** argv) {
  if (e.get_exit_code() == 0) return app.exit(e);
  CLI::App* sub = nullptr;
  int sub_at = argc;
  std::vector<std::string> commands;
  for (CLI::App* s : app.get_subcommands([](CLI::App*) { return true; })) commands.push_back(s->get_name());
  for (int i = 1; i < argc && sub == nullptr; ++i) {
    for (CLI::App* s : app.get_subcommands([](CLI::App*) { return true; })) {
      if (s->get_name() == argv[i]) {
        sub = s;
        sub_at = i;
      }
    }
  }
  if (sub == nullptr) {
    for (int i = 1; i < argc; ++i) {
      const std::string word = argv[i];
      if (word.empty() || word[0] == '-') continue;
      const std::string near = nearestWord(word, commands);
      std::fprintf(stderr, "tetrig: unknown command '%s'%s; the commands: %s (tetrig --help)\n", printableText(word, 60).c_str(),
                   near.empty() ? "" : (" (did you mean " + near + "?)").c_str(), joinWords(commands).c_str());
      return 2;
    }
    std::fprintf(stderr, "tetrig: give a command: %s (tetrig --help)\n", joinWords(commands).c_str());
    return 2;
  }
  const std::string prefix = "tetrig " + sub->get_name();
  // Every option the command knows, and whether it takes a value (a value may start with '-').
  std::vector<std::string> names;
  std::vector<bool> takes_value;
  for (const CLI::Option* o : sub->get_options()) {
    for (const std::string& n : o->get_lnames()) {
      names.push_back("--" + n);
      takes_value.push_back(o->get_items_expected_min() > 0);
    }
    for (const std::string& n : o->get_snames()) {
      names.push_back("-" + n);
      takes_value.push_back(o->get_items_expected_min() > 0);
    }
  }
  for (int i = sub_at + 1; i < argc; ++i) {
    const std::string token = argv[i];
    if (token.size() < 2 || token[0] != '-' || looksLikeNumber(token)) continue;
    const std::string name = token.substr(0, token.find('='));
    const auto known = std::find(names.begin(), names.end(), name);
    if (known != names.end()) {
      if (takes_value[static_cast<std::size_t>(known - names.begin())] && token.find('=') == std::string::npos) ++i;  // its value
      continue;
    }
    const std::string near = nearestWord(name, names);
    std::fprintf(stderr, "%s: unknown option '%s'%s (%s --help lists them)\n", prefix.c_str(), printableText(name, 60).c_str(),
                 near.empty() ? "" : (" (did you mean " + near + "?)").c_str(), prefix.c_str());
    return 2;
  }
  std::string what = e.what();
  for (char& c : what) {
    if (c == '\n') c = ' ';
  }
  std::fprintf(stderr, "%s: error: %s (%s --help)\n", prefix.c_str(), printableText(what, 300).c_str(), prefix.c_str());
  return 2;
}

// The option groups of the commands' --help.
const char* const kEssentials = "Essentials";
const char* const kStage = "Several performers (docs/live.md, \"Several performers\")";
const char* const kAccuracy = "Accuracy (how closely the skin follows the markers)";
const char* const kLatency = "Latency";
const char* const kSources = "Sources";
const char* const kOutput = "Output";

// `tetrig run`'s options beyond RunOptions, and its command and options that the checks after parsing query.
struct RunArgs {
  tetrig::tools::RunOptions run;
  std::string run_clip;
  std::vector<std::string> run_performers;
  std::string run_stage;
  bool no_mlock = false;
  std::string shm_mode;
  CLI::App* run_cmd = nullptr;
  CLI::Option* run_rig = nullptr;
  CLI::Option* run_source = nullptr;
};

// Every command's options, as the parser fills them.
struct CommandLine {
  BuildArgs build;
  std::string inspect_path;
  bool inspect_markers = false;
  tetrig::tools::DemoOptions demo;
  RunArgs run;
  tetrig::tools::ExportOptions exp;
  tetrig::tools::ViewOptions view;
  tetrig::tools::PoseOptions pose;
  std::string character_out;
};

// `tetrig build-rig` and its options.
void addBuildRigCommand(CLI::App& app, BuildArgs& build) {
  CLI::App* build_cmd = app.add_subcommand("build-rig", "Build a rig file from a mesh, a rig description and a marker clip");
  build_cmd->add_option("--mesh", build.mesh, "The character: a surface mesh (OBJ, PLY, OFF, STL, glTF, ...) or a ready tet mesh (.node/.ele, .mesh)")
      ->required()
      ->group(kEssentials);
  build_cmd->add_option("--clip,--markers", build.markers,
                        "The performer: a C3D clip whose markers drive the character (its first frame, or --frame, is matched to the mesh's "
                        "rest pose; --markers is the old spelling)")
      ->group(kEssentials);
  build_cmd->add_option("--out", build.out, "Rig file to write (a file tetrig did not write is kept unless --force)")->required()->group(kEssentials);
  build_cmd->add_option("--description,--rig", build.rig_json,
                        "Rig description JSON: anything the automatic rig should do otherwise (handles, regions, stiffness, markers; "
                        "docs/rig-format.md; --rig is the old spelling)")
      ->group(kEssentials);
  build_cmd->add_flag("--keep-zero-markers", build.keep_zero_markers,
                      "C3D samples at x = y = z = 0 with residual 0 are valid points (default: gaps)")
      ->group("Clip");
  build_cmd->add_option("--tet-vertices", build.tet_vertices,
                        "How finely the body's volume is modelled: more follows the markers more closely and costs more per frame "
                        "(default 2500)")
      ->check(CLI::Range(4, 10000000))
      ->group("Accuracy and cost");
  build_cmd->add_option("--coarse-tet-vertices", build.coarse_tet_vertices,
                        "The coarse level's tet-vertex budget (default 150; 0: none): tetrig run solves it first every frame, so the "
                        "skin lands nearer its final shape in a frame's few iterations (docs/fidelity.md)")
      ->check(CLI::Range(0, 10000000))
      ->group("Accuracy and cost");
  build_cmd->add_option("--frame", build.frame,
                        "Rest frame of the clip, 0-based (default 0: the first), or auto: the frame that best fits the mesh's rest pose")
      ->check([](const std::string& v) -> std::string {
        if (v == "auto") return {};
        std::size_t used = 0;
        try {
          const long long f = std::stoll(v, &used);
          if (used == v.size() && f >= 0 && f <= 100000000) return {};
        } catch (const std::exception&) {
        }
        return "expected a frame number in [0, 100000000] or auto";
      })
      ->group("Clip");
  build_cmd->add_option("--max-marker-distance", build.max_marker_distance,
                        "Stop when a marker is further than this from the surface after alignment, rig units "
                        "(default: 6 % of the mesh's bounding-box diagonal)")
      ->check(CLI::Range(1e-6, 1e6))
      ->group("Alignment checks");
  build_cmd->add_option("--min-fit-scale", build.min_fit_scale, "Refuse an automatic alignment whose fit scale is below this (default 0.85)")
      ->check(CLI::Range(1e-6, 1e6))
      ->group("Alignment checks");
  build_cmd->add_option("--max-fit-scale", build.max_fit_scale, "Refuse an automatic alignment whose fit scale is above this (default 1.18)")
      ->check(CLI::Range(1e-6, 1e6))
      ->group("Alignment checks");
  build_cmd->add_flag("--accept-pose-mismatch", build.accept_pose_mismatch,
                      "Build although the markers do not cover the mesh's extent in its rest pose (a partial marker set)")
      ->group("Alignment checks");
  build_cmd->add_flag("--accept-implausible-alignment", build.accept_implausible_alignment,
                      "Build although the automatic alignment fails the scale or pose checks (docs/rig-builder.md)")
      ->group("Alignment checks");
  build_cmd->add_option("--mesh-unit", build.mesh_unit,
                        "Unit of the mesh: m, cm, mm, or auto (the unit that makes it as tall as the performer's markers) (default m)")
      ->group("Units and axes");
  build_cmd->add_option("--mesh-up", build.mesh_up, "Up axis of the mesh: x, y, z, -x, -y, -z (default y)")->group("Units and axes");
  build_cmd->add_option("--device-up", build.device_up, "Up axis of the marker clip (default z, the C3D convention)")->group("Units and axes");
  build_cmd->add_option("--alignment", build.alignment,
                        "How the markers are placed on the mesh: auto (fitted to the surface), units (axes and unit only), matrix "
                        "(the description's)")
      ->check(CLI::IsMember({"auto", "units", "matrix"}))
      ->group("Units and axes");
  build_cmd->add_flag("--list-markers", build.list_markers, "List every marker in the summary")->group("Output");
  build_cmd->add_flag("--simple-progress", build.simple, "Plain progress lines even on a terminal")->group("Output");
  build_cmd->add_flag("--force", build.force, "Replace an existing --out that is not a tetrig rig (an input is never replaced)")->group("Output");
  build_cmd->add_flag("-q,--quiet", build.quiet, "No progress and no summary")->group("Output");
}

// `tetrig inspect` and its options.
void addInspectCommand(CLI::App& app, std::string& inspect_path, bool& inspect_markers) {
  CLI::App* inspect_cmd = app.add_subcommand("inspect", "Show what a rig file holds: counts, bounding box, handles, markers, memory");
  inspect_cmd->add_option("RIG", inspect_path, "Rig file")->required();
  inspect_cmd->add_flag("--markers", inspect_markers, "List every marker");
}

// `tetrig demo` and its options.
void addDemoCommand(CLI::App& app, tetrig::tools::DemoOptions& demo) {
  CLI::App* demo_cmd = app.add_subcommand("demo", "Run the live path (source -> solver -> shared memory -> a consumer) on the project's own default data, or on --mesh/--c3d");
  demo_cmd->add_option("--frames", demo.frames, "Frames to solve (default: one pass of the default character's performance, 1152 frames; the whole clip with --c3d)")
      ->check(CLI::Range(1, 100000000));
  demo_cmd->add_option("--mesh", demo.mesh, "Real data: a surface mesh (with --c3d); the rig is built once and cached");
  demo_cmd->add_option("--clip,--c3d", demo.c3d, "Real data: the C3D clip that drives the mesh (with --mesh; --c3d is the old spelling)");
  demo_cmd->add_option("--max-marker-distance", demo.max_marker_distance,
                       "Real data: stop when a marker is further than this from the surface after alignment, rig units "
                       "(default: 6 % of the mesh's bounding-box diagonal)")
      ->check(CLI::Range(1e-6, 1e6));
  demo_cmd->add_option("--publish", demo.publish, "Shared-memory segment name (default: tetrig-demo-<pid>)");
  demo_cmd->add_option("--iterations", demo.iterations, "Iterations per frame (also bounded by the budget)")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000));
  tetrig::tools::addSolverFlags(*demo_cmd, demo.solver);
  demo_cmd->add_option("--budget-ms", demo.frame_budget_ms, "Receive -> published deadline per frame (default: 0.9 of the source's period)")
      ->check(CLI::Range(0.001, 60000.0));
  demo_cmd->add_option("--out", demo.out_obj, "Write the last published surface to this OBJ file");
  demo_cmd->add_option("--report", demo.report, "The report folder: summary.json, sheet.png, latency.png (docs/demo.md)")
      ->capture_default_str();
  demo_cmd->add_flag("--no-report", demo.no_report, "Write no report");
  demo_cmd->add_option("--sheet-frames", demo.sheet_frames, "Frames on the report's picture sheet")
      ->capture_default_str()
      ->check(CLI::Range(1, 48));
  demo_cmd->add_flag("-q,--quiet", demo.quiet, "Less output");
}

// `tetrig run` and its options.
void addRunCommand(CLI::App& app, RunArgs& r) {
  tetrig::tools::RunOptions& run = r.run;
  std::string& run_clip = r.run_clip;
  std::vector<std::string>& run_performers = r.run_performers;
  std::string& run_stage = r.run_stage;
  bool& no_mlock = r.no_mlock;
  std::string& shm_mode = r.shm_mode;
  CLI::App* run_cmd = r.run_cmd = app.add_subcommand("run", "Run the live path: a marker source -> the rig, frame after frame -> shared memory");
  r.run_rig = run_cmd->add_option("--rig", run.rig_path, "Rig file (tetrig build-rig)")->group(kEssentials);
  run_cmd->add_option("--performer", run_performers,
                      "One performer: rig=PATH,source=SPEC,publish=NAME[,subject=S][,name=N][,coarse-rig=PATH][,cpu=K]; repeat for each "
                      "(performers naming one source share it; subject=S takes its S:LABEL markers)")
      ->group(kStage);
  run_cmd->add_option("--stage", run_stage, "A stage file (JSON) listing the performers")->group(kStage);
  r.run_source = run_cmd->add_option("--source", run.source,
                                     "Where the markers come from: c3d:PATH, replay:PATH, synthetic[:N], synthetic:character, hid:VID:PID, "
                                     "usb:VID:PID (hex ids), hydra[:SERIAL]")
                     ->group(kEssentials);
  run_cmd->add_option("--clip", run_clip, "Play this C3D clip (the same as --source c3d:PATH)")->group(kEssentials);
  run_cmd->add_option("--publish", run.publish, "Shared-memory segment the engine reads (docs/shm.md)")->capture_default_str()->group(kEssentials);
  run_cmd->add_option("--frames", run.frames, "Stop after this many solved frames (default: until the source ends or Ctrl-C)")
      ->check([](const std::string& v) -> std::string {
        if (!v.empty() && v.size() <= 19 && v.find_first_not_of("0123456789") == std::string::npos) return {};
        return "'" + v + "' is not a number of frames (a whole number, 0 = until the source ends; a range A:B is tetrig export's --range)";
      })
      ->group(kEssentials);
  run_cmd->add_option("--iterations", run.iterations, "Solver iterations per frame: more land nearer the final shape, each costs time")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000))
      ->group(kAccuracy);
  tetrig::tools::addSolverFlags(*run_cmd, run.solver, kAccuracy);
  run_cmd->add_option("--coarse-rig", run.coarse_rig_path,
                      "A coarse rig of the same mesh and markers (fewer --tet-vertices, e.g. 300) solved first every frame: "
                      "lands nearer the final shape")
      ->group(kAccuracy);
  run_cmd->add_option("--occlusion-blend-ms", run.occlusion_blend_ms, "How long a marker that drops out or returns takes to blend")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 10000.0))
      ->group(kAccuracy);
  run_cmd->add_option("--budget-ms", run.budget_ms, "Receive -> published deadline per frame (default: 0.9 of the source's period)")
      ->check(CLI::Range(0.01, 60000.0))
      ->group(kLatency);
  run_cmd->add_option("--pose-threads", run.pose_threads, "Threads that write the mesh: 1 (default), or 2 on a machine with a spare core")
      ->check(CLI::Range(1, 2))
      ->group(kLatency);
  run_cmd->add_option("--cpu", run.cpu, "Pin the solver thread to this CPU")->check(CLI::Range(0, 4095))->group(kLatency);
  run_cmd->add_option("--spin-before-frame-us", run.spin_before_frame_us,
                      "Before each frame is due, read the frame's data into the caches and poll for it this long (default 500; 0: sleep until it comes)")
      ->check(CLI::Range(0.0, 100000.0))
      ->group(kLatency);
  run_cmd->add_flag("--fifo", run.fifo, "Run the solver thread under SCHED_FIFO (needs the privilege; reported when refused)")->group(kLatency);
  run_cmd->add_flag("--no-mlock", no_mlock, "Do not lock the process's memory")->group(kLatency);
  run_cmd->add_flag("--as-fast-as-possible", run.as_fast_as_possible, "Playback: as fast as the solver takes frames (each frame waits until the last was taken: none dropped; offline runs)")->group(kSources);
  run_cmd->add_option("--speed", run.speed, "Playback speed factor (the budget follows it)")
      ->capture_default_str()
      ->check(CLI::Range(0.01, 100.0))
      ->group(kSources);
  run_cmd->add_flag("--loop", run.loop, "Playback: start again at the end")->group(kSources);
  run_cmd->add_flag("--keep-zero-markers", run.keep_zero_markers,
                    "c3d: samples at x = y = z = 0 with residual 0 are valid points (default: gaps)")
      ->group(kSources);
  run_cmd->add_option("--rate", run.rate_hz, "Frame rate in Hz: asked of a device (SET_RATE), or overriding a clip's or the synthetic rate")
      ->check(CLI::Range(1, 65535))
      ->group(kSources);
  run_cmd->add_option("--label-timeout-ms", run.label_timeout_ms, "How long to wait for a device to name its markers")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 600000.0))
      ->group(kSources);
  run_cmd->add_option("--stale-ms", run.stale_ms, "No frame for this long: the segment says the source is stale")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 600000.0))
      ->group(kSources);
  run_cmd->add_flag("--normals", run.normals, "Also publish per-vertex normals")->group(kOutput);
  run_cmd->add_flag("--dds", run.dds, "Also publish the frames over DDS: topics tetrig/<publish name>/frame and /static (docs/dds.md)")->group(kOutput);
  run_cmd->add_option("--stats-json", run.stats_json, "Write the run's statistics (keys: docs/live.md; a file tetrig did not write is kept unless --force)")->group(kOutput);
  run_cmd->add_flag("--force", run.force, "Replace an existing --stats-json that tetrig did not write (an input is never replaced)")->group(kOutput);
  run_cmd->add_option("--shm-mode", shm_mode, "Segment permissions in octal (default 600: owner only; read bits for group/others, e.g. 640 or 644, but no write bits)")
      ->group(kOutput);
  run_cmd->add_flag("-q,--quiet", run.quiet, "Only errors")->group(kOutput);
}

// `tetrig export` and its options.
void addExportCommand(CLI::App& app, tetrig::tools::ExportOptions& exp) {
  CLI::App* export_cmd = app.add_subcommand(
      "export", "Run a clip offline through a rig at full quality and write the fine-mesh animation (PC2 + OBJ, OBJ/PLY sequence, glTF)");
  export_cmd->add_option("--rig", exp.rig_path, "Rig file (tetrig build-rig)")->required()->group(kEssentials);
  export_cmd->add_option("--clip,--c3d", exp.clip_path,
                         "C3D clip that drives the rig (bound by marker label, as tetrig run binds it; --c3d is the old spelling)")
      ->required()
      ->group(kEssentials);
  export_cmd->add_option("--out", exp.out,
                         "Output, format from the extension: FILE.pc2 (+ FILE.rest.obj, the rest mesh), NAME_####.obj or NAME_####.ply "
                         "(one file per frame; the #s become the clip frame number), FILE.gltf or FILE.glb (which for which tool: below)")
      ->required()
      ->group(kEssentials);
  export_cmd->footer(
      "Which file for which tool (docs/export.md):\n"
      "  FILE.pc2       Blender, 3ds Max, Maya: the point cache plays on its rest mesh FILE.rest.obj (Blender: File > Import >\n"
      "                 tetrig export, or a Mesh Cache modifier on the imported rest OBJ). The rest OBJ has the asset's vertex\n"
      "                 order, texture coordinates and materials (mtllib, vt, usemtl), so the cache also plays on the original OBJ\n"
      "                 (one without duplicate or unused vertices).\n"
      "  FILE.glb/.gltf game engines: one morph target per frame (positions and normals), the asset's texture coordinates\n"
      "                 (vertices split at uv seams) and materials (a texture by its path relative to the file); at most 1000 frames.\n"
      "  NAME_####.obj  other tools: one OBJ per frame with the rest OBJ's texture coordinates and materials; normals are the\n"
      "                 reader's (as for the rest OBJ).\n"
      "  NAME_####.ply  one PLY per frame; texture coordinates (s, t) only when each vertex has one (no seams).\n"
      "Texture coordinates and materials come from an OBJ asset (build-rig reads its vt, usemtl and .mtl files).");
  export_cmd->add_option("--range,--frames", exp.frames,
                         "Clip frames A:B (0-based, B exclusive; A: or :B), default the whole clip (--frames is the old spelling)")
      ->group(kEssentials);
  export_cmd->add_option("--report", exp.report,
                         "Also write a JSON report: how closely the skin followed the markers (tracking_mm, docs/fidelity.md) and counts")
      ->group(kEssentials);
  export_cmd->add_option("--iterations", exp.iterations,
                         "Exactly this many solver iterations per frame, as tetrig run does live (default: iterate to convergence)")
      ->check(CLI::Range(1, 100000))
      ->group(kAccuracy);
  export_cmd->add_option("--tolerance", exp.tolerance,
                         "Convergence: stop once no fine vertex moved more than this fraction of the mesh's bounding-box diagonal in 4 iterations")
      ->capture_default_str()
      ->check(CLI::Range(1e-12, 1.0))
      ->group(kAccuracy);
  export_cmd->add_option("--max-iterations", exp.max_iterations, "Convergence: at most this many iterations per frame")
      ->capture_default_str()
      ->check(CLI::Range(1, 100000))
      ->group(kAccuracy);
  export_cmd->add_option("--occlusion-blend-ms", exp.occlusion_blend_ms, "Blend time when a marker drops out or returns (as tetrig run)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 10000.0))
      ->group(kAccuracy);
  tetrig::tools::addSolverFlags(*export_cmd, exp.solver, kAccuracy);
  export_cmd->add_flag("--keep-zero-markers", exp.keep_zero_markers,
                       "Samples at x = y = z = 0 with residual 0 are valid points, not gaps (as tetrig run)")
      ->group(kSources);
  export_cmd->add_option("--rate", exp.rate_hz, "Frame rate in Hz instead of the clip's (glTF sample times)")->check(CLI::Range(0.001, 100000.0))
      ->group(kSources);
  export_cmd->add_flag("--simple-progress", exp.simple_progress, "Plain progress lines even on a terminal")->group(kOutput);
  export_cmd->add_flag("--force", exp.force, "Replace existing output files that tetrig did not write (an input is never replaced)")
      ->group(kOutput);
  export_cmd->add_flag("-q,--quiet", exp.quiet, "No progress and no summary")->group(kOutput);
}

// `tetrig view` and its options.
void addViewCommand(CLI::App& app, tetrig::tools::ViewOptions& view) {
  CLI::App* view_cmd = app.add_subcommand(
      "view", "A window showing a shared-memory segment live: shaded mesh, orbit/zoom, frame id, rate, latency (docs/view.md)");
  view_cmd->add_option("NAME", view.name, "Segment name (the --publish name of tetrig run / tetrig demo; default: tetrig run's)")
      ->capture_default_str();
  view_cmd->add_flag("--markers", view.markers, "Draw the markers as dots coloured by state (measured, blended, predicted) with their counts (M toggles)");
  view_cmd->add_flag("--follow", view.follow, "Keep the camera on the figure as it moves (F toggles it)");
  view_cmd->add_option("--screenshot", view.screenshot, "Write the window's picture to this PNG after --after-frames new frames, then exit 0");
  view_cmd->add_option("--after-frames", view.after_frames, "New frames before the screenshot")
      ->capture_default_str()
      ->check(CLI::Range(1, 100000000));
  view_cmd->add_option("--timeout", view.timeout_s, "--screenshot: fail when the frames did not come within this many seconds")
      ->capture_default_str()
      ->check(CLI::Range(0.1, 86400.0));
  view_cmd->add_option("--width", view.width, "Window width, pixels")->capture_default_str()->check(CLI::Range(64, 8192));
  view_cmd->add_option("--height", view.height, "Window height, pixels")->capture_default_str()->check(CLI::Range(64, 8192));
  view_cmd->add_option("--up", view.up, "The rig's up axis: x, y or z")->capture_default_str()->check(CLI::IsMember({"x", "y", "z"}));
  view_cmd->add_option("--stale-ms", view.stale_ms, "Heartbeat age that counts as a producer not responding")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 600000.0));
  view_cmd->add_flag("-q,--quiet", view.quiet, "No status lines on stderr");
  view_cmd->add_flag("--dds", view.dds, "Read NAME's frames over DDS (topics tetrig/NAME/frame and /static) instead of its segment (docs/dds.md)");
}

// `tetrig pose` and its options.
void addPoseCommand(CLI::App& app, tetrig::tools::PoseOptions& pose) {
  CLI::App* pose_cmd = app.add_subcommand("pose", "Pose a rig: rigid transforms (.def files) for its region handles -> the fine mesh as OBJ");
  pose_cmd->add_option("RIG", pose.rig_path, "Rig file (tetrig build-rig)")->required();
  pose_cmd->add_option("--region", pose.regions,
                       "NAME=FILE.def: region handle NAME takes the 4x4 rigid transform in FILE.def (deformation-survey format; "
                       "repeat for several regions; the others stay at rest)")
      ->required();
  pose_cmd->add_option("--out", pose.out, "OBJ file to write (atomically replaced), vertices in the rig's fine-mesh order")->required();
  pose_cmd->add_option("--iterations", pose.iterations, "Exactly this many solver iterations (default: until the energy stops changing)")
      ->check(CLI::Range(1, 10000000));
  pose_cmd->add_option("--max-iterations", pose.max_iterations, "Convergence: fail after this many iterations")
      ->capture_default_str()
      ->check(CLI::Range(1, 10000000));
  pose_cmd->add_option("--volume-weight", pose.volume_weight,
                       "Volume term: its share w of each tet's energy, (1 - w) ||F - R||^2 + w ||F - T||^2 with T the tet's "
                       "nearest unit-volume shape (docs/deformation.md); 0 = as rigid as possible")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.99));
  pose_cmd->add_flag("--force", pose.force, "Replace an existing --out that tetrig did not write (an input is never replaced)");
  pose_cmd->add_flag("-q,--quiet", pose.quiet, "No summary");
}

// `tetrig make-character` and its options.
void addMakeCharacterCommand(CLI::App& app, std::string& character_out) {
  CLI::App* character_cmd = app.add_subcommand(
      "make-character", "Generate the default character's assets (skin OBJ + T-pose markers CSV; docs/character.md) into a folder");
  character_cmd->add_option("--out", character_out, "Folder to write character.obj and markers.csv into (each replaced atomically)")
      ->required();
}

// `tetrig make-character`: writes the default character's assets and says what they are.
int makeCharacterCommand(const std::string& character_out) {
  const tetrig::character::CharacterSkinStats made = tetrig::character::writeCharacterAssets(character_out);
  std::printf("tetrig make-character: %s/%s: %d vertices, %d triangles, genus %d, %.3f m tall, %.4f m^3 (%.2f s); %s/%s: %d markers\n",
              character_out.c_str(), tetrig::character::kCharacterObjName, made.vertices, made.triangles, made.genus, made.height_m,
              made.volume_m3, made.seconds, character_out.c_str(), tetrig::character::kCharacterMarkersName,
              tetrig::drivers::kCharacterMarkerCount);
  return 0;
}

// `tetrig run`: checks the performers, the source and --shm-mode, then runs the live path.
int runCommand(RunArgs& r) {
  tetrig::tools::RunOptions& run = r.run;
  const std::string& run_clip = r.run_clip;
  const std::string& run_stage = r.run_stage;
  const std::vector<std::string>& run_performers = r.run_performers;
  const std::string& shm_mode = r.shm_mode;
  run.lock_memory = !r.no_mlock;
  if (!run_performers.empty() && !run_stage.empty())
    throw std::invalid_argument("give the performers with --performer or in a --stage file, not both");
  const bool stage = !run_performers.empty() || !run_stage.empty();
  if (stage) {
    if (r.run_rig->count() > 0 || r.run_source->count() > 0 || !run_clip.empty() || r.run_cmd->get_option("--publish")->count() > 0 ||
        r.run_cmd->get_option("--coarse-rig")->count() > 0 || r.run_cmd->get_option("--cpu")->count() > 0)
      throw std::invalid_argument("with --performer or --stage, each performer names its rig, source, segment, coarse rig and CPU: "
                                  "not --rig, --source, --clip, --publish, --coarse-rig or --cpu");
    if (!run_stage.empty()) run.performers = tetrig::tools::loadStageFile(run_stage);
    for (const std::string& text : run_performers) run.performers.push_back(tetrig::tools::parsePerformerSpec(text));
    tetrig::tools::checkStage(run.performers);
  } else {
    if (r.run_rig->count() == 0) throw std::invalid_argument("no rig: give --rig RIG (or --performer / --stage for several performers)");
    if (!run_clip.empty() && r.run_source->count() > 0)
      throw std::invalid_argument("give --clip PATH or --source SOURCE, not both (--clip PATH is --source c3d:PATH)");
    if (!run_clip.empty()) run.source = "c3d:" + run_clip;
    if (run_clip.empty() && r.run_source->count() == 0)
      throw std::invalid_argument("no marker source: give --clip CLIP.c3d or --source SOURCE (c3d:PATH, synthetic, hid:VID:PID, ...)");
  }
  if (!shm_mode.empty()) {
    // Octal digits only (std::stoul would take spaces and signs, and throw "stoul" on other text).
    if (shm_mode.size() > 4 || shm_mode.find_first_not_of("01234567") != std::string::npos || std::stoul(shm_mode, nullptr, 8) > 0777) {
      throw std::invalid_argument("--shm-mode '" + shm_mode + "' is not octal permissions such as 600, 640 or 644");
    }
    const unsigned long mode = std::stoul(shm_mode, nullptr, 8);
    if ((mode & 022) != 0) {
      throw std::invalid_argument("--shm-mode " + shm_mode + " lets group or others write the segment: any such user could rewrite or "
                                  "truncate it and crash its readers, which refuse it; use 600, 640 or 644");
    }
    run.shm_permissions = static_cast<unsigned>(mode);
  }
  return tetrig::tools::runLive(run);
}

// Runs the command the parser chose (none: 0).
int runChosenCommand(const std::string& cmd, CommandLine& c) {
  if (cmd == "build-rig") return buildRigCommand(c.build);
  if (cmd == "inspect") return inspectCommand(c.inspect_path, c.inspect_markers);
  if (cmd == "demo") return tetrig::tools::runDemo(c.demo);
  if (cmd == "pose") return tetrig::tools::runPose(c.pose);
  if (cmd == "view") return tetrig::tools::runView(c.view);
  if (cmd == "make-character") return makeCharacterCommand(c.character_out);
  if (cmd == "export") return tetrig::tools::runExport(c.exp);
  if (cmd == "run") return runCommand(c.run);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"tetrig: real-time volumetric deformation driven by motion-capture markers (Stoll et al. 2007)"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "tetrig " TETRIG_VERSION_STRING);  // tetrig/version.h: project(VERSION) in CMakeLists.txt

  // The commands and their options, in the order --help lists them.
  CommandLine commands;
  addBuildRigCommand(app, commands.build);
  addInspectCommand(app, commands.inspect_path, commands.inspect_markers);
  addDemoCommand(app, commands.demo);
  addRunCommand(app, commands.run);
  addExportCommand(app, commands.exp);
  addViewCommand(app, commands.view);
  addPoseCommand(app, commands.pose);
  addMakeCharacterCommand(app, commands.character_out);

  // A mistake on the command line: one line, status 2 (--help and --version: 0).
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return commandLineError(app, e, argc, argv);
  }

  const std::string cmd = app.get_subcommands().empty() ? std::string() : app.get_subcommands().front()->get_name();
  // The chosen command; an error is one line on stderr, status 1.
  try {
    return runChosenCommand(cmd, commands);
  } catch (const std::exception& e) {
    // One line, and no control sequence from a file's text (a label, a JSON key) reaches the terminal.
    std::string what = e.what();
    for (char& c : what) {
      if (c == '\n') c = ' ';
    }
    std::fprintf(stderr, "tetrig %s: error: %s\n", cmd.c_str(), printableText(what).c_str());
    return 1;
  }
}
