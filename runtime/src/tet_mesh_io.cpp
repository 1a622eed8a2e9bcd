// Readers for two tetrahedral mesh file formats:
// - TetGen's .node/.ele text files (format as documented in the TetGen 1.5 user manual, section
//   "File formats": header lines "<#points> <dim> <#attributes> <#boundary markers>" and
//   "<#tets> <nodes per tet> <#attributes>", one record per line, '#' starts a comment);
// - the MEDIT .mesh ASCII format (INRIA, "MEDIT: an interactive mesh visualization software",
//   P. Frey 2001): keyword sections "Vertices N" (x y z ref) and "Tetrahedra N" (a b c d ref,
//   1-based), other keyword sections carry a count and one record per line, "End" ends the file.
//
// Both parsers work line by line so that every error names the line it was found on. Counts are
// checked against the size of the text before anything is allocated from them, so a corrupt count
// cannot make the reader allocate gigabytes.
#include "tetrig/tet_mesh_io.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <limits>
#include <sstream>
#include <string_view>
#include <system_error>
#include <vector>

namespace tetrig {
namespace {

// One text file split into lines, handing out the tokens of each non-empty line ('#' comments and
// '\r' removed) together with its 1-based line number.
class LineTokenizer {
 public:
  LineTokenizer(const std::string& text, std::string name) : text_(text), name_(std::move(name)) {}

  // Advances to the next line that has at least one token. False at the end of the text.
  bool next() {
    while (pos_ < text_.size()) {
      const size_t end = text_.find('\n', pos_);
      const size_t stop = end == std::string_view::npos ? text_.size() : end;
      std::string_view line = text_.substr(pos_, stop - pos_);
      pos_ = end == std::string_view::npos ? text_.size() : end + 1;
      ++line_no_;
      if (const size_t hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
      tokens_.clear();
      size_t i = 0;
      while (i < line.size()) {
        while (i < line.size() && isSpace(line[i])) ++i;
        const size_t start = i;
        while (i < line.size() && !isSpace(line[i])) ++i;
        if (i > start) tokens_.push_back(line.substr(start, i - start));
      }
      if (!tokens_.empty()) return true;
    }
    tokens_.clear();
    return false;
  }

  const std::vector<std::string_view>& tokens() const { return tokens_; }
  size_t lineNo() const { return line_no_; }
  size_t textSize() const { return text_.size(); }
  const std::string& name() const { return name_; }

  [[noreturn]] void fail(const std::string& what) const {
    throw MeshFileError(name_ + ":" + std::to_string(line_no_) + ": " + what);
  }
  [[noreturn]] void failAtEnd(const std::string& what) const {
    throw MeshFileError(name_ + ": unexpected end of file: " + what);
  }

  // Parses token k of the current line as an integer in [lo, hi].
  std::int64_t integer(size_t k, const char* what, std::int64_t lo, std::int64_t hi) const {
    const std::string_view tok = tokens_[k];
    std::int64_t value = 0;
    const auto [ptr, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), value);
    if (ec != std::errc() || ptr != tok.data() + tok.size()) {
      fail(std::string("expected an integer ") + what + ", found '" + shorten(tok) + "'");
    }
    if (value < lo || value > hi) {
      fail(std::string(what) + " " + std::to_string(value) + " is out of range [" + std::to_string(lo) +
           ", " + std::to_string(hi) + "]");
    }
    return value;
  }

  // Parses token k of the current line as a finite double.
  double real(size_t k, const char* what) const {
    const std::string_view tok = tokens_[k];
    double value = 0.0;
    const auto [ptr, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), value);
    if (ec != std::errc() || ptr != tok.data() + tok.size()) {
      fail(std::string("expected a number (") + what + "), found '" + shorten(tok) + "'");
    }
    if (!std::isfinite(value)) fail(std::string("non-finite ") + what + " '" + shorten(tok) + "'");
    return value;
  }

  void expectTokenCount(size_t expected, const std::string& what) const {
    if (tokens_.size() != expected) {
      fail("expected " + what + " (" + std::to_string(expected) + " tokens), found " +
           std::to_string(tokens_.size()) + " token" + (tokens_.size() == 1 ? "" : "s"));
    }
  }

  static std::string shorten(std::string_view tok) {
    std::string s(tok.substr(0, 32));
    if (tok.size() > 32) s += "...";
    for (char& c : s) {
      if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) >= 0x7f) c = '?';
    }
    return s;
  }

 private:
  static bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

  std::string_view text_;
  std::string name_;
  size_t pos_ = 0;
  size_t line_no_ = 0;
  std::vector<std::string_view> tokens_;
};

constexpr std::int64_t kMaxCount = std::numeric_limits<std::int32_t>::max() - 1;

// A record needs at least two characters (a token and a separator) per token, so a count larger
// than that bound cannot be satisfied by the text: reject it before allocating.
void checkCountFits(const LineTokenizer& in, std::int64_t count, std::int64_t tokens_per_record,
                    const char* what) {
  // count <= 2^31 and tokens_per_record <= ~2^21: the product cannot overflow 64 bits.
  const std::int64_t need = count * std::max<std::int64_t>(tokens_per_record, 1) * 2;
  if (need > static_cast<std::int64_t>(in.textSize()) + 2) {
    in.fail("count of " + std::string(what) + " " + std::to_string(count) +
            " is larger than the file can hold (" + std::to_string(in.textSize()) + " bytes)");
  }
}

std::string readWholeFile(const std::filesystem::path& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw MeshFileError(path.string() + ": is a folder, not a mesh file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw MeshFileError(path.string() + ": cannot open file for reading");
  std::ostringstream buffer;
  buffer << in.rdbuf();
  if (in.bad()) throw MeshFileError(path.string() + ": read error");
  return std::move(buffer).str();
}

bool looksBinary(const std::string& text) {
  const size_t n = std::min<size_t>(text.size(), 4096);
  for (size_t i = 0; i < n; ++i) {
    if (text[i] == '\0') return true;
  }
  return false;
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// TetGen .node / .ele

TetMesh parseTetGen(const std::string& node_text, const std::string& ele_text, const std::string& name) {
  TetMesh mesh;
  LineTokenizer node(node_text, name + ".node");
  if (looksBinary(node_text)) throw MeshFileError(node.name() + ": binary data, expected a TetGen text file");
  if (!node.next()) node.failAtEnd("expected the header '<#points> 3 <#attributes> <#boundary markers>'");
  if (node.tokens().size() < 2 || node.tokens().size() > 4) {
    node.fail("expected the header '<#points> 3 <#attributes> <#boundary markers>' (2 to 4 tokens), found " +
              std::to_string(node.tokens().size()) + " tokens");
  }
  const std::int64_t n_points = node.integer(0, "point count", 0, kMaxCount);
  if (n_points == 0) {
    node.fail("point count is 0 (points stored in a .smesh/.poly file are not supported; expected the points here)");
  }
  const std::int64_t dim = node.integer(1, "dimension", 0, 1000);
  if (dim != 3) node.fail("expected dimension 3, found " + std::to_string(dim));
  const std::int64_t n_attr = node.tokens().size() > 2 ? node.integer(2, "attribute count", 0, 1000000) : 0;
  const std::int64_t n_marker = node.tokens().size() > 3 ? node.integer(3, "boundary marker count", 0, 1) : 0;
  const std::int64_t node_tokens = 4 + n_attr + n_marker;
  checkCountFits(node, n_points, node_tokens, "points");

  mesh.vertices.resize(n_points, 3);
  std::int64_t base = 0;
  const std::string node_record = "'<index> <x> <y> <z>'" +
                                  (n_attr > 0 ? " + " + std::to_string(n_attr) + " attributes" : std::string()) +
                                  (n_marker > 0 ? std::string(" + a boundary marker") : std::string());
  for (std::int64_t i = 0; i < n_points; ++i) {
    if (!node.next()) {
      node.failAtEnd("expected " + std::to_string(n_points) + " points, found " + std::to_string(i));
    }
    node.expectTokenCount(static_cast<size_t>(node_tokens), "point " + node_record);
    if (i == 0) {
      base = node.integer(0, "first point index (0 or 1)", 0, 1);
    } else {
      const std::int64_t index = node.integer(0, "point index", std::numeric_limits<std::int64_t>::min(),
                                              std::numeric_limits<std::int64_t>::max());
      if (index != base + i) {
        node.fail("expected point index " + std::to_string(base + i) + " (points must be numbered consecutively), found " +
                  std::to_string(index));
      }
    }
    for (int c = 0; c < 3; ++c) mesh.vertices(i, c) = node.real(static_cast<size_t>(1 + c), "coordinate");
    for (std::int64_t a = 0; a < n_attr; ++a) (void)node.real(static_cast<size_t>(4 + a), "point attribute");
    if (n_marker > 0) {
      (void)node.integer(static_cast<size_t>(4 + n_attr), "boundary marker", std::numeric_limits<std::int64_t>::min(),
                         std::numeric_limits<std::int64_t>::max());
    }
  }
  if (node.next()) {
    node.fail("expected end of file after " + std::to_string(n_points) + " points, found more data (is the point count wrong?)");
  }

  LineTokenizer ele(ele_text, name + ".ele");
  if (looksBinary(ele_text)) throw MeshFileError(ele.name() + ": binary data, expected a TetGen text file");
  if (!ele.next()) ele.failAtEnd("expected the header '<#tets> <4 or 10 nodes per tet> <#attributes>'");
  if (ele.tokens().size() < 2 || ele.tokens().size() > 3) {
    ele.fail("expected the header '<#tets> <4 or 10 nodes per tet> <#attributes>' (2 or 3 tokens), found " +
             std::to_string(ele.tokens().size()) + " tokens");
  }
  const std::int64_t n_tets = ele.integer(0, "tet count", 0, kMaxCount);
  const std::int64_t nodes_per_tet = ele.integer(1, "nodes per tet", 0, 1000);
  if (nodes_per_tet != 4 && nodes_per_tet != 10) {
    ele.fail("expected 4 or 10 nodes per tet, found " + std::to_string(nodes_per_tet));
  }
  const std::int64_t ele_attr = ele.tokens().size() > 2 ? ele.integer(2, "attribute count", 0, 1000000) : 0;
  const std::int64_t ele_tokens = 1 + nodes_per_tet + ele_attr;
  checkCountFits(ele, n_tets, ele_tokens, "tets");
  const std::string ele_record = "'<index>' + " + std::to_string(nodes_per_tet) + " node indices" +
                                 (ele_attr > 0 ? " + " + std::to_string(ele_attr) + " attributes" : std::string());

  mesh.tets.resize(n_tets, 4);
  for (std::int64_t t = 0; t < n_tets; ++t) {
    if (!ele.next()) ele.failAtEnd("expected " + std::to_string(n_tets) + " tets, found " + std::to_string(t));
    ele.expectTokenCount(static_cast<size_t>(ele_tokens), "tet " + ele_record);
    (void)ele.integer(0, "tet index", std::numeric_limits<std::int64_t>::min(), std::numeric_limits<std::int64_t>::max());
    for (std::int64_t k = 0; k < nodes_per_tet; ++k) {
      const std::int64_t v = ele.integer(static_cast<size_t>(1 + k), "node index", base, base + n_points - 1);
      if (k < 4) mesh.tets(t, k) = static_cast<std::int32_t>(v - base);
    }
    for (std::int64_t a = 0; a < ele_attr; ++a) (void)ele.real(static_cast<size_t>(1 + nodes_per_tet + a), "tet attribute");
  }
  if (ele.next()) {
    ele.fail("expected end of file after " + std::to_string(n_tets) + " tets, found more data (is the tet count wrong?)");
  }
  return mesh;
}

namespace {

std::filesystem::path withExtension(const std::filesystem::path& path, const char* ext) {
  const std::string e = path.extension().string();
  std::filesystem::path p = path;
  if (e == ".node" || e == ".ele") return p.replace_extension(ext);
  p += ext;
  return p;
}

}  // namespace

TetMesh readTetGen(const std::filesystem::path& path) {
  const std::filesystem::path node_path = withExtension(path, ".node");
  const std::filesystem::path ele_path = withExtension(path, ".ele");
  const std::string node_text = readWholeFile(node_path);
  const std::string ele_text = readWholeFile(ele_path);
  std::filesystem::path stem = node_path;
  stem.replace_extension();
  return parseTetGen(node_text, ele_text, stem.string());
}

// ------------------------------------------------------------------------------------------------
// MEDIT .mesh

TetMesh parseMedit(const std::string& text, const std::string& name) {
  LineTokenizer in(text, name);
  if (looksBinary(text)) {
    throw MeshFileError(name + ": binary data; only ASCII MEDIT .mesh is supported (convert .meshb to .mesh)");
  }
  TetMesh mesh;
  bool have_vertices = false;
  bool have_tets = false;
  bool have_end = false;
  std::vector<std::size_t> tet_lines;  // line of each tet record, for index errors reported later

  // Reads the count of a section: on the keyword's line ("Vertices 12") or on the next line.
  auto readCount = [&in](const std::string& keyword, std::int64_t tokens_per_record) -> std::int64_t {
    std::int64_t count = 0;
    if (in.tokens().size() == 2) {
      count = in.integer(1, ("count of " + keyword).c_str(), 0, kMaxCount);
    } else if (in.tokens().size() == 1) {
      if (!in.next()) in.failAtEnd("expected the count of " + keyword);
      in.expectTokenCount(1, "the count of " + keyword);
      count = in.integer(0, ("count of " + keyword).c_str(), 0, kMaxCount);
    } else {
      in.fail("expected '" + keyword + "' followed by its count, found " + std::to_string(in.tokens().size()) + " tokens");
    }
    checkCountFits(in, count, tokens_per_record, keyword.c_str());
    return count;
  };

  if (!in.next()) in.failAtEnd("expected 'MeshVersionFormatted'");
  bool first = true;
  do {
    const std::string keyword(in.tokens()[0]);
    if (first && keyword != "MeshVersionFormatted") {
      in.fail("expected 'MeshVersionFormatted' (is this a MEDIT .mesh file?), found '" + LineTokenizer::shorten(keyword) + "'");
    }
    first = false;
    if (keyword == "MeshVersionFormatted" || keyword == "Dimension") {
      std::int64_t value = 0;
      if (in.tokens().size() == 2) {
        value = in.integer(1, keyword.c_str(), 0, 1000);
      } else if (in.tokens().size() == 1) {
        if (!in.next()) in.failAtEnd("expected the value of " + keyword);
        in.expectTokenCount(1, "the value of " + keyword);
        value = in.integer(0, keyword.c_str(), 0, 1000);
      } else {
        in.fail("expected '" + keyword + " <value>', found " + std::to_string(in.tokens().size()) + " tokens");
      }
      if (keyword == "Dimension" && value != 3) in.fail("expected Dimension 3, found " + std::to_string(value));
      if (keyword == "MeshVersionFormatted" && (value < 1 || value > 4)) {
        in.fail("expected MeshVersionFormatted 1 to 4, found " + std::to_string(value));
      }
    } else if (keyword == "End") {
      if (in.tokens().size() != 1) in.fail("expected 'End' alone on its line");
      have_end = true;
      break;
    } else if (keyword == "Vertices") {
      if (have_vertices) in.fail("second Vertices section");
      have_vertices = true;
      const std::int64_t n = readCount(keyword, 4);
      mesh.vertices.resize(n, 3);
      for (std::int64_t i = 0; i < n; ++i) {
        if (!in.next()) in.failAtEnd("expected " + std::to_string(n) + " vertices, found " + std::to_string(i));
        in.expectTokenCount(4, "3 coordinates and a reference");
        for (int c = 0; c < 3; ++c) mesh.vertices(i, c) = in.real(static_cast<size_t>(c), "coordinate");
        (void)in.integer(3, "vertex reference", std::numeric_limits<std::int64_t>::min(),
                         std::numeric_limits<std::int64_t>::max());
      }
    } else if (keyword == "Tetrahedra") {
      if (have_tets) in.fail("second Tetrahedra section");
      have_tets = true;
      const std::int64_t n = readCount(keyword, 5);
      mesh.tets.resize(n, 4);
      tet_lines.resize(static_cast<size_t>(n));
      for (std::int64_t t = 0; t < n; ++t) {
        if (!in.next()) in.failAtEnd("expected " + std::to_string(n) + " tetrahedra, found " + std::to_string(t));
        in.expectTokenCount(5, "4 vertex indices and a reference");
        for (int k = 0; k < 4; ++k) {
          // 1-based; the upper bound is checked once Vertices is known (it may come later).
          mesh.tets(t, k) = static_cast<std::int32_t>(in.integer(static_cast<size_t>(k), "vertex index", 1, kMaxCount) - 1);
        }
        (void)in.integer(4, "tetrahedron reference", std::numeric_limits<std::int64_t>::min(),
                         std::numeric_limits<std::int64_t>::max());
        tet_lines[static_cast<size_t>(t)] = in.lineNo();
      }
    } else {
      // Any other section (Edges, Triangles, Corners, Ridges, RequiredVertices, Normals, ...):
      // a count, then that many records, one per line, whose contents we do not need.
      const char c0 = keyword[0];
      if (!((c0 >= 'A' && c0 <= 'Z') || (c0 >= 'a' && c0 <= 'z'))) {
        in.fail("expected a section keyword (Vertices, Tetrahedra, Triangles, ..., End), found '" +
                LineTokenizer::shorten(keyword) + "' (is a count wrong?)");
      }
      if (in.tokens().size() > 2) {
        in.fail("expected '" + LineTokenizer::shorten(keyword) + "' followed by its count, found " +
                std::to_string(in.tokens().size()) + " tokens");
      }
      const std::int64_t n = readCount(LineTokenizer::shorten(keyword), 1);
      for (std::int64_t i = 0; i < n; ++i) {
        if (!in.next()) {
          in.failAtEnd("expected " + std::to_string(n) + " records in section " + LineTokenizer::shorten(keyword) +
                       ", found " + std::to_string(i));
        }
      }
    }
  } while (in.next());

  if (have_end && in.next()) in.fail("found data after 'End'");
  if (!have_vertices) throw MeshFileError(name + ": no Vertices section (expected 'Vertices' followed by its count)");
  if (!have_tets) {
    throw MeshFileError(name + ": no Tetrahedra section (a surface-only .mesh has no volume; tetrahedralize it first)");
  }
  const std::int64_t nv = mesh.vertices.rows();
  for (Eigen::Index t = 0; t < mesh.tets.rows(); ++t) {
    for (int k = 0; k < 4; ++k) {
      if (mesh.tets(t, k) >= nv) {
        throw MeshFileError(name + ":" + std::to_string(tet_lines[static_cast<size_t>(t)]) + ": vertex index " +
                            std::to_string(mesh.tets(t, k) + 1) + " is out of range [1, " + std::to_string(nv) +
                            "] (the file has " + std::to_string(nv) + " vertices)");
      }
    }
  }
  return mesh;
}

TetMesh readMedit(const std::filesystem::path& path) { return parseMedit(readWholeFile(path), path.string()); }

TetMesh readTetMesh(const std::filesystem::path& path) {
  const std::string ext = path.extension().string();
  if (ext == ".node" || ext == ".ele") return readTetGen(path);
  if (ext == ".mesh") return readMedit(path);
  throw MeshFileError(path.string() + ": unknown tet mesh extension '" + ext +
                      "' (expected .node/.ele for TetGen or .mesh for MEDIT)");
}

}  // namespace tetrig
