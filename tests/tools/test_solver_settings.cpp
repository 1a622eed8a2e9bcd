// The solver settings every tool shares (tetrig/solver_settings.hpp, tools/solver_flags.hpp):
// run, export, demo and tetrig_fidelity start from the same SolverSettings{} (the accurate
// settings), accept the same flags with the same meaning and range checks, and write the settings
// they ran with as the "solver" object of their JSON reports.
#include "demo.hpp"
#include "export.hpp"
#include "run.hpp"
#include "solver_flags.hpp"

#include "run_command.hpp"
#include "small_rig.hpp"
#include "temp_dir.hpp"

#include "tetrig/live_rig.hpp"
#include "tetrig/solver_settings.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>
#include <sstream>
#include <unistd.h>
#include <string>
#include <vector>

namespace tetrig {
namespace {

using test::TempDir;

// The flags `args` (space-separated) parsed by addSolverFlags on a fresh command, from the defaults.
SolverSettings parsed(const std::string& args) {
  CLI::App app{"solver flags"};
  SolverSettings s;
  tools::addSolverFlags(app, s);
  std::vector<std::string> argv;
  std::string word;
  for (std::istringstream in(args); in >> word;) argv.push_back(word);
  std::reverse(argv.begin(), argv.end());  // CLI11 takes them last first
  app.parse(argv);
  tools::checkSolverSettings(s);
  return s;
}

TEST(SolverSettings, TheDefaultsAreTheAccurateSettingsAndPlainIsTheFastOne) {
  const SolverSettings d;
  EXPECT_EQ(d.rotation_extrapolation, 1.0);
  EXPECT_EQ(d.rotation_relaxation, 1.8);
  EXPECT_EQ(d.inversion_guard, 4.0);
  EXPECT_EQ(d.inversion_guard_solves, 1);
  EXPECT_EQ(d.inversion_guard_threshold, 0.6);
  EXPECT_TRUE(d.volume_constraint);
  EXPECT_TRUE(d.use_coarse_level);
  EXPECT_EQ(d.after_publish_iterations, 0);
  const SolverSettings p = SolverSettings::plain();
  EXPECT_EQ(p.rotation_extrapolation, 0.0);
  EXPECT_EQ(p.rotation_relaxation, 1.8);
  EXPECT_EQ(p.inversion_guard, 0.0);
  EXPECT_EQ(p.inversion_guard_solves, 0);
  EXPECT_EQ(p.inversion_guard_threshold, 0.5);
  EXPECT_FALSE(p.volume_constraint);
  EXPECT_NE(p, d);
  EXPECT_NO_THROW(tools::checkSolverSettings(d));
  EXPECT_NO_THROW(tools::checkSolverSettings(p));
}

// The help names each switch as a user types it (no CLI11 notation such as "{false}" or "!--no-x"),
// and says which one is the default.
TEST(SolverSettings, TheHelpSpellsEachSwitchAsTyped) {
  CLI::App app{"solver flags"};
  SolverSettings s;
  tools::addSolverFlags(app, s);
  const std::string help = app.help();
  for (const char* flag : {"--predict", "--no-predict", "--keep-volume", "--no-keep-volume", "--no-coarse", "--relax",
                           "--inversion-guard", "--inversion-guard-solves", "--inversion-guard-threshold", "--after-publish-iterations"}) {
    EXPECT_NE(help.find(std::string("  ") + flag + " "), std::string::npos) << flag << " is not listed as typed:\n" << help;
  }
  EXPECT_EQ(help.find('{'), std::string::npos) << help;
  EXPECT_EQ(help.find("!--"), std::string::npos) << help;
  EXPECT_NE(help.find("Keep the body's volume constant (default on)"), std::string::npos) << help;
}

TEST(SolverSettings, EveryToolStartsFromTheSameDefaults) {
  EXPECT_EQ(LiveRigOptions{}.solver, SolverSettings{});
  EXPECT_EQ(tools::RunOptions{}.solver, SolverSettings{});
  EXPECT_EQ(tools::ExportOptions{}.solver, SolverSettings{});
  EXPECT_EQ(tools::DemoOptions{}.solver, SolverSettings{});
  // No flag: the defaults.
  EXPECT_EQ(parsed(""), SolverSettings{});
}

TEST(SolverSettings, TheFlagsSetWhatTheySay) {
  EXPECT_EQ(parsed("--no-predict").rotation_extrapolation, 0.0);
  EXPECT_EQ(parsed("--predict").rotation_extrapolation, 1.0);
  EXPECT_FALSE(parsed("--no-keep-volume").volume_constraint);
  EXPECT_TRUE(parsed("--keep-volume").volume_constraint);
  EXPECT_FALSE(parsed("--no-coarse").use_coarse_level);
  EXPECT_EQ(parsed("--relax 1.3").rotation_relaxation, 1.3);
  EXPECT_EQ(parsed("--inversion-guard 0.5 --inversion-guard-solves 0").inversion_guard, 0.5);
  EXPECT_EQ(parsed("--inversion-guard-solves 2").inversion_guard_solves, 2);
  EXPECT_EQ(parsed("--inversion-guard-threshold 0.4").inversion_guard_threshold, 0.4);
  EXPECT_EQ(parsed("--after-publish-iterations 2").after_publish_iterations, 2);
  EXPECT_EQ(parsed("--relax 1.2 --relax 1.4").rotation_relaxation, 1.4) << "given twice: the last one counts";
  EXPECT_THROW(parsed("--keep-volume --no-keep-volume"), CLI::ExcludesError) << "on and off at once is refused";
  EXPECT_THROW(parsed("--predict --no-predict"), CLI::ExcludesError);
  // The plain settings by flags.
  SolverSettings plain = parsed("--no-predict --no-keep-volume --inversion-guard 0 --inversion-guard-solves 0 --inversion-guard-threshold 0.5");
  EXPECT_EQ(plain, SolverSettings::plain());
  // Range checks: at parse time, and across flags (the explicit guard above 1).
  EXPECT_THROW(parsed("--relax 2"), CLI::ValidationError);
  EXPECT_THROW(parsed("--inversion-guard-threshold 0"), CLI::ValidationError);
  EXPECT_THROW(parsed("--inversion-guard-solves 65"), CLI::ValidationError);
  EXPECT_THROW(parsed("--predict --no-predict"), CLI::ExcludesError);
  EXPECT_THROW(parsed("--inversion-guard-solves 0"), std::invalid_argument) << "k 3 needs the implicit guard";
  EXPECT_NO_THROW(parsed("--inversion-guard 1 --inversion-guard-solves 0"));
}

// The "solver" object of a report, with the keys solverJson writes only (a tool adds its own).
nlohmann::json solverKeys(const nlohmann::json& report) {
  nlohmann::json out = nlohmann::json::object();
  const nlohmann::json reference = tools::solverJson(SolverSettings{});
  for (const auto& [key, value] : reference.items()) {
    EXPECT_TRUE(report.contains(key)) << key;
    if (report.contains(key)) out[key] = report[key];
  }
  return out;
}

// Each tool, run on the small rig and clip with the same flags, reports the same settings: those
// the flags say (from the same defaults), and refuses the same bad values in one line, non-zero.
TEST(SolverSettings, RunExportDemoAndFidelityParseTheFlagsIdentically) {
  const TempDir dir;
  const std::filesystem::path node = test::writeBlockTetMesh(dir, "block");
  const std::filesystem::path clip = test::writeSmallClip(dir);
  const std::filesystem::path json = dir.write("small.json", test::smallRigJson());
  const std::string rig = (dir.path() / "small.rig").string();
  ASSERT_EQ(test::runCommand(TETRIG_EXE, "build-rig --mesh '" + node.string() + "' --rig '" + json.string() + "' --markers '" +
                                             clip.string() + "' --out '" + rig + "' --quiet",
                             dir.path())
                .status,
            0);
  const std::string name = "tetrig-solver-" + std::to_string(getpid());
  // Every tool's report with `flags`.
  auto reports = [&](const std::string& flags, const std::string& tag) {
    std::vector<std::pair<std::string, nlohmann::json>> out;
    const std::string stats = (dir.path() / (tag + "_run.json")).string();
    const auto r = test::runCommand(TETRIG_EXE, "run --rig '" + rig + "' " + flags + " --source 'c3d:" + clip.string() + "' --publish " +
                                                    name + " -q --stats-json '" + stats + "'",
                                    dir.path());
    EXPECT_EQ(r.status, 0) << r.err;
    if (r.status == 0) out.emplace_back("run", nlohmann::json::parse(std::ifstream(stats))["solver"]);
    const std::string report = (dir.path() / (tag + "_export.json")).string();
    const auto e = test::runCommand(TETRIG_EXE, "export --rig '" + rig + "' --clip '" + clip.string() + "' --iterations 3 " + flags +
                                                    " --out '" + (dir.path() / (tag + ".pc2")).string() + "' -q --report '" + report + "'",
                                    dir.path());
    EXPECT_EQ(e.status, 0) << e.err;
    if (e.status == 0) out.emplace_back("export", nlohmann::json::parse(std::ifstream(report))["solver"]);
    const std::string fidelity = (dir.path() / (tag + "_fidelity.json")).string();
    const auto f = test::runCommand(TETRIG_FIDELITY_EXE, "--rig '" + rig + "' --c3d '" + clip.string() + "' --iterations 3 " + flags +
                                                             " -q --json '" + fidelity + "'",
                                    dir.path());
    EXPECT_EQ(f.status, 0) << f.err;
    if (f.status == 0) out.emplace_back("fidelity", nlohmann::json::parse(std::ifstream(fidelity))["solver"]);
    const std::filesystem::path demo = dir.path() / (tag + "_demo");
    const auto d = test::runCommand(TETRIG_EXE, "demo --frames 5 --quiet " + flags + " --publish " + name + " --report '" + demo.string() + "'",
                                    dir.path());
    EXPECT_EQ(d.status, 0) << d.err;
    if (d.status == 0) out.emplace_back("demo", nlohmann::json::parse(std::ifstream(demo / "summary.json"))["solver"]);
    EXPECT_EQ(out.size(), 4u);
    return out;
  };
  for (const auto& [flags, expected] : std::vector<std::pair<std::string, SolverSettings>>{
           {"", SolverSettings{}},
           {"--no-predict --no-keep-volume --inversion-guard 0 --inversion-guard-solves 0 --inversion-guard-threshold 0.5",
            SolverSettings::plain()},
           {"--relax 1.5 --inversion-guard 5 --inversion-guard-solves 2 --inversion-guard-threshold 0.6 --after-publish-iterations 1",
            [] {
              SolverSettings s;
              s.rotation_relaxation = 1.5;
              s.inversion_guard = 5.0;
              s.inversion_guard_solves = 2;
              s.inversion_guard_threshold = 0.6;
              s.after_publish_iterations = 1;
              return s;
            }()}}) {
    const std::string tag = "t" + std::to_string(flags.size());
    for (const auto& [tool, solver] : reports(flags, tag))
      EXPECT_EQ(solverKeys(solver), tools::solverJson(expected)) << tool << " with '" << flags << "'";
  }
  // The same bad value is refused by each, in one line naming the flag.
  const std::string bad = "--inversion-guard 2 --inversion-guard-solves 0";
  const std::string needle = "--inversion-guard must be in [0, 1]";
  const auto r = test::runCommand(TETRIG_EXE, "run --rig '" + rig + "' " + bad + " --source 'c3d:" + clip.string() + "' --publish " + name,
                                  dir.path());
  const auto e = test::runCommand(TETRIG_EXE, "export --rig '" + rig + "' --clip '" + clip.string() + "' --iterations 3 " + bad + " --out '" +
                                                  (dir.path() / "bad.pc2").string() + "'",
                                  dir.path());
  const auto f = test::runCommand(TETRIG_FIDELITY_EXE, "--rig '" + rig + "' --c3d '" + clip.string() + "' " + bad, dir.path());
  const auto d = test::runCommand(TETRIG_EXE, "demo --frames 5 --no-report " + bad, dir.path());
  for (const auto* c : {&r, &e, &f, &d}) {
    EXPECT_NE(c->status, 0) << c->out;
    EXPECT_NE(c->err.find(needle), std::string::npos) << c->err;
  }
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "bad.pc2"));
}

}  // namespace
}  // namespace tetrig
