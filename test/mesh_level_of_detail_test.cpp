// Level of detail of the displayed mesh: vertex clustering keeps the surface
// within its bound of the full mesh, the budget holds, and pieces near the
// viewpoint stay finer than far ones. Surfaces are analytic (a rolling
// terrain at the outdoor voxel's spacing, a sphere), sampled densely to
// measure distances between the full and the coarse mesh.
#include "range_image_mapping/mapping/mesh_level_of_detail.h"

#include "range_image_mapping/evaluation/surface_metrics.h"
#include "range_image_mapping/surface_sampling.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>
#include <tuple>
#include <vector>

namespace range_image_mapping::mapping {
namespace {

constexpr double kVoxel = 0.1;

// z = 0.6 sin(0.35 x) cos(0.25 y) + 0.3 sin(1.3 x + 0.7 y) over [x0, x0 + size] x [y0, y0 + size],
// vertices every kVoxel, normals exact.
TriangleMesh terrain(double x0, double y0, double size_x, double size_y) {
  const int nx = int(std::lround(size_x / kVoxel)) + 1, ny = int(std::lround(size_y / kVoxel)) + 1;
  TriangleMesh mesh;
  for (int j = 0; j < ny; ++j)
    for (int i = 0; i < nx; ++i) {
      const double x = x0 + i * kVoxel, y = y0 + j * kVoxel;
      const double z = 0.6 * std::sin(0.35 * x) * std::cos(0.25 * y) + 0.3 * std::sin(1.3 * x + 0.7 * y);
      const double dz_dx = 0.6 * 0.35 * std::cos(0.35 * x) * std::cos(0.25 * y) + 0.3 * 1.3 * std::cos(1.3 * x + 0.7 * y);
      const double dz_dy = -0.6 * 0.25 * std::sin(0.35 * x) * std::sin(0.25 * y) + 0.3 * 0.7 * std::cos(1.3 * x + 0.7 * y);
      mesh.vertices.emplace_back(float(x), float(y), float(z));
      mesh.normals.push_back(Eigen::Vector3f(float(-dz_dx), float(-dz_dy), 1.0f).normalized());
      mesh.intensities.push_back(float(i % 50));
    }
  for (int j = 0; j + 1 < ny; ++j)
    for (int i = 0; i + 1 < nx; ++i) {
      const int a = j * nx + i, b = a + 1, c = a + nx, d = c + 1;
      mesh.triangles.emplace_back(a, b, d);
      mesh.triangles.emplace_back(a, d, c);
    }
  return mesh;
}

TriangleMesh sphere(double radius_m, int rings) {
  TriangleMesh mesh;
  const int segments = 2 * rings;
  for (int r = 0; r <= rings; ++r)
    for (int s = 0; s < segments; ++s) {
      const double theta = M_PI * r / rings, phi = 2.0 * M_PI * s / segments;
      const Eigen::Vector3f normal(float(std::sin(theta) * std::cos(phi)), float(std::sin(theta) * std::sin(phi)),
                                   float(std::cos(theta)));
      mesh.vertices.push_back(float(radius_m) * normal + Eigen::Vector3f(0.37f, -0.21f, 0.13f));
      mesh.normals.push_back(normal);
    }
  for (int r = 0; r < rings; ++r)
    for (int s = 0; s < segments; ++s) {
      const int a = r * segments + s, b = r * segments + (s + 1) % segments, c = a + segments,
                d = b + segments;
      if (r > 0) mesh.triangles.emplace_back(a, c, b);
      if (r + 1 < rings) mesh.triangles.emplace_back(b, c, d);
    }
  return mesh;
}

std::vector<Eigen::Vector3f> samples(const TriangleMesh& mesh, double spacing_m) {
  SurfaceSampleOptions options;
  options.spacing_m = spacing_m;
  return sampleSurface(mesh, options);
}

// Largest distance from a sample of `from` to the surface of `to`, measured on
// samples of `to` spacing_m apart (so up to spacing_m more than the truth).
double largestDistance(const TriangleMesh& from, const TriangleMesh& to, double spacing_m) {
  const std::vector<float> distances = evaluation::nearestDistances(samples(from, spacing_m), samples(to, spacing_m));
  return *std::max_element(distances.begin(), distances.end());
}

TEST(ClusterVertices, StaysWithinTheCellDiagonalOfTheFullSurface) {
  const TriangleMesh full = terrain(-3.0, -2.0, 8.0, 6.0);
  constexpr double kSpacing = 0.01;
  for (const double cell : {0.2, 0.4, 0.8}) {
    const TriangleMesh coarse = clusterVertices(full, cell);
    ASSERT_FALSE(coarse.triangles.empty()) << cell;
    ASSERT_EQ(coarse.normals.size(), coarse.vertices.size());
    ASSERT_EQ(coarse.intensities.size(), coarse.vertices.size());
    // Proven bound, one way: coarse -> full.
    const double coarse_to_full = largestDistance(coarse, full, kSpacing);
    EXPECT_LE(coarse_to_full, std::sqrt(3.0) * cell + kSpacing) << "cell " << cell;
    // And no holes: the full surface is near the coarse one too (away from
    // the border, which clustering pulls inwards by up to a cell).
    const TriangleMesh inner = terrain(-3.0 + cell * 2, -2.0 + cell * 2, 8.0 - 4 * cell, 6.0 - 4 * cell);
    EXPECT_LE(largestDistance(inner, coarse, kSpacing), std::sqrt(3.0) * cell + kSpacing) << "cell " << cell;
    // Cells twice the vertex spacing keep about a quarter of the triangles.
    const double kept = double(coarse.triangles.size()) / double(full.triangles.size());
    const double expected = std::pow(kVoxel / cell, 2.0);
    EXPECT_LT(kept, 1.6 * expected) << "cell " << cell;
    EXPECT_GT(kept, 0.4 * expected) << "cell " << cell;
    for (const Eigen::Vector3f& normal : coarse.normals) EXPECT_NEAR(normal.norm(), 1.0f, 1e-4f);
  }
}

TEST(ClusterVertices, KeepsAClosedSurfaceClosed) {
  const TriangleMesh full = sphere(2.0, 120);  // edges about 5 cm
  const double cell = 0.4;
  const TriangleMesh coarse = clusterVertices(full, cell);
  EXPECT_LT(coarse.triangles.size(), full.triangles.size() / 10);
  EXPECT_LE(largestDistance(coarse, full, 0.01), std::sqrt(3.0) * cell + 0.01);
  EXPECT_LE(largestDistance(full, coarse, 0.01), std::sqrt(3.0) * cell + 0.01);
  // Area is kept within a few percent: no holes, no folds.
  EXPECT_NEAR(coarse.area() / full.area(), 1.0, 0.05);
}

TEST(ClusterVertices, CellZeroIsTheMeshAndBadInputIsNamed) {
  const TriangleMesh full = terrain(0.0, 0.0, 1.0, 1.0);
  const TriangleMesh same = clusterVertices(full, 0.0);
  EXPECT_EQ(same.triangles, full.triangles);
  EXPECT_THROW(clusterVertices(full, -0.1), std::invalid_argument);
  EXPECT_THROW(clusterVertices(full, std::nan("")), std::invalid_argument);
  TriangleMesh broken = full;
  broken.triangles.emplace_back(0, 1, int(full.vertices.size()));
  try {
    clusterVertices(broken, 0.2);
    ADD_FAILURE() << "an index out of range was accepted";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("out of range"), std::string::npos) << error.what();
  }
}

// A 48 m x 48 m terrain in pieces of 3.2 m (the Mapper's marker chunks of
// 4 blocks of 8 voxels), the viewpoint over one corner.
struct PiecedTerrain {
  std::map<std::tuple<int, int>, TriangleMesh> pieces;
  std::size_t triangles = 0;
};

PiecedTerrain piecedTerrain() {
  constexpr double kPiece = 3.2;
  PiecedTerrain result;
  for (int j = 0; j < 15; ++j)
    for (int i = 0; i < 15; ++i) {
      TriangleMesh piece = terrain(i * kPiece, j * kPiece, kPiece, kPiece);
      result.triangles += piece.triangles.size();
      result.pieces[{i, j}] = std::move(piece);
    }
  return result;
}

MeshLevelOfDetail::Key keyOf(const std::tuple<int, int>& ij) { return {std::get<0>(ij), std::get<1>(ij), 0}; }

// Every piece of the terrain in a level of detail at the test's voxel size,
// with the box it was cut from.
MeshLevelOfDetail levelOfDetail(const PiecedTerrain& terrain, LevelOfDetailOptions options) {
  options.voxel_size_m = kVoxel;
  MeshLevelOfDetail lod(options);
  for (const auto& [ij, mesh] : terrain.pieces) {
    const auto [i, j] = ij;
    const Eigen::AlignedBox3f region(Eigen::Vector3f(float(i * 3.2), float(j * 3.2), -100.0f),
                                     Eigen::Vector3f(float((i + 1) * 3.2), float((j + 1) * 3.2), 100.0f));
    lod.setPiece(keyOf(ij), mesh, region);
  }
  return lod;
}

// The shown vertices of a piece on the plane x = x_m, as (y, z), sorted.
std::vector<std::pair<float, float>> verticesAtX(const TriangleMesh& mesh, float x_m) {
  std::vector<std::pair<float, float>> result;
  for (const Eigen::Vector3f& vertex : mesh.vertices)
    if (std::abs(vertex.x() - x_m) <= 1e-5f) result.emplace_back(vertex.y(), vertex.z());
  std::sort(result.begin(), result.end());
  return result;
}

TEST(MeshLevelOfDetail, KeepsTheBudgetAndNearPiecesFiner) {
  const PiecedTerrain full = piecedTerrain();
  LevelOfDetailOptions options;
  options.full_detail_distance_m = 8.0;
  options.triangle_budget = full.triangles / 8;
  MeshLevelOfDetail lod = levelOfDetail(full, options);
  EXPECT_EQ(lod.fullTriangles(), full.triangles);
  const Eigen::Vector3f viewpoint(1.0f, 1.0f, 2.0f);
  const std::vector<MeshLevelOfDetail::Key> changed = lod.update(viewpoint);
  EXPECT_EQ(changed.size(), full.pieces.size());  // everything is new

  std::size_t shown = 0;
  int nearest_level = -1, farthest_level = -1;
  float nearest = 1e9f, farthest = -1.0f;
  std::vector<std::pair<float, int>> level_by_distance;
  for (const auto& [ij, mesh] : full.pieces) {
    const TriangleMesh* coarse = lod.shown(keyOf(ij));
    ASSERT_NE(coarse, nullptr);
    const int level = lod.levelOf(keyOf(ij));
    shown += coarse->triangles.size();
    const float distance = mesh.bounds().exteriorDistance(viewpoint);
    level_by_distance.emplace_back(distance, level);
    if (distance < nearest) nearest = distance, nearest_level = level;
    if (distance > farthest) farthest = distance, farthest_level = level;
  }
  EXPECT_EQ(shown, lod.shownTriangles());
  EXPECT_LE(shown, options.triangle_budget);
  EXPECT_GT(shown, options.triangle_budget / 4) << "coarsened far more than the budget asks";
  EXPECT_LT(nearest_level, farthest_level);
  std::sort(level_by_distance.begin(), level_by_distance.end());
  for (std::size_t i = 1; i < level_by_distance.size(); ++i)
    EXPECT_LE(level_by_distance[i - 1].second, level_by_distance[i].second)
        << "a nearer piece is coarser than a farther one";

  // Each piece within its level's bound of its full mesh.
  for (const auto& [ij, mesh] : full.pieces) {
    if (std::get<0>(ij) % 7 != 0 || std::get<1>(ij) % 7 != 0) continue;  // a few, to keep it quick
    const int level = lod.levelOf(keyOf(ij));
    const double bound = level == 0 ? 0.0 : std::sqrt(3.0) * kVoxel * std::ldexp(1.0, level);
    EXPECT_LE(largestDistance(*lod.shown(keyOf(ij)), mesh, 0.02), bound + 0.02) << "level " << level;
  }

  // The same viewpoint again: nothing to re-send. Far away: levels change.
  EXPECT_TRUE(lod.update(viewpoint).empty());
  EXPECT_FALSE(lod.update(Eigen::Vector3f(47.0f, 47.0f, 2.0f)).empty());
  EXPECT_LE(lod.shownTriangles(), options.triangle_budget);
}

TEST(MeshLevelOfDetail, PiecesAtDifferentLevelsMeetWithoutCracks) {
  const PiecedTerrain full = piecedTerrain();
  LevelOfDetailOptions options;
  options.full_detail_distance_m = 1.0;
  MeshLevelOfDetail lod = levelOfDetail(full, options);
  lod.update(Eigen::Vector3f(0.5f, 1.6f, 1.0f));
  // Levels 0, 2 and 3 side by side along x.
  ASSERT_EQ(lod.levelOf(keyOf({0, 0})), 0);
  ASSERT_GE(lod.levelOf(keyOf({1, 0})), 1);
  ASSERT_GT(lod.levelOf(keyOf({2, 0})), lod.levelOf(keyOf({1, 0})));
  for (int i = 0; i < 2; ++i) {
    const float border = float((i + 1) * 3.2);
    const auto left = verticesAtX(*lod.shown(keyOf({i, 0})), border);
    const auto right = verticesAtX(*lod.shown(keyOf({i + 1, 0})), border);
    EXPECT_GE(left.size(), 30u) << "the border at x = " << border << " lost its vertices";
    EXPECT_EQ(left, right) << "pieces " << i << " and " << i + 1 << " do not share their border";
  }
  // And the coarse pieces stay within their bound of the full surface.
  const int level = lod.levelOf(keyOf({2, 0}));
  EXPECT_LE(largestDistance(*lod.shown(keyOf({2, 0})), full.pieces.at({2, 0}), 0.02),
            std::sqrt(3.0) * kVoxel * std::ldexp(1.0, level) + 0.02);
  EXPECT_LT(lod.shown(keyOf({2, 0}))->triangles.size(), full.pieces.at({2, 0}).triangles.size() / 4);
}

TEST(MeshLevelOfDetail, WithoutBudgetNearPiecesAreFull) {
  const PiecedTerrain full = piecedTerrain();
  LevelOfDetailOptions options;
  options.full_detail_distance_m = 8.0;
  MeshLevelOfDetail lod = levelOfDetail(full, options);
  lod.update(Eigen::Vector3f(1.0f, 1.0f, 2.0f));
  EXPECT_EQ(lod.shown(keyOf({0, 0}))->triangles, full.pieces.at({0, 0}).triangles);
  EXPECT_GT(lod.levelOf(keyOf({14, 14})), 0);
  EXPECT_LT(lod.shownTriangles(), full.triangles);
}

TEST(MeshLevelOfDetail, LeavesOutTheFarthestWhenEvenTheCoarsestIsTooMuch) {
  const PiecedTerrain full = piecedTerrain();
  LevelOfDetailOptions options;
  options.max_level = 2;
  options.triangle_budget = 2000;
  MeshLevelOfDetail lod = levelOfDetail(full, options);
  lod.update(Eigen::Vector3f::Zero());
  EXPECT_LE(lod.shownTriangles(), options.triangle_budget);
  EXPECT_NE(lod.shown(keyOf({0, 0})), nullptr);
  EXPECT_EQ(lod.shown(keyOf({14, 14})), nullptr);
  // A removed piece is reported once, then gone.
  lod.removePiece(keyOf({0, 0}));
  const std::vector<MeshLevelOfDetail::Key> changed = lod.update(Eigen::Vector3f::Zero());
  EXPECT_NE(std::find(changed.begin(), changed.end(), keyOf({0, 0})), changed.end());
  EXPECT_EQ(lod.shown(keyOf({0, 0})), nullptr);
}

TEST(LevelOfDetailOptions, BadValuesAreNamed) {
  LevelOfDetailOptions options;
  options.voxel_size_m = 0.0;
  EXPECT_THROW(MeshLevelOfDetail{options}, std::invalid_argument);
  options = {};
  options.full_detail_distance_m = -1.0;
  EXPECT_THROW(options.validate(), std::invalid_argument);
  options = {};
  EXPECT_EQ(levelForDistance(5.0, options), 0);
  EXPECT_EQ(levelForDistance(15.0, options), 1);
  EXPECT_EQ(levelForDistance(35.0, options), 2);
  EXPECT_EQ(levelForDistance(1e9, options), options.max_level);
}

}  // namespace
}  // namespace range_image_mapping::mapping
