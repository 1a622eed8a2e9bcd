// Output paths checked before any work: no input replaced, no file replaced that tetrig did not
// write (output_guard.hpp).
#include "tetrig/rigbuild/output_guard.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <cstring>
#include <fstream>
#include <string_view>
#include <vector>

#include "tetrig/printable_text.hpp"

namespace tetrig::rigbuild {

namespace {

// The first `limit` bytes of a regular file (fewer if it is shorter; none if it cannot be read).
std::string head(const std::filesystem::path& file, std::size_t limit) {
  std::ifstream in(file, std::ios::binary);
  std::string bytes(limit, '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(limit));
  bytes.resize(in ? limit : static_cast<std::size_t>(std::max<std::streamsize>(in.gcount(), 0)));
  return bytes;
}

// Comment lines at the top of a text mesh: `prefix`-led lines before the first other line.
bool headerCommentStartsTetrig(std::string_view text, std::string_view prefix, bool skip_non_comments) {
  std::size_t at = 0;
  while (at < text.size()) {
    std::size_t end = text.find('\n', at);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(at, end - at);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (line.rfind(prefix, 0) == 0) {
      std::string_view rest = line.substr(prefix.size());
      while (!rest.empty() && rest.front() == ' ') rest.remove_prefix(1);
      if (rest.rfind("tetrig", 0) == 0) return true;
    } else if (!skip_non_comments && !line.empty()) {
      return false;
    }
    at = end + 1;
  }
  return false;
}

// `"generator":"tetrig...` (tinygltf's compact JSON, or with spaces) within `json`.
bool generatorIsTetrig(std::string_view json) {
  const std::size_t key = json.find("\"generator\"");
  if (key == std::string_view::npos) return false;
  std::size_t at = key + std::strlen("\"generator\"");
  while (at < json.size() && (json[at] == ' ' || json[at] == ':' || json[at] == '\n' || json[at] == '\t')) ++at;
  return json.substr(at).rfind("\"tetrig", 0) == 0;
}

bool sameFile(const std::filesystem::path& a, const std::filesystem::path& b) {
  struct stat sa {}, sb {};
  if (::stat(a.c_str(), &sa) != 0 || ::stat(b.c_str(), &sb) != 0) {
    std::error_code ea, eb;
    const auto ca = std::filesystem::weakly_canonical(a, ea), cb = std::filesystem::weakly_canonical(b, eb);
    return !ea && !eb && ca == cb;
  }
  return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
}

}  // namespace

std::filesystem::path pc2RestObjPath(const std::filesystem::path& pc2) {
  std::filesystem::path obj = pc2;
  obj.replace_extension(".rest.obj");
  return obj;
}

bool writtenByTetrig(const std::filesystem::path& file, OutputKind kind) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec)) return false;
  switch (kind) {
    case OutputKind::kRig:
      return head(file, 8) == "TETRIGRF";
    case OutputKind::kObj:
      // Comments first; tetrig's OBJ files open with their comment block.
      return headerCommentStartsTetrig(head(file, 4096), "#", false);
    case OutputKind::kPly: {
      const std::string h = head(file, 4096);
      const std::size_t end = h.find("end_header");
      return h.rfind("ply", 0) == 0 && headerCommentStartsTetrig(std::string_view(h).substr(0, end), "comment", true);
    }
    case OutputKind::kPc2: {
      const std::filesystem::path obj = pc2RestObjPath(file);
      if (!writtenByTetrig(obj, OutputKind::kObj)) return false;
      return head(obj, 4096).find("point cache " + file.filename().string()) != std::string::npos;
    }
    case OutputKind::kGltf:
    case OutputKind::kJson:
      return generatorIsTetrig(head(file, 1 << 20));
    case OutputKind::kGlb: {
      // 12-byte header, then the JSON chunk (length, "JSON", text).
      const std::string h = head(file, 1 << 20);
      return h.size() > 20 && h.compare(0, 4, "glTF") == 0 && h.compare(16, 4, "JSON") == 0 &&
             generatorIsTetrig(std::string_view(h).substr(20));
    }
  }
  return false;
}

void checkOutputPath(const std::filesystem::path& out, OutputKind kind, std::span<const std::filesystem::path> inputs,
                     bool force, const std::string& what) {
  const std::string shown = printableText(out.string());
  std::error_code ec;
  const auto status = std::filesystem::status(out, ec);
  if (std::filesystem::is_directory(status)) {
    throw OutputRefused(what + " " + shown + " is a directory; give a file name");
  }
  // The folder it goes in, now: found missing only when the file is written, after the work, it
  // would lose that work.
  const std::filesystem::path dir = out.has_parent_path() ? out.parent_path() : std::filesystem::path(".");
  if (!std::filesystem::is_directory(dir, ec)) {
    throw OutputRefused(what + " " + shown + ": the folder " + printableText(dir.string()) + " does not exist (create it first)");
  }
  if (::access(dir.c_str(), W_OK) != 0) {
    throw OutputRefused(what + " " + shown + ": the folder " + printableText(dir.string()) + " is not writable");
  }
  for (const std::filesystem::path& in : inputs) {
    if (!in.empty() && std::filesystem::exists(in, ec) && sameFile(out, in)) {
      const std::string which = in == out ? "also an input of this command" : "the same file as the input " + printableText(in.string());
      throw OutputRefused(what + " " + shown + " is " + which + ": writing it would lose the input; give another name");
    }
  }
  if (!std::filesystem::exists(status) || force) return;
  if (!writtenByTetrig(out, kind)) {
    throw OutputRefused(what + " " + shown + " exists and tetrig did not write it: refusing to replace it; give another name, "
                        "or add --force to replace it");
  }
}

}  // namespace tetrig::rigbuild
