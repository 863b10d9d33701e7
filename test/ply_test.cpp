#include "range_image_mapping/io/ply.h"

#include "test_data.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

namespace range_image_mapping::io {
namespace {

std::string temporaryPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("rim_ply_test_" + name)).string();
}

std::string readBytes(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
}

void writeBytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

std::string readError(const std::string& path) {
  try {
    readPlyPoints(path);
  } catch (const PlyFormatError& error) { return error.what(); }
  return "no PlyFormatError";
}

std::vector<Eigen::Vector3f> somePoints(std::size_t count) {
  std::vector<Eigen::Vector3f> points(count);
  for (std::size_t i = 0; i < count; ++i)
    points[i] = Eigen::Vector3f(0.5f * i - 3.0f, 1e-3f * i * i, -7.25f + std::sin(float(i)));
  return points;
}

TEST(PlyPointCloud, WriteReadRoundTripWithExtraProperties) {
  const std::vector<Eigen::Vector3f> points = somePoints(1000);
  std::vector<uint16_t> row(points.size());
  std::vector<int32_t> column(points.size());
  std::vector<float> range(points.size());
  std::vector<uint8_t> label(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    row[i] = static_cast<uint16_t>(i % 128);
    column[i] = static_cast<int32_t>(i) - 500;
    range[i] = points[i].norm();
    label[i] = static_cast<uint8_t>(i * 7);
  }
  const std::string path = temporaryPath("cloud.ply");
  writePlyPointCloud(path, points,
                     {{"row", row}, {"col", column}, {"range", range}, {"label", label}});

  EXPECT_EQ(readPlyPoints(path), points);
  // The layout other tools read: header text, then 12 + 2 + 4 + 4 + 1 bytes per vertex.
  const std::string bytes = readBytes(path);
  const std::string header =
      "ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\n"
      "property float y\nproperty float z\nproperty ushort row\nproperty int col\n"
      "property float range\nproperty uchar label\nend_header\n";
  ASSERT_EQ(bytes.substr(0, header.size()), header);
  ASSERT_EQ(bytes.size(), header.size() + 1000 * 23);
  const std::size_t vertex = header.size() + 999 * 23;
  uint16_t stored_row;
  int32_t stored_column;
  float stored_range;
  std::memcpy(&stored_row, bytes.data() + vertex + 12, 2);
  std::memcpy(&stored_column, bytes.data() + vertex + 14, 4);
  std::memcpy(&stored_range, bytes.data() + vertex + 18, 4);
  EXPECT_EQ(stored_row, row[999]);
  EXPECT_EQ(stored_column, column[999]);
  EXPECT_EQ(stored_range, range[999]);
  EXPECT_EQ(static_cast<uint8_t>(bytes[vertex + 22]), label[999]);
  std::remove(path.c_str());
}

TEST(PlyPointCloud, BadPropertiesAreRejected) {
  const std::vector<Eigen::Vector3f> points = somePoints(4);
  const std::string path = temporaryPath("bad.ply");
  EXPECT_THROW(writePlyPointCloud(path, points, {{"range", std::vector<float>(3)}}),
               std::invalid_argument);
  EXPECT_THROW(writePlyPointCloud(path, points, {{"x", std::vector<float>(4)}}),
               std::invalid_argument);
  EXPECT_THROW(writePlyPointCloud(path, points, {{"my range", std::vector<float>(4)}}),
               std::invalid_argument);
  EXPECT_THROW(writePlyPointCloud("/nonexistent/dir/cloud.ply", points), PlyFormatError);
}

TEST(PlyPointCloud, ReferenceMapLoads) {
  RIM_REQUIRE_DATA(map_path, "ouster-extra/OS-1-128_v2.3.0_1024x10_lb_n3_map-000.ply");
  const std::vector<Eigen::Vector3f> points = readPlyPoints(map_path);
  ASSERT_EQ(points.size(), 155000u);
  Eigen::Vector3f low = points.front(), high = points.front();
  for (const Eigen::Vector3f& point : points) {
    low = low.cwiseMin(point);
    high = high.cwiseMax(point);
  }
  // SOURCE.md: bbox x[-246.5,245.6] y[-53.4,73.7] z[-4.3,17.4], rounded to 0.1 m.
  EXPECT_NEAR(low.x(), -246.5, 0.05);
  EXPECT_NEAR(high.x(), 245.6, 0.05);
  EXPECT_NEAR(low.y(), -53.4, 0.05);
  EXPECT_NEAR(high.y(), 73.7, 0.05);
  EXPECT_NEAR(low.z(), -4.3, 0.05);
  EXPECT_NEAR(high.z(), 17.4, 0.05);
}

TEST(PlyPointCloud, ReadsAsciiDoublesAndSkipsOtherElements) {
  const std::string path = temporaryPath("ascii.ply");
  writeBytes(path,
             "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\n"
             "element camera 1\r\nproperty list uchar float view\r\nproperty int id\r\n"
             "element vertex 2\r\nproperty uchar red\r\nproperty double z\r\nproperty double x\r\n"
             "property list uchar int neighbours\r\nproperty double y\r\n"
             "element face 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n"
             "3 0.5 0.25 1 7\r\n"
             "255 3.5 1.25 2 1 0 -2e-3\r\n"
             "0 -1 -2 0 1e2\r\n"
             "3 0 1 1\r\n");
  const std::vector<Eigen::Vector3f> points = readPlyPoints(path);
  ASSERT_EQ(points.size(), 2u);
  EXPECT_EQ(points[0], Eigen::Vector3f(1.25f, -2e-3f, 3.5f));
  EXPECT_EQ(points[1], Eigen::Vector3f(-2.0f, 100.0f, -1.0f));
  std::remove(path.c_str());
}

TEST(PlyPointCloud, MalformedFilesGiveClearErrors) {
  const std::string path = temporaryPath("malformed.ply");
  const auto expectError = [&](const std::string& bytes, const std::string& part) {
    writeBytes(path, bytes);
    const std::string error = readError(path);
    EXPECT_NE(error.find(part), std::string::npos) << "got: " << error;
  };
  const std::string vertex_header =
      "element vertex 2\nproperty float x\nproperty float y\nproperty float z\n";
  expectError("plyx\nformat ascii 1.0\n", "does not start with \"ply\"");
  expectError("ply\nformat ascii 1.0\n" + vertex_header, "has no end_header line");
  expectError("ply\nformat binary_big_endian 1.0\n" + vertex_header + "end_header\n",
              "binary_big_endian");
  expectError("ply\nformat ascii 1.0\nelement vertex 2\nproperty flaot x\nend_header\n",
              "header line 4 has an unknown property type \"flaot\"");
  expectError("ply\nformat ascii 1.0\nproperty float x\nend_header\n",
              "property before any element");
  expectError("ply\nformat ascii 1.0\nelement vertex -2\nend_header\n", "without a valid count");
  expectError("ply\nformat ascii 1.0\nelement face 0\nend_header\n", "has no vertex element");
  expectError(
      "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n0 "
      "0\n",
      "has no scalar vertex property z");
  expectError("ply\n" + vertex_header + "end_header\n", "has no format line");
  expectError("ply\nformat ascii 1.0\n" + vertex_header + "end_header\n1 2 3\n4 5\n",
              "ends in the middle");
  expectError("ply\nformat ascii 1.0\n" + vertex_header + "end_header\n1 2 3\n4 five 6\n",
              "not a number");
  expectError("ply\nformat binary_little_endian 1.0\n" + vertex_header + "end_header\n" +
                  std::string(20, '\0'),
              "ends in the middle");
  expectError(
      "ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\n"
      "property float y\nproperty float z\nend_header\n",
      "declares 4000000000 vertices");
  std::remove(path.c_str());
  EXPECT_NE(readError("/nonexistent/map.ply").find("cannot open"), std::string::npos);
}

TEST(PlyMesh, WritesVerticesNormalsAndFaces) {
  const std::vector<Eigen::Vector3f> vertices{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const std::vector<Eigen::Vector3f> normals(4, Eigen::Vector3f(0, 0, 1));
  const std::vector<Eigen::Vector3i> triangles{{0, 1, 2}, {0, 2, 3}};
  const std::string path = temporaryPath("mesh.ply");
  writePlyMesh(path, vertices, normals, triangles);
  EXPECT_EQ(readPlyPoints(path), vertices);
  const std::string bytes = readBytes(path);
  const std::size_t body = bytes.find("end_header\n") + 11;
  ASSERT_EQ(bytes.size(), body + 4 * 24 + 2 * 13);
  EXPECT_NE(bytes.find("property float nx\n"), std::string::npos);
  EXPECT_NE(bytes.find("element face 2\nproperty list uchar int vertex_indices\n"),
            std::string::npos);
  int32_t last_index;
  std::memcpy(&last_index, bytes.data() + bytes.size() - 4, 4);
  EXPECT_EQ(bytes[body + 4 * 24 + 13], 3);
  EXPECT_EQ(last_index, 3);

  writePlyMesh(path, vertices, {}, triangles);  // normals are optional
  EXPECT_EQ(readBytes(path).find("nx"), std::string::npos);
  EXPECT_THROW(writePlyMesh(path, vertices, normals, {{0, 1, 4}}), std::invalid_argument);
  EXPECT_THROW(writePlyMesh(path, vertices, {Eigen::Vector3f::UnitZ()}, triangles),
               std::invalid_argument);
  std::remove(path.c_str());
}

}  // namespace
}  // namespace range_image_mapping::io
