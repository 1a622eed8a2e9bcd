// Progress lines in a log (tools/rigbuild/progress.cpp): off a terminal, a step prints a line at
// every 10 % it passes (not at 100 %: the step's end line says it), each with the time taken.
#include "tetrig/rigbuild/progress.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

namespace tetrig::rigbuild {
namespace {

std::vector<std::string> linesOf(std::FILE* f) {
  std::rewind(f);
  std::vector<std::string> lines;
  char buf[512];
  while (std::fgets(buf, sizeof buf, f) != nullptr) {
    std::string l(buf);
    if (!l.empty() && l.back() == '\n') l.pop_back();
    lines.push_back(l);
  }
  return lines;
}

TEST(Progress, ALogGetsALineAtEveryTenthWithTheTimeTaken) {
  std::FILE* f = std::tmpfile();
  ASSERT_NE(f, nullptr);
  {
    Progress p("tetrig export", Progress::Mode::kSimple, f);
    p.begin("solving 40 frames");
    for (int i = 1; i <= 40; ++i) p.update(i / 40.0);
    p.end("done");
  }
  const std::vector<std::string> lines = linesOf(f);
  std::fclose(f);
  ASSERT_EQ(lines.size(), 11u);  // begin, 10 % .. 90 %, end
  EXPECT_EQ(lines.front(), "tetrig export: solving 40 frames ...");
  for (int k = 1; k <= 9; ++k) {
    EXPECT_EQ(lines[static_cast<std::size_t>(k)].rfind("tetrig export: solving 40 frames " + std::to_string(10 * k) + " % (", 0), 0u)
        << lines[static_cast<std::size_t>(k)];
    EXPECT_EQ(lines[static_cast<std::size_t>(k)].back(), ')');
  }
  EXPECT_EQ(lines.back().rfind("tetrig export: solving 40 frames: done (", 0), 0u) << lines.back();
}

TEST(Progress, QuietPrintsNothing) {
  std::FILE* f = std::tmpfile();
  ASSERT_NE(f, nullptr);
  {
    Progress p("x", Progress::Mode::kQuiet, f);
    p.begin("step");
    p.update(0.5);
    p.note("a note");
    p.end();
  }
  EXPECT_TRUE(linesOf(f).empty());
  std::fclose(f);
}

}  // namespace
}  // namespace tetrig::rigbuild
