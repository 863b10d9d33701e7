// The one triangle mesh type: appending (vertices, triangles, normals,
// intensities), bounds and area.
#include "range_image_mapping/triangle_mesh.h"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace range_image_mapping {
namespace {

// The unit square in z = 0, facing +z, with normals and intensities.
TriangleMesh unitSquare() {
  TriangleMesh square;
  square.vertices = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  square.triangles = {{0, 1, 2}, {0, 2, 3}};
  square.normals.assign(4, Eigen::Vector3f::UnitZ());
  square.intensities = {1, 2, 3, 4};
  return square;
}

TEST(TriangleMesh, AppendMovesVerticesAndNormalsAndKeepsIntensities) {
  TriangleMesh mesh = unitSquare();
  const Eigen::Isometry3f pose =
      Eigen::Translation3f(0, 0, 5) * Eigen::AngleAxisf(float(M_PI / 2), Eigen::Vector3f::UnitX());
  mesh.append(unitSquare(), pose);
  ASSERT_EQ(mesh.vertices.size(), 8u);
  ASSERT_EQ(mesh.normals.size(), 8u);
  ASSERT_EQ(mesh.intensities.size(), 8u);
  EXPECT_EQ(mesh.triangles[2], Eigen::Vector3i(4, 5, 6));
  EXPECT_TRUE(mesh.vertices[6].isApprox(Eigen::Vector3f(1, 0, 6), 1e-6f)) << mesh.vertices[6].transpose();
  EXPECT_TRUE(mesh.normals[7].isApprox(-Eigen::Vector3f::UnitY(), 1e-6f)) << mesh.normals[7].transpose();
  EXPECT_EQ(mesh.intensities[7], 4.0f);
  EXPECT_NEAR(mesh.area(), 2.0, 1e-6);
  EXPECT_TRUE(mesh.bounds().min().isZero(1e-6f)) << mesh.bounds().min().transpose();
  EXPECT_TRUE(mesh.bounds().max().isApprox(Eigen::Vector3f(1, 1, 6)));
}

TEST(TriangleMesh, PerVertexAttributesStayOnePerVertex) {
  TriangleMesh empty;
  empty.append(unitSquare());  // takes the normals and intensities along
  EXPECT_EQ(empty.normals.size(), 4u);
  EXPECT_EQ(empty.intensities.size(), 4u);
  TriangleMesh mesh = unitSquare();
  mesh.append(TriangleMesh{});  // nothing to add
  EXPECT_EQ(mesh.vertices.size(), 4u);

  TriangleMesh bare = unitSquare();
  bare.normals.clear();
  EXPECT_THROW(mesh.append(bare), std::invalid_argument);
  bare = unitSquare();
  bare.intensities.clear();
  EXPECT_THROW(mesh.append(bare), std::invalid_argument);
  EXPECT_EQ(mesh.vertices.size(), 4u);  // a refused append changes nothing
}

TEST(TriangleMesh, AnEmptyMeshHasNoAreaAndEmptyBounds) {
  const TriangleMesh empty;
  EXPECT_EQ(empty.area(), 0.0);
  EXPECT_TRUE(empty.bounds().isEmpty());
}

}  // namespace
}  // namespace range_image_mapping
