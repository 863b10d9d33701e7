#include "range_image_mapping/io/mesh_file.h"

#include "range_image_mapping/io/ply.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace range_image_mapping::io {
namespace {

std::string temporaryPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("rim_mesh_file_test_" + name)).string();
}

void writeBytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

template <typename T>
void append(std::string& bytes, T value) {
  char raw[sizeof(T)];
  std::memcpy(raw, &value, sizeof(T));
  bytes.append(raw, sizeof(T));
}

// Any exception's message, or a marker that there was none.
std::string loadError(const std::string& path) {
  try {
    loadMeshFile(path);
  } catch (const std::runtime_error& error) {
    return error.what();
  }
  return "no error";
}

// A tetrahedron with coordinates that are not round in binary.
TriangleMesh tetrahedron() {
  TriangleMesh mesh;
  mesh.vertices = {
      {0.1f, -0.2f, 0.3f}, {1.7f, 0.05f, -0.3f}, {0.3f, 2.9f, 1e-3f}, {0.4f, 0.5f, 3.3f}};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  return mesh;
}

TEST(MeshFile, SavedPlyLoadsBackExactly) {
  const TriangleMesh mesh = tetrahedron();
  const std::string path = temporaryPath("tetrahedron.ply");
  saveMeshFile(path, mesh);
  const TriangleMesh loaded = loadMeshFile(path);
  EXPECT_EQ(loaded.vertices, mesh.vertices);
  EXPECT_EQ(loaded.triangles, mesh.triangles);
  std::remove(path.c_str());
}

TEST(MeshFile, AsciiPlyWithDoublesPolygonsAndOtherElements) {
  const std::string path = temporaryPath("ascii.PLY");  // the extension is case-insensitive
  writeBytes(path,
             "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\n"
             "element vertex 5\r\nproperty double x\r\nproperty uchar red\r\n"
             "property double y\r\nproperty double z\r\n"
             "element face 2\r\nproperty uchar flags\r\nproperty list uchar uint vertex_indices\r\n"
             "property list int float texcoord\r\n"
             "element edge 1\r\nproperty int vertex1\r\nproperty int vertex2\r\n"
             "end_header\r\n"
             "0 255 0 0\r\n1.5 3 0 0\r\n1.5 7 2.25 0\r\n0 9 2.25 -1e-2\r\n0.75 1 1 3\r\n"
             "7 4 0 1 2 3 2 0.5 0.5\r\n"
             "0 3 4 3 2 0\r\n"
             "0 1\r\n");
  const TriangleMesh mesh = loadMeshFile(path);
  ASSERT_EQ(mesh.vertices.size(), 5u);
  EXPECT_EQ(mesh.vertices[2], Eigen::Vector3f(1.5f, 2.25f, 0.0f));
  EXPECT_EQ(mesh.vertices[3], Eigen::Vector3f(0.0f, 2.25f, -1e-2f));
  // The quad becomes a fan around its first corner, keeping the winding.
  const std::vector<Eigen::Vector3i> expected{{0, 1, 2}, {0, 2, 3}, {4, 3, 2}};
  EXPECT_EQ(mesh.triangles, expected);
  std::remove(path.c_str());
}

TEST(MeshFile, BinaryPlyWithDoublesIntCountsAndUnsignedIndices) {
  std::string bytes =
      "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty double x\n"
      "property double y\nproperty double z\nproperty float confidence\n"
      "element face 1\nproperty list int uint vertex_index\nend_header\n";
  const double coordinates[4][3] = {{0, 0, 0}, {2.5, 0, 0.125}, {2.5, 4, 0.125}, {0, 4, 1e-9}};
  for (const auto& vertex : coordinates) {
    for (double value : vertex) append(bytes, value);
    append(bytes, 0.5f);
  }
  append<int32_t>(bytes, 4);
  for (uint32_t index : {3u, 2u, 1u, 0u}) append(bytes, index);
  const std::string path = temporaryPath("binary.ply");
  writeBytes(path, bytes);
  const TriangleMesh mesh = loadMeshFile(path);
  ASSERT_EQ(mesh.vertices.size(), 4u);
  EXPECT_EQ(mesh.vertices[1], Eigen::Vector3f(2.5f, 0.0f, 0.125f));
  EXPECT_EQ(mesh.vertices[3], Eigen::Vector3f(0.0f, 4.0f, 1e-9f));
  const std::vector<Eigen::Vector3i> expected{{3, 2, 1}, {3, 1, 0}};
  EXPECT_EQ(mesh.triangles, expected);
  std::remove(path.c_str());
}

TEST(MeshFile, ObjCornerFormsNegativeIndicesAndContinuations) {
  const std::string path = temporaryPath("scene.obj");
  writeBytes(path,
             "# a quad and a triangle\nmtllib scene.mtl\no quad\n"
             "v 0 0 0\nv 1 0 0\r\nv 1 1 0 1.0\nv 0 1 0 0.5 0.5 0.5\n"
             "vt 0 0\nvn 0 0 1\ng walls\nusemtl grey\ns off\n"
             "f 1/1/1 2/1/1 3//1 \\\n  4/1\n"
             "v 0.5 0.5 2.75   # apex\n"
             "f -1 -5 -4\n"
             "l 1 2\n");
  const TriangleMesh mesh = loadMeshFile(path);
  ASSERT_EQ(mesh.vertices.size(), 5u);
  EXPECT_EQ(mesh.vertices[4], Eigen::Vector3f(0.5f, 0.5f, 2.75f));
  const std::vector<Eigen::Vector3i> expected{{0, 1, 2}, {0, 2, 3}, {4, 0, 1}};
  EXPECT_EQ(mesh.triangles, expected);
  std::remove(path.c_str());
}

TEST(MeshFile, ObjAllowsFacesBeforeTheirVertices) {
  const std::string path = temporaryPath("late_vertices.obj");
  writeBytes(path, "f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n");
  const TriangleMesh mesh = loadMeshFile(path);
  EXPECT_EQ(mesh.triangles, std::vector<Eigen::Vector3i>({{0, 1, 2}}));
  std::remove(path.c_str());
}

TEST(MeshFile, MalformedObjNamesFileAndLine) {
  const std::string path = temporaryPath("malformed.obj");
  const auto expectError = [&](const std::string& text, const std::string& part) {
    writeBytes(path, text);
    const std::string error = loadError(path);
    EXPECT_NE(error.find("OBJ: " + path + " line "), std::string::npos) << "got: " << error;
    EXPECT_NE(error.find(part), std::string::npos) << "got: " << error;
  };
  const std::string triangle = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  expectError(triangle + "v 1 zwei 3\n", "line 4: vertex coordinate \"zwei\" is not a number");
  expectError(triangle + "v 1 2\n", "line 4: a vertex needs 3 coordinates, found 2");
  expectError(triangle + "v 1 2 nan\n", "line 4: vertex coordinate \"nan\" is not finite");
  expectError(triangle + "v 1 2 1e400\n", "not finite");
  expectError(triangle + "\n\nf 1 2\n", "line 6: a face needs at least 3 corners, found 2");
  expectError(triangle + "f 1 2 0\n", "line 4: face corner \"0\" has vertex index 0");
  expectError(triangle + "f 1 2 x/1\n", "face corner \"x/1\" does not start with a vertex index");
  expectError(triangle + "f 1 2 3x\n", "does not start with a vertex index");
  expectError(triangle + "f -1 -2 -4\n",
              "line 4: face corner \"-4\" refers back past the first vertex");
  expectError(triangle + "f 1 2 3\n# more\nf 1 2 9\n",
              "line 6: a face refers to vertex 9 but the file has 3 vertices");
  std::remove(path.c_str());
}

TEST(MeshFile, MalformedPlyNamesFileAndProblem) {
  const std::string path = temporaryPath("malformed.ply");
  const auto expectError = [&](const std::string& bytes, const std::string& part) {
    writeBytes(path, bytes);
    const std::string error = loadError(path);
    EXPECT_NE(error.find(path), std::string::npos) << "got: " << error;
    EXPECT_NE(error.find(part), std::string::npos) << "got: " << error;
  };
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 1 0\n";
  expectError(header + "3 0 1 3\n", "face 0 refers to vertex 3 of 3 (line 13)");
  expectError(header + "3 0 1 -1\n", "face 0 refers to vertex -1 of 3");
  expectError(header + "2 0 1\n", "face 0 has 2 vertices; a face needs at least 3 (line 13)");
  expectError(header + "4 0 1 2\n", "ends in the middle of the data");
  expectError(header + "3 0 1 two\n", "not a number");
  expectError(
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n",
      "has no face element");
  expectError(
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 0\nproperty list uchar int vertex_indices\n"
      "end_header\n0 0 0\n1 0 0\n0 1 0\n",
      "has no triangles");
  expectError(
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property double z\nelement face 1\nproperty list uchar int vertex_indices\n"
      "end_header\n0 0 0\n1 0 0\n0 1 1e300\n3 0 1 2\n",
      "vertex 2 is not finite");
  // A hostile list length in a binary file is caught before any allocation.
  std::string binary =
      "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n"
      "property float y\nproperty float z\nelement face 1\n"
      "property list uint int vertex_indices\nend_header\n";
  for (int axis = 0; axis < 3; ++axis) append(binary, 0.0f);
  append<uint32_t>(binary, 4000000000u);
  expectError(binary, "has a list of 4000000000 items but only 0 bytes left");
  std::remove(path.c_str());
}

TEST(MeshFile, RejectsUnknownExtensionsMissingFilesAndSavingOtherFormats) {
  EXPECT_NE(loadError("/tmp/scene.stl").find("has extension \".stl\"; expected .ply or .obj"),
            std::string::npos);
  EXPECT_NE(loadError("/nonexistent/scene.obj").find("OBJ: cannot open /nonexistent/scene.obj"),
            std::string::npos);
  EXPECT_NE(loadError("/nonexistent/scene.ply").find("cannot open"), std::string::npos);
  EXPECT_THROW(saveMeshFile(temporaryPath("scene.obj"), tetrahedron()), MeshFileError);
  TriangleMesh broken = tetrahedron();
  broken.triangles.push_back({0, 1, 4});
  EXPECT_THROW(saveMeshFile(temporaryPath("broken.ply"), broken), std::invalid_argument);
  const std::string empty_obj = temporaryPath("empty.obj");
  writeBytes(empty_obj, "v 0 0 0\n");
  EXPECT_NE(loadError(empty_obj).find("has no triangles"), std::string::npos);
  std::remove(empty_obj.c_str());
}

}  // namespace
}  // namespace range_image_mapping::io
