// Output paths (tools/rigbuild/output_guard.cpp): tetrig's own files are recognised by their mark
// and may be replaced; any other existing file needs --force; an input never becomes an output.
#include "tetrig/rigbuild/output_guard.hpp"
#include "temp_dir.hpp"

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace tetrig::rigbuild {
namespace {

using test::TempDir;

std::string refusal(const std::filesystem::path& out, OutputKind kind, const std::vector<std::filesystem::path>& inputs, bool force) {
  try {
    checkOutputPath(out, kind, inputs, force);
  } catch (const OutputRefused& e) {
    return e.what();
  }
  return "";
}

TEST(OutputGuard, RecognisesWhatTetrigWrites) {
  const TempDir d;
  struct Case {
    const char* name;
    OutputKind kind;
    std::string ours, theirs;
  };
  const std::string glb_json = "{\"asset\":{\"generator\":\"tetrig export\",\"version\":\"2.0\"}}";
  const std::string glb_other = "{\"asset\":{\"generator\":\"Blender\",\"version\":\"2.0\"}}";
  auto glb = [](const std::string& json) {
    std::string b = "glTF";
    b += std::string("\x02\0\0\0\0\0\0\0", 8);
    b += std::string("\0\0\0\0", 4) + "JSON" + json;
    return b;
  };
  const Case cases[] = {
      {"a.rig", OutputKind::kRig, std::string("TETRIGRF\x01\0\0\0", 12), "RIFF...."},
      {"a.obj", OutputKind::kObj, "# tetrig export: x\n# more\nv 0 0 0\n", "# Blender v3.4 OBJ File\nv 0 0 0\n"},
      {"b.obj", OutputKind::kObj, "#tetrig pose: rig\nv 0 0 0\n", "v 0 0 0\n# tetrig export: comment after the data\n"},
      {"a.ply", OutputKind::kPly, "ply\nformat ascii 1.0\ncomment tetrig export: x\nend_header\n",
       "ply\nformat ascii 1.0\ncomment VCGLIB generated\nend_header\ncomment tetrig\n"},
      {"a.gltf", OutputKind::kGltf, "{\"asset\":{\"generator\":\"tetrig export\",\"version\":\"2.0\"}}",
       "{\"asset\":{\"generator\":\"Khronos glTF Blender I/O\"},\"extras\":\"tetrig\"}"},
      {"a.glb", OutputKind::kGlb, glb(glb_json), glb(glb_other)},
      {"a.json", OutputKind::kJson, "{\n  \"generator\": \"tetrig export\"\n}\n", "{\"name\": \"tetrig\"}"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const auto ours = d.write(std::string("ours_") + c.name, c.ours);
    const auto theirs = d.write(std::string("theirs_") + c.name, c.theirs);
    EXPECT_TRUE(writtenByTetrig(ours, c.kind));
    EXPECT_FALSE(writtenByTetrig(theirs, c.kind));
    EXPECT_EQ(refusal(ours, c.kind, {}, false), "");
    EXPECT_NE(refusal(theirs, c.kind, {}, false).find("exists and tetrig did not write it: refusing to replace it; give another name, "
                                                      "or add --force to replace it"),
              std::string::npos);
    EXPECT_EQ(refusal(theirs, c.kind, {}, true), "");
  }
  EXPECT_FALSE(writtenByTetrig(d / "missing.obj", OutputKind::kObj));
  EXPECT_EQ(refusal(d / "missing.obj", OutputKind::kObj, {}, false), "");  // a new file is always fine
}

TEST(OutputGuard, APointCacheIsTetrigsWhenItsRestMeshSaysSo) {
  const TempDir d;
  EXPECT_EQ(pc2RestObjPath("dir/walk.pc2"), std::filesystem::path("dir/walk.rest.obj"));
  const auto pc2 = d.write("walk.pc2", "POINTCACHE2");
  EXPECT_FALSE(writtenByTetrig(pc2, OutputKind::kPc2));  // no rest mesh beside it
  d.write("walk.rest.obj", "# tetrig export: rig\n# rest fine mesh; the animation is the point cache other.pc2\nv 0 0 0\n");
  EXPECT_FALSE(writtenByTetrig(pc2, OutputKind::kPc2));  // tetrig's, but for another cache
  d.write("walk.rest.obj", "# tetrig export: rig\n# rest fine mesh; the animation is the point cache walk.pc2\nv 0 0 0\n");
  EXPECT_TRUE(writtenByTetrig(pc2, OutputKind::kPc2));
  d.write("walk.rest.obj", "# rest fine mesh; the animation is the point cache walk.pc2\nv 0 0 0\n");
  EXPECT_FALSE(writtenByTetrig(pc2, OutputKind::kPc2));  // not tetrig's mark
}

TEST(OutputGuard, AnInputIsNeverAnOutput) {
  const TempDir d;
  const auto rig = d.write("human.rig", std::string("TETRIGRF\x01\0\0\0", 12));
  const auto mesh = d.write("human.obj", "# tetrig export: looks like ours\nv 0 0 0\n");
  // The same path, even with force and even though it carries tetrig's mark.
  EXPECT_NE(refusal(mesh, OutputKind::kObj, {rig, mesh}, true).find("human.obj is also an input of this command: writing it would lose "
                                                                    "the input; give another name"),
            std::string::npos);
  // Another name for the same file: a hard link, a symbolic link, a path through "..".
  std::filesystem::create_hard_link(rig, d / "hard.rig");
  std::filesystem::create_symlink(rig, d / "soft.rig");
  std::filesystem::create_directory(d / "sub");
  for (const std::filesystem::path& alias : {d / "hard.rig", d / "soft.rig", d / "sub" / ".." / "human.rig"}) {
    SCOPED_TRACE(alias.string());
    EXPECT_NE(refusal(alias, OutputKind::kRig, {rig}, true).find("is the same file as the input " + rig.string()), std::string::npos);
  }
  // Empty and missing inputs are ignored.
  EXPECT_EQ(refusal(d / "new.rig", OutputKind::kRig, {std::filesystem::path(), d / "missing.c3d"}, false), "");
  // A directory is refused with its own message.
  EXPECT_NE(refusal(d / "sub", OutputKind::kRig, {}, true).find("sub is a directory; give a file name"), std::string::npos);
}

// The folder an output goes in must exist now, not when the file is written after the work.
TEST(OutputGuard, AFolderThatDoesNotExistIsRefusedBeforeAnyWork) {
  const TempDir d;
  const std::string missing = (d / "no" / "such").string();
  EXPECT_NE(refusal(d / "no" / "such" / "out.json", OutputKind::kJson, {}, true)
                .find("out.json: the folder " + missing + " does not exist (create it first)"),
            std::string::npos);
  EXPECT_EQ(refusal(d / "out.json", OutputKind::kJson, {}, false), "") << "an existing folder is fine";
  // A file where the folder should be is no folder either.
  const auto file = d.write("plain", "x");
  EXPECT_NE(refusal(file / "out.json", OutputKind::kJson, {}, true).find("does not exist (create it first)"), std::string::npos);
}

}  // namespace
}  // namespace tetrig::rigbuild
