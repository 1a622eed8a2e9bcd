// What a command may replace: never one of its own inputs, and an existing file only when tetrig
// wrote it (recognised by what tetrig puts in such a file) or the user said --force.
// Offline, any thread; throws OutputRefused with one line that names the file and what to do.
// Call it for every output path before any work starts, so a refusal costs nothing.
#pragma once

#include <filesystem>
#include <span>
#include <stdexcept>
#include <string>

namespace tetrig::rigbuild {

class OutputRefused : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// The kinds of file tetrig writes, each with the mark that shows tetrig wrote it.
enum class OutputKind {
  kRig,   // rig file: starts with the magic "TETRIGRF"
  kObj,   // OBJ: a '#' comment line before the first vertex that starts "# tetrig"
  kPly,   // PLY: a "comment tetrig" header line
  kPc2,   // PC2 point cache (no room for a mark): tetrig's when its rest OBJ (pc2RestObjPath) is
          // tetrig's and names this point cache
  kGltf,  // glTF JSON: the asset's generator starts "tetrig"
  kGlb,   // binary glTF: the same, in its JSON chunk
  kJson,  // a JSON report: a "generator" key whose value starts "tetrig"
};

// The rest mesh written beside a point cache: FILE.pc2 -> FILE.rest.obj (never FILE.obj, which is
// where a user keeps the mesh the cache was made for).
std::filesystem::path pc2RestObjPath(const std::filesystem::path& pc2);

// True when `file` exists, is a regular file and carries tetrig's mark for `kind`.
bool writtenByTetrig(const std::filesystem::path& file, OutputKind kind);

// Refuses `out` (OutputRefused) when it is a directory, when the folder it goes in does not exist
// or is not writable, when it is the same file as any of `inputs` (even with `force`), or when it
// exists and tetrig did not write it (unless `force`).
// `what` names the option in the message, e.g. "--out".
void checkOutputPath(const std::filesystem::path& out, OutputKind kind, std::span<const std::filesystem::path> inputs,
                     bool force, const std::string& what = "--out");

}  // namespace tetrig::rigbuild
