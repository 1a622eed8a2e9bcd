// Runs one of our programs the way a user's shell would and keeps what it printed, for the tests
// of the command-line tools (tetrig, tetrig_fidelity): its exit status and its whole stdout and
// stderr (captured through files in the test's own directory, removed afterwards).
// Tests only.
#pragma once

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace tetrig::test {

struct CommandRun {
  int status = -1;  // the exit status; -1 when the program did not exit (e.g. killed by a signal)
  std::string out, err;
};

// `program` is quoted for the shell; `args` are passed as written (the caller quotes paths).
inline CommandRun runCommand(const std::string& program, const std::string& args, const std::filesystem::path& dir) {
  const std::filesystem::path out = dir / "stdout.txt", err = dir / "stderr.txt";
  const std::string cmd = "'" + program + "' " + args + " >'" + out.string() + "' 2>'" + err.string() + "'";
  CommandRun r;
  const int raw = std::system(cmd.c_str());
  r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  const auto slurp = [](const std::filesystem::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  };
  r.out = slurp(out);
  r.err = slurp(err);
  std::filesystem::remove(out);
  std::filesystem::remove(err);
  return r;
}

}  // namespace tetrig::test
