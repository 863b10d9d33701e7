#include "range_image_mapping/io/mesh_file.h"

#include "range_image_mapping/io/ply.h"
#include "triangle_fan.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>

namespace range_image_mapping::io {
namespace {

std::string lowerCaseExtension(const std::string& path) {
  std::string extension = std::filesystem::path(path).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return extension;
}

// Wavefront OBJ, statement by statement; only geometry ("v", "f") is kept.
class ObjParser {
 public:
  ObjParser(const std::string& path, const std::string& text) : path_(path), text_(text) {}

  TriangleMesh parse() {
    while (nextStatement()) {
      const std::size_t keyword_end = statement_.find_first_of(" \t");
      const std::string keyword = statement_.substr(0, keyword_end);
      cursor_ = keyword_end == std::string::npos ? statement_.size() : keyword_end;
      if (keyword == "v")
        parseVertex();
      else if (keyword == "f")
        parseFace();
      // Normals, texture coordinates, groups, materials, lines: not geometry we cast against.
    }
    if (largest_index_ >= static_cast<long long>(mesh_.vertices.size()))
      fail(largest_index_line_, "a face refers to vertex " + std::to_string(largest_index_ + 1) +
                                    " but the file has " + std::to_string(mesh_.vertices.size()) +
                                    " vertices");
    return std::move(mesh_);
  }

 private:
  // One statement: a line, joined with the next while it ends in a backslash.
  bool nextStatement() {
    statement_.clear();
    bool have_line = false;
    while (position_ < text_.size()) {
      std::size_t end = text_.find('\n', position_);
      if (end == std::string::npos) end = text_.size();
      std::string line = text_.substr(position_, end - position_);
      position_ = end + 1;
      ++line_number_;
      if (!have_line) statement_line_ = line_number_;
      have_line = true;
      if (const std::size_t comment = line.find('#'); comment != std::string::npos)
        line.erase(comment);
      while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back())))
        line.pop_back();
      const bool continued = !line.empty() && line.back() == '\\';
      if (continued) line.back() = ' ';
      statement_ += line;
      if (!continued) break;
    }
    const std::size_t first = statement_.find_first_not_of(" \t");
    statement_.erase(0, first == std::string::npos ? statement_.size() : first);
    return have_line;
  }

  // Skips blanks; false at the end of the statement.
  bool nextToken() {
    cursor_ = statement_.find_first_not_of(" \t", cursor_);
    if (cursor_ == std::string::npos) cursor_ = statement_.size();
    return cursor_ < statement_.size();
  }

  void parseVertex() {
    std::vector<double> values;
    while (nextToken()) {
      const char* start = statement_.c_str() + cursor_;
      char* end = nullptr;
      errno = 0;
      const double value = std::strtod(start, &end);
      if (end == start || (*end != '\0' && *end != ' ' && *end != '\t'))
        fail(statement_line_, "vertex coordinate \"" + token() + "\" is not a number");
      if (errno == ERANGE || !std::isfinite(value))
        fail(statement_line_, "vertex coordinate \"" + token() + "\" is not finite");
      values.push_back(value);
      cursor_ += static_cast<std::size_t>(end - start);
    }
    // x y z, then an optional w or a colour some writers append.
    if (values.size() < 3 || values.size() > 7)
      fail(statement_line_, "a vertex needs 3 coordinates, found " + std::to_string(values.size()));
    for (int axis = 0; axis < 3; ++axis)
      if (std::abs(values[axis]) > std::numeric_limits<float>::max())
        fail(statement_line_,
             "vertex coordinate " + std::to_string(values[axis]) + " does not fit a float");
    mesh_.vertices.emplace_back(static_cast<float>(values[0]), static_cast<float>(values[1]),
                                static_cast<float>(values[2]));
  }

  void parseFace() {
    polygon_.clear();
    while (nextToken()) polygon_.push_back(parseCorner());
    if (polygon_.size() < 3)
      fail(statement_line_,
           "a face needs at least 3 corners, found " + std::to_string(polygon_.size()));
    appendTriangleFan(polygon_, mesh_.triangles);
  }

  // "i", "i/t", "i//n" or "i/t/n": only the vertex index i matters.
  int parseCorner() {
    const std::string corner = token();
    const char* start = statement_.c_str() + cursor_;
    char* end = nullptr;
    errno = 0;
    const long long index = std::strtoll(start, &end, 10);
    cursor_ += corner.size();
    if (end == start || (*end != '/' && *end != '\0' && *end != ' ' && *end != '\t'))
      fail(statement_line_, "face corner \"" + corner + "\" does not start with a vertex index");
    if (index == 0 || errno == ERANGE)
      fail(statement_line_, "face corner \"" + corner + "\" has vertex index " +
                                (errno == ERANGE ? "out of range" : "0 (indices start at 1)"));
    const auto vertex_count = static_cast<long long>(mesh_.vertices.size());
    // Negative indices count back from the latest vertex.
    const long long zero_based = index < 0 ? vertex_count + index : index - 1;
    if (zero_based < 0)
      fail(statement_line_, "face corner \"" + corner + "\" refers back past the first vertex (" +
                                std::to_string(vertex_count) + " so far)");
    if (zero_based >= std::numeric_limits<int>::max())
      fail(statement_line_, "face corner \"" + corner + "\" has a vertex index beyond int");
    // Positive indices may name vertices defined later: checked at the end.
    if (zero_based > largest_index_) {
      largest_index_ = zero_based;
      largest_index_line_ = statement_line_;
    }
    return static_cast<int>(zero_based);
  }

  std::string token() const {
    const std::size_t end = statement_.find_first_of(" \t", cursor_);
    return statement_.substr(cursor_, end == std::string::npos ? std::string::npos : end - cursor_);
  }

  [[noreturn]] void fail(int line, const std::string& problem) const {
    throw MeshFileError("OBJ: " + path_ + " line " + std::to_string(line) + ": " + problem);
  }

  const std::string& path_;
  const std::string& text_;
  std::size_t position_ = 0;
  int line_number_ = 0;
  int statement_line_ = 0;
  std::string statement_;
  std::size_t cursor_ = 0;
  std::vector<int> polygon_;
  long long largest_index_ = -1;
  int largest_index_line_ = 0;
  TriangleMesh mesh_;
};

TriangleMesh loadObj(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) throw MeshFileError("OBJ: cannot open " + path);
  const std::string text((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  return ObjParser(path, text).parse();
}

TriangleMesh loadPly(const std::string& path) {
  TriangleMesh mesh = readPlyMesh(path);
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i)
    if (!mesh.vertices[i].allFinite())
      throw MeshFileError("PLY: " + path + " vertex " + std::to_string(i) + " is not finite");
  return mesh;
}

}  // namespace

TriangleMesh loadMeshFile(const std::string& path) {
  const std::string extension = lowerCaseExtension(path);
  TriangleMesh mesh;
  if (extension == ".ply")
    mesh = loadPly(path);
  else if (extension == ".obj")
    mesh = loadObj(path);
  else
    throw MeshFileError("mesh file " + path + " has extension \"" + extension +
                        "\"; expected .ply or .obj");
  if (mesh.triangles.empty()) throw MeshFileError("mesh file " + path + " has no triangles");
  return mesh;
}

void saveMeshFile(const std::string& path, const TriangleMesh& mesh) {
  if (lowerCaseExtension(path) != ".ply")
    throw MeshFileError("mesh file " + path + ": meshes are saved as PLY; use the .ply extension");
  std::vector<PlyProperty> properties;
  if (!mesh.intensities.empty()) properties.push_back({"intensity", mesh.intensities});
  writePlyMesh(path, mesh.vertices, mesh.normals, mesh.triangles, properties);
}

}  // namespace range_image_mapping::io
