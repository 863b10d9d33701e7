// Marching cubes over the voxel block grid, checked against analytic signed
// distance fields written straight into the grid (no integrator): spheres,
// a box with sharp corners and random fields that exercise every corner
// pattern and both choices on ambiguous faces.
#include "range_image_mapping/mapping/marching_cubes.h"

#include "range_image_mapping/io/mesh_file.h"
#include "range_image_mapping/io/ply.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <limits>
#include <set>
#include <string>
#include <vector>

namespace range_image_mapping::mapping {
namespace {

using DistanceFunction = std::function<double(const Eigen::Vector3d&)>;

struct FillOptions {
  double truncation_voxels = 3.0;
  // Voxels where this is false get weight 0.5 (below a min_weight of 1).
  std::function<bool(const Eigen::Vector3d&)> observed;
  DistanceFunction intensity;
};

// Activates every block that may hold a cube near the surface (within 3
// voxels of it, anywhere in the block) and writes the truncated exact
// distance with weight 1: an ideal TSDF.
void fillGrid(VoxelBlockGrid& grid, const DistanceFunction& distance,
              const Eigen::AlignedBox3d& region, const FillOptions& fill = {}) {
  const double voxel = grid.voxelSize(), truncation = fill.truncation_voxels * voxel;
  const int edge = grid.blockEdge();
  const BlockKey first = grid.blockKeyOf(region.min()), last = grid.blockKeyOf(region.max());
  const uint64_t generation = grid.nextGeneration();
  for (int bz = first.z(); bz <= last.z(); ++bz)
    for (int by = first.y(); by <= last.y(); ++by)
      for (int bx = first.x(); bx <= last.x(); ++bx) {
        const BlockKey key(bx, by, bz);
        const Eigen::Vector3d centre =
            grid.voxelPosition(key, 0, 0, 0) + Eigen::Vector3d::Constant(0.5 * grid.blockSize());
        if (std::abs(distance(centre)) > 0.87 * grid.blockSize() + 3.0 * voxel) continue;
        VoxelBlock* block = grid.activate(key);
        ASSERT_NE(block, nullptr);
        for (int k = 0; k < edge; ++k)
          for (int j = 0; j < edge; ++j)
            for (int i = 0; i < edge; ++i) {
              const Eigen::Vector3d position = grid.voxelPosition(key, i, j, k);
              const int index = i + edge * (j + edge * k);
              block->sdf[index] = float(std::clamp(distance(position), -truncation, truncation));
              block->weight[index] = !fill.observed || fill.observed(position) ? 1.0f : 0.5f;
              if (fill.intensity) block->intensity[index] = float(fill.intensity(position));
            }
        block->changed_generation = generation;
      }
}

DistanceFunction sphereDistance(const Eigen::Vector3d& centre, double radius) {
  return [=](const Eigen::Vector3d& p) { return (p - centre).norm() - radius; };
}

// Exact Euclidean distance to an axis-aligned box (negative inside).
DistanceFunction boxDistance(const Eigen::Vector3d& minimum, const Eigen::Vector3d& maximum) {
  return [=](const Eigen::Vector3d& p) {
    const Eigen::Vector3d centre = 0.5 * (minimum + maximum), half = 0.5 * (maximum - minimum);
    const Eigen::Vector3d q = (p - centre).cwiseAbs() - half;
    return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
  };
}

Eigen::AlignedBox3d aroundSphere(const Eigen::Vector3d& centre, double radius, double margin) {
  return {centre - Eigen::Vector3d::Constant(radius + margin),
          centre + Eigen::Vector3d::Constant(radius + margin)};
}

VoxelBlockGrid sphereGrid(double voxel, int block_edge, const Eigen::Vector3d& centre, double radius,
                          const FillOptions& fill = {}) {
  VoxelBlockGrid grid({voxel, block_edge, bool(fill.intensity)});
  fillGrid(grid, sphereDistance(centre, radius), aroundSphere(centre, radius, 4 * voxel * block_edge),
           fill);
  return grid;
}

// ---------------------------------------------------------------- mesh checks

using Position = std::array<float, 3>;
using TrianglePositions = std::array<Position, 3>;

Position positionOf(const Eigen::Vector3f& v) { return {v.x(), v.y(), v.z()}; }

// Triangles as vertex positions, rotated so the smallest comes first (the
// winding is kept): equal sets mean the same surface whatever the indexing.
std::multiset<TrianglePositions> triangleSet(const TriangleMesh& mesh) {
  std::multiset<TrianglePositions> set;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    TrianglePositions corners{positionOf(mesh.vertices[t[0]]), positionOf(mesh.vertices[t[1]]),
                              positionOf(mesh.vertices[t[2]])};
    std::rotate(corners.begin(), std::min_element(corners.begin(), corners.end()), corners.end());
    set.insert(corners);
  }
  return set;
}

std::vector<Position> sortedVertices(const TriangleMesh& mesh) {
  std::vector<Position> sorted;
  for (const Eigen::Vector3f& v : mesh.vertices) sorted.push_back(positionOf(v));
  std::sort(sorted.begin(), sorted.end());
  return sorted;
}

std::map<std::pair<int, int>, int> directedEdgeUses(const std::vector<Eigen::Vector3i>& triangles) {
  std::map<std::pair<int, int>, int> uses;
  for (const Eigen::Vector3i& t : triangles)
    for (int corner = 0; corner < 3; ++corner) ++uses[{t[corner], t[(corner + 1) % 3]}];
  return uses;
}

// A closed, consistently oriented 2-manifold: every edge is walked exactly
// once in each direction by the two triangles that share it.
void expectClosedAndOriented(const TriangleMesh& mesh) {
  const auto uses = directedEdgeUses(mesh.triangles);
  std::size_t bad = 0;
  for (const auto& [edge, count] : uses) {
    const auto reverse = uses.find({edge.second, edge.first});
    bad += count != 1 || reverse == uses.end() || reverse->second != 1;
  }
  EXPECT_EQ(bad, 0u) << "directed edges not matched by exactly one reversed edge";
  EXPECT_EQ(countBoundaryEdges(mesh.triangles), 0u);
  for (const Eigen::Vector3i& t : mesh.triangles)
    ASSERT_TRUE(t[0] != t[1] && t[1] != t[2] && t[0] != t[2]) << "triangle with a repeated vertex";
}

long eulerCharacteristic(const TriangleMesh& mesh) {
  std::set<std::pair<int, int>> edges;
  std::set<int> used;
  for (const Eigen::Vector3i& t : mesh.triangles)
    for (int corner = 0; corner < 3; ++corner) {
      edges.insert(std::minmax(t[corner], t[(corner + 1) % 3]));
      used.insert(t[corner]);
    }
  return long(used.size()) - long(edges.size()) + long(mesh.triangles.size());
}

double area(const TriangleMesh& mesh) {
  double sum = 0.0;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>(), b = mesh.vertices[t[1]].cast<double>(),
                          c = mesh.vertices[t[2]].cast<double>();
    sum += 0.5 * (b - a).cross(c - a).norm();
  }
  return sum;
}

std::string temporaryPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("rim_marching_cubes_test_" + name)).string();
}

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// ---------------------------------------------------------------- sphere

struct SphereCase {
  double voxel;
  Eigen::Vector3d centre;
};

TEST(MarchingCubes, SphereVerticesOnSurfaceNormalsOutwardClosedGenusZero) {
  const double radius = 1.0;
  const std::vector<SphereCase> cases{{0.04, {0.013, -0.271, 0.3137}},
                                      {0.07, {-1.017, 2.433, 0.5}},
                                      {0.1, {3.31, -0.77, -2.05}},
                                      {0.2, {0.05, 0.11, -0.09}}};
  for (const SphereCase& sphere : cases) {
    SCOPED_TRACE("voxel " + std::to_string(sphere.voxel));
    const VoxelBlockGrid grid = sphereGrid(sphere.voxel, 8, sphere.centre, radius);
    ASSERT_GT(grid.blockCount(), 8u);  // spans many blocks
    const TriangleMesh mesh = extractMesh(grid);
    ASSERT_GT(mesh.triangles.size(), 100u);
    ASSERT_EQ(mesh.normals.size(), mesh.vertices.size());
    EXPECT_TRUE(mesh.intensities.empty());

    double worst_error = 0.0, error_sum = 0.0, worst_normal = 1.0;
    for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
      const Eigen::Vector3d offset = mesh.vertices[v].cast<double>() - sphere.centre;
      const double error = std::abs(offset.norm() - radius);
      worst_error = std::max(worst_error, error);
      error_sum += error;
      EXPECT_NEAR(mesh.normals[v].norm(), 1.0, 1e-5);
      worst_normal = std::min(worst_normal, double(mesh.normals[v].cast<double>().dot(offset.normalized())));
    }
    const double mean_error = error_sum / double(mesh.vertices.size());
    std::printf("sphere R %.1f voxel %.2f: %zu blocks, %zu vertices, %zu triangles, vertex error "
                "max %.5f mean %.6f m, worst normal dot %.5f\n",
                radius, sphere.voxel, grid.blockCount(), mesh.vertices.size(), mesh.triangles.size(),
                worst_error, mean_error, worst_normal);
    EXPECT_LT(worst_error, sphere.voxel / 4);  // the requirement
    EXPECT_LT(mean_error, sphere.voxel / 40);
    EXPECT_GT(worst_normal, 0.9);

    // Winding: counter-clockwise seen from outside (free space).
    std::size_t inward = 0;
    for (const Eigen::Vector3i& t : mesh.triangles) {
      const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>(), b = mesh.vertices[t[1]].cast<double>(),
                            c = mesh.vertices[t[2]].cast<double>();
      const Eigen::Vector3d normal = (b - a).cross(c - a);
      if (normal.norm() < 1e-12) continue;  // a sliver has no reliable direction
      inward += normal.dot((a + b + c) / 3.0 - sphere.centre) <= 0.0;
    }
    EXPECT_EQ(inward, 0u);
    expectClosedAndOriented(mesh);
    EXPECT_EQ(eulerCharacteristic(mesh), 2);
  }
}

TEST(MarchingCubes, BoxWithSharpCornersIsClosedWithTheRightArea) {
  const Eigen::Vector3d minimum(-0.613, -0.431, -0.377), maximum(0.722, 0.493, 0.331);
  const Eigen::Vector3d size = maximum - minimum;
  const double true_area = 2.0 * (size.x() * size.y() + size.y() * size.z() + size.z() * size.x());
  const double edge_length = 4.0 * size.sum();
  for (const double voxel : {0.05, 0.025}) {
    SCOPED_TRACE("voxel " + std::to_string(voxel));
    VoxelBlockGrid grid({voxel, 8, false});
    fillGrid(grid, boxDistance(minimum, maximum),
             Eigen::AlignedBox3d(minimum - Eigen::Vector3d::Constant(1.0),
                                 maximum + Eigen::Vector3d::Constant(1.0)));
    const TriangleMesh mesh = extractMesh(grid);
    const double mesh_area = area(mesh);
    // Linear interpolation bevels the sharp edges: inside, near an edge, the
    // distance to the other face is the smaller one. The loss is a strip
    // narrower than a voxel along each edge, so it halves with the voxel.
    const double strip_width = (true_area - mesh_area) / edge_length;
    std::printf("box voxel %.3f: %zu blocks, %zu triangles, area %.4f m^2 (true %.4f, %+.2f %%), "
                "lost strip %.3f voxels wide along the edges\n",
                voxel, grid.blockCount(), mesh.triangles.size(), mesh_area, true_area,
                100.0 * (mesh_area / true_area - 1.0), strip_width / voxel);
    EXPECT_NEAR(mesh_area / true_area, 1.0, 0.05);
    EXPECT_GT(strip_width, 0.0);
    EXPECT_LT(strip_width, 0.5 * voxel);
    double worst = 0.0;
    for (const Eigen::Vector3f& v : mesh.vertices)
      worst = std::max(worst, std::abs(boxDistance(minimum, maximum)(v.cast<double>())));
    EXPECT_LT(worst, voxel / 2);
    expectClosedAndOriented(mesh);
    EXPECT_EQ(eulerCharacteristic(mesh), 2);
  }
}

// ---------------------------------------------------------------- ambiguity and cracks

// Random values on a lattice cube, positive outside it: surfaces of any
// topology, with every corner pattern and both outcomes on ambiguous faces.
void fillRandomField(VoxelBlockGrid& grid, int size, uint32_t seed) {
  const int edge = grid.blockEdge();
  const uint64_t generation = grid.nextGeneration();
  const int first_block = -1, last_block = (size + 1) / edge + 1;
  for (int bz = first_block; bz <= last_block; ++bz)
    for (int by = first_block; by <= last_block; ++by)
      for (int bx = first_block; bx <= last_block; ++bx) {
        VoxelBlock* block = grid.activate(BlockKey(bx, by, bz));
        for (int k = 0; k < edge; ++k)
          for (int j = 0; j < edge; ++j)
            for (int i = 0; i < edge; ++i) {
              const Eigen::Vector3i lattice = BlockKey(bx, by, bz) * edge + Eigen::Vector3i(i, j, k);
              const bool inside = (lattice.array() > 0).all() && (lattice.array() < size).all();
              // A hash of the lattice point, so any block edge sees the same field.
              uint32_t hash = seed ^ uint32_t(lattice.x() * 73856093) ^ uint32_t(lattice.y() * 19349669) ^
                              uint32_t(lattice.z() * 83492791);
              hash ^= hash >> 16;
              hash *= 0x7feb352du;
              hash ^= hash >> 15;
              hash *= 0x846ca68bu;
              hash ^= hash >> 16;
              const float random = float(hash % 2001u) / 1000.0f - 1.0f;  // [-1, 1]
              const int index = i + edge * (j + edge * k);
              block->sdf[index] = inside ? float(grid.voxelSize()) * random : float(grid.voxelSize());
              block->weight[index] = 1.0f;
            }
        block->changed_generation = generation;
      }
}

TEST(MarchingCubes, RandomFieldsGiveClosedOrientedSurfacesIndependentOfBlockSize) {
  for (uint32_t seed : {1u, 2u, 3u}) {
    VoxelBlockGrid small_blocks({0.1, 8, false}), large_blocks({0.1, 16, false});
    fillRandomField(small_blocks, 22, seed);
    fillRandomField(large_blocks, 22, seed);
    const TriangleMesh mesh = extractMesh(small_blocks);
    ASSERT_GT(mesh.triangles.size(), 10000u);
    expectClosedAndOriented(mesh);
    const TriangleMesh other = extractMesh(large_blocks);
    EXPECT_EQ(sortedVertices(mesh), sortedVertices(other));
    EXPECT_TRUE(triangleSet(mesh) == triangleSet(other));

    // Tunnels (loops fanned around a vertex inside the cube) did occur.
    MeshExtractor extractor;
    extractor.update(small_blocks);
    std::size_t interior_vertices = 0;
    for (const MeshChunk* chunk : extractor.chunks())
      for (const LatticeEdge& name : chunk->vertex_edges) interior_vertices += name.index >= 3 * 8 * 8 * 8;
    EXPECT_GT(interior_vertices, 0u);
  }
}

TEST(MarchingCubes, SphereMeshDoesNotDependOnBlockBorders) {
  const Eigen::Vector3d centre(0.217, -0.093, 0.4411);
  const TriangleMesh small_blocks = extractMesh(sphereGrid(0.05, 8, centre, 0.9));
  const TriangleMesh large_blocks = extractMesh(sphereGrid(0.05, 16, centre, 0.9));
  ASSERT_GT(small_blocks.vertices.size(), 1000u);
  EXPECT_EQ(sortedVertices(small_blocks), sortedVertices(large_blocks));
  EXPECT_TRUE(triangleSet(small_blocks) == triangleSet(large_blocks));
  EXPECT_EQ(countBoundaryEdges(large_blocks.triangles), 0u);
}

// ---------------------------------------------------------------- unobserved voxels

TEST(MarchingCubes, MeshEndsWhereObservationsEnd) {
  const Eigen::Vector3d centre(0.11, 0.07, -0.13);
  const double voxel = 0.05, radius = 1.0, limit_z = centre.z() + 0.3;
  FillOptions fill;
  fill.observed = [&](const Eigen::Vector3d& p) { return p.z() <= limit_z; };
  const VoxelBlockGrid half = sphereGrid(voxel, 8, centre, radius, fill);
  const TriangleMesh full = extractMesh(sphereGrid(voxel, 8, centre, radius));
  // Voxels beyond the limit have weight 0.5: unobserved for min_weight 1.
  MeshOptions strict;
  strict.min_weight = 1.0f;
  const TriangleMesh mesh = extractMesh(half, strict);
  const double last_plane = std::floor(limit_z / voxel) * voxel;  // highest observed lattice plane

  std::size_t above = 0;
  for (const Eigen::Vector3f& v : mesh.vertices) above += v.z() > last_plane + 1e-5;
  EXPECT_EQ(above, 0u) << "vertices in unobserved space";

  // The boundary is the iso-line on the last observed plane, nowhere else.
  const auto uses = directedEdgeUses(mesh.triangles);
  std::size_t boundary = 0, off_plane = 0;
  for (const auto& [edge, count] : uses) {
    if (uses.count({edge.second, edge.first})) continue;
    ++boundary;
    for (int end : {edge.first, edge.second})
      off_plane += std::abs(mesh.vertices[end].z() - last_plane) > 1e-5;
  }
  EXPECT_EQ(boundary, countBoundaryEdges(mesh.triangles));
  EXPECT_GT(boundary, std::size_t(2 * M_PI * 0.9 / voxel));  // roughly the circle's length in voxels
  EXPECT_EQ(off_plane, 0u);

  // Below the limit, the triangles are exactly those of the fully observed sphere.
  const auto half_set = triangleSet(mesh), full_set = triangleSet(full);
  EXPECT_TRUE(std::includes(full_set.begin(), full_set.end(), half_set.begin(), half_set.end()));
  std::size_t missing = 0;
  for (const TrianglePositions& t : full_set)
    if (std::min({t[0][2], t[1][2], t[2][2]}) < last_plane - 1e-5) missing += !half_set.count(t);
  EXPECT_EQ(missing, 0u);

  // A lower min_weight counts the weight 0.5 voxels as observed, and so does
  // the default (every observed voxel, whatever its weight).
  MeshOptions lenient;
  lenient.min_weight = 0.25f;
  EXPECT_TRUE(triangleSet(extractMesh(half, lenient)) == full_set);
  EXPECT_TRUE(triangleSet(extractMesh(half)) == full_set);
}

TEST(MarchingCubes, IntensityIsInterpolatedAlongTheEdge) {
  FillOptions fill;
  fill.intensity = [](const Eigen::Vector3d& p) { return 10.0 + 2.0 * p.x() - p.y() + 0.5 * p.z(); };
  const VoxelBlockGrid grid = sphereGrid(0.1, 8, {0.03, 0.02, 0.01}, 0.8, fill);
  const TriangleMesh mesh = extractMesh(grid);
  ASSERT_EQ(mesh.intensities.size(), mesh.vertices.size());
  ASSERT_FALSE(mesh.vertices.empty());
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v)
    EXPECT_NEAR(mesh.intensities[v], fill.intensity(mesh.vertices[v].cast<double>()), 1e-4);
}

// ---------------------------------------------------------------- incremental

std::vector<BlockKey> sortedKeys(std::vector<BlockKey> keys) {
  std::sort(keys.begin(), keys.end(), [](const BlockKey& a, const BlockKey& b) {
    return std::array<int, 3>{a.x(), a.y(), a.z()} < std::array<int, 3>{b.x(), b.y(), b.z()};
  });
  return keys;
}

void expectSameMesh(const TriangleMesh& a, const TriangleMesh& b) {
  EXPECT_EQ(a.vertices.size(), b.vertices.size());
  EXPECT_EQ(sortedVertices(a), sortedVertices(b));
  EXPECT_TRUE(triangleSet(a) == triangleSet(b));
}

TEST(MeshExtractor, RebuildsChangedBlocksAndTheirLowerNeighboursOnly) {
  const Eigen::Vector3d centre(0.123, -0.456, 0.0789);
  const double voxel = 0.05, radius = 1.0;
  VoxelBlockGrid grid = sphereGrid(voxel, 8, centre, radius);
  MeshExtractor extractor;

  MeshUpdate first = extractor.update(grid);
  std::vector<BlockKey> all_keys;
  for (const VoxelBlock* block : grid.blocks()) all_keys.push_back(block->key);
  EXPECT_EQ(first.changed, sortedKeys(all_keys));  // every block is new
  EXPECT_TRUE(first.removed.empty());
  expectSameMesh(extractor.combined(), extractMesh(grid));
  EXPECT_EQ(extractor.triangleCount(), extractMesh(grid).triangles.size());
  EXPECT_EQ(countBoundaryEdges(extractor.combined().triangles), 0u);

  const MeshUpdate idle = extractor.update(grid);
  EXPECT_TRUE(idle.changed.empty());
  EXPECT_TRUE(idle.removed.empty());

  // Grow the sphere inside three surface blocks (the field jumps at their
  // borders, which is fine: the mesh only has to match a full extraction).
  std::vector<const MeshChunk*> chunks = extractor.chunks();
  ASSERT_GT(chunks.size(), 30u);
  const std::vector<BlockKey> modified{chunks[5]->key, chunks[chunks.size() / 2]->key,
                                       chunks[chunks.size() - 7]->key};
  std::map<std::array<int, 3>, std::vector<Eigen::Vector3f>> vertices_before;
  for (const MeshChunk* chunk : chunks)
    vertices_before[{chunk->key.x(), chunk->key.y(), chunk->key.z()}] = chunk->vertices;
  const uint64_t generation = grid.nextGeneration();
  std::set<std::array<int, 3>> expected_changed;
  const auto grown = sphereDistance(centre, radius + 0.4 * voxel);
  for (const BlockKey& key : modified) {
    VoxelBlock* block = grid.find(key);
    for (int k = 0; k < 8; ++k)
      for (int j = 0; j < 8; ++j)
        for (int i = 0; i < 8; ++i)
          block->sdf[i + 8 * (j + 8 * k)] =
              float(std::clamp(grown(grid.voxelPosition(key, i, j, k)), -3 * voxel, 3 * voxel));
    block->changed_generation = generation;
    // The block and all its lower neighbours: no fingerprint of what they
    // read is known yet (every block was meshed at once).
    for (int n = 0; n < 8; ++n) {
      const BlockKey lower = key - Eigen::Vector3i(n & 1, (n >> 1) & 1, n >> 2);
      if (grid.find(lower)) expected_changed.insert({lower.x(), lower.y(), lower.z()});
    }
  }
  const MeshUpdate update = extractor.update(grid);
  std::vector<BlockKey> expected;
  for (const auto& key : expected_changed) expected.emplace_back(key[0], key[1], key[2]);
  EXPECT_EQ(update.changed, sortedKeys(expected));
  EXPECT_TRUE(update.removed.empty());
  expectSameMesh(extractor.combined(), extractMesh(grid));

  // The test can fail: some lower neighbour (not itself modified) really changed.
  std::size_t neighbours_changed = 0;
  for (const BlockKey& key : update.changed) {
    if (std::find(modified.begin(), modified.end(), key) != modified.end()) continue;
    const MeshChunk* chunk = extractor.chunk(key);
    const auto before = vertices_before.find({key.x(), key.y(), key.z()});
    const bool had = before != vertices_before.end();
    neighbours_changed += (chunk != nullptr) != had || (chunk && chunk->vertices != before->second);
  }
  EXPECT_GT(neighbours_changed, 0u);

  // Removed blocks take their chunks with them; their lower neighbours are re-meshed.
  std::set<std::array<int, 3>> had_chunk;
  for (const MeshChunk* chunk : extractor.chunks()) had_chunk.insert({chunk->key.x(), chunk->key.y(), chunk->key.z()});
  std::vector<BlockKey> removed_blocks;
  grid.removeBlocksFartherThan(centre + Eigen::Vector3d(0.7, 0.0, 0.0), 1.0, &removed_blocks);
  ASSERT_GT(removed_blocks.size(), 10u);
  std::vector<BlockKey> expected_removed;
  for (const BlockKey& key : removed_blocks)
    if (had_chunk.count({key.x(), key.y(), key.z()})) expected_removed.push_back(key);
  ASSERT_FALSE(expected_removed.empty());
  const MeshUpdate removal = extractor.update(grid);
  EXPECT_EQ(removal.removed, sortedKeys(expected_removed));
  for (const BlockKey& key : removed_blocks) EXPECT_EQ(extractor.chunk(key), nullptr);
  const TriangleMesh after_removal = extractor.combined();
  expectSameMesh(after_removal, extractMesh(grid));
  EXPECT_GT(countBoundaryEdges(after_removal.triangles), 0u);  // the cut is open

  // A new grid with a lower generation (a reset map) is re-meshed whole.
  const VoxelBlockGrid other = sphereGrid(voxel, 8, centre + Eigen::Vector3d(2.0, 0.0, 0.0), 0.5);
  ASSERT_LT(other.generation(), grid.generation());
  const MeshUpdate reset = extractor.update(other);
  EXPECT_FALSE(reset.removed.empty());
  expectSameMesh(extractor.combined(), extractMesh(other));
  extractor.clear();
  EXPECT_TRUE(extractor.chunks().empty());
  EXPECT_EQ(extractor.triangleCount(), 0u);
}

// A re-meshed chunk is written into the stored chunk's arrays: a surface
// block whose surface shrinks to one corner, one that gets a dense surface
// and one emptied still give the full extraction's mesh, and the shrunk
// chunk does not keep arrays sized for its old surface.
TEST(MeshExtractor, RemeshedChunksOfAnySizeGiveTheFullExtraction) {
  const Eigen::Vector3d centre(0.123, -0.456, 0.0789);
  const double voxel = 0.05;
  VoxelBlockGrid grid = sphereGrid(voxel, 8, centre, 1.0);
  MeshExtractor extractor;
  extractor.update(grid);
  std::vector<const MeshChunk*> chunks = extractor.chunks();
  ASSERT_GT(chunks.size(), 30u);
  std::sort(chunks.begin(), chunks.end(),
            [](const MeshChunk* a, const MeshChunk* b) { return a->triangles.size() > b->triangles.size(); });
  const BlockKey shrinking = chunks.front()->key, growing = chunks.back()->key, emptied = chunks[chunks.size() / 2]->key;
  const std::size_t largest = chunks.front()->triangles.size(), smallest = chunks.back()->triangles.size();
  const uint64_t generation = grid.nextGeneration();
  // Unobserved voxels (weight 0) end the surface inside the block.
  const auto rewrite = [&](const BlockKey& key, const std::function<float(int, int, int)>& sdf,
                           const std::function<bool(int, int, int)>& observed) {
    VoxelBlock* block = grid.find(key);
    for (int k = 0; k < 8; ++k)
      for (int j = 0; j < 8; ++j)
        for (int i = 0; i < 8; ++i) {
          block->sdf[i + 8 * (j + 8 * k)] = sdf(i, j, k);
          block->weight[i + 8 * (j + 8 * k)] = observed(i, j, k) ? 1.0f : 0.0f;
        }
    block->changed_generation = generation;
  };
  const float far = float(3 * voxel);
  rewrite(
      shrinking, [&](int i, int j, int k) { return i + j + k == 0 ? -far : far; },
      [](int i, int j, int k) { return i < 2 && j < 2 && k < 2; });
  rewrite(
      growing, [&](int i, int j, int k) { return float(voxel * std::sin(2.1 * i + 1.3 * j) * std::cos(1.7 * k)); },
      [](int, int, int) { return true; });
  rewrite(
      emptied, [&](int, int, int) { return far; }, [](int, int, int) { return false; });
  extractor.update(grid);
  expectSameMesh(extractor.combined(), extractMesh(grid));
  const MeshChunk* shrunk = extractor.chunk(shrinking);
  ASSERT_NE(shrunk, nullptr);
  EXPECT_LT(4 * shrunk->triangles.size(), largest);
  EXPECT_LE(shrunk->vertices.capacity(), 2 * shrunk->vertices.size() + 16);
  EXPECT_LE(shrunk->triangles.capacity(), 2 * shrunk->triangles.size() + 16);
  ASSERT_NE(extractor.chunk(growing), nullptr);
  EXPECT_GT(extractor.chunk(growing)->triangles.size(), 4 * smallest);
  EXPECT_EQ(extractor.chunk(emptied), nullptr);
}

// A lower neighbour reads only the first three voxel layers of a block
// across the faces it lies below: it is re-meshed only when one of the
// voxels it reads changed, and the mesh stays the full extraction's.
TEST(MeshExtractor, RemeshesALowerNeighbourOnlyWhenWhatItReadsChanged) {
  for (const bool intensity : {false, true}) {
    FillOptions fill;
    if (intensity) fill.intensity = [](const Eigen::Vector3d& p) { return 10.0 * p.x(); };
    const Eigen::Vector3d centre(0.123, -0.456, 0.0789);
    VoxelBlockGrid grid = sphereGrid(0.05, 8, centre, 1.0, fill);
    MeshExtractor extractor;
    extractor.update(grid);
    // A surface block with all 7 lower neighbours.
    const VoxelBlock* chosen = nullptr;
    for (const MeshChunk* chunk : extractor.chunks()) {
      int lower_neighbours = 0;
      for (int n = 1; n < 8; ++n)
        lower_neighbours += grid.find(chunk->key - Eigen::Vector3i(n & 1, (n >> 1) & 1, n >> 2)) != nullptr;
      if (lower_neighbours == 7) {
        chosen = grid.find(chunk->key);
        break;
      }
    }
    ASSERT_NE(chosen, nullptr);
    const BlockKey key = chosen->key;
    VoxelBlock& block = *grid.find(key);
    const auto lowerNeighbours = [&](std::vector<int> offsets) {
      std::vector<BlockKey> keys;
      for (int n : offsets) keys.push_back(key - Eigen::Vector3i(n & 1, (n >> 1) & 1, n >> 2));
      return sortedKeys(keys);
    };
    // Voxel (i, j, k) of the block changed (a value, a weight or an
    // intensity), then one update: what it re-meshed.
    const auto change = [&](int i, int j, int k, int what) {
      const int index = i + 8 * (j + 8 * k);
      if (what == 0) block.sdf[index] += 0.001f;
      if (what == 1) block.weight[index] += 1.0f;
      if (what == 2) block.intensity[index] += 1.0f;
      block.changed_generation = grid.nextGeneration();
      return extractor.update(grid).changed;
    };
    // Every block was meshed at once: no lower neighbour took a fingerprint
    // of what it read, so the first mark re-meshes them all.
    block.changed_generation = grid.nextGeneration();
    EXPECT_EQ(extractor.update(grid).changed, lowerNeighbours({0, 1, 2, 3, 4, 5, 6, 7}));
    block.changed_generation = grid.nextGeneration();  // marked, nothing changed
    EXPECT_EQ(extractor.update(grid).changed, lowerNeighbours({0}));
    EXPECT_EQ(change(7, 7, 7, 0), lowerNeighbours({0}));     // no lower neighbour reads it
    EXPECT_EQ(change(2, 5, 6, 0), lowerNeighbours({0, 1}));  // the one below along x
    EXPECT_EQ(change(6, 1, 2, 1), lowerNeighbours({0, 2, 4, 6}));
    if (intensity) EXPECT_EQ(change(6, 6, 0, 2), lowerNeighbours({0, 4}));
    EXPECT_EQ(change(0, 2, 1, 0), lowerNeighbours({0, 1, 2, 3, 4, 5, 6, 7}));
    expectSameMesh(extractor.combined(), extractMesh(grid));
  }
}

// With a budget of blocks per update, changed blocks wait oldest first: the
// first update re-meshes the budget, the rest follow in later updates, a
// block changed again while it waits is re-meshed once, and the mesh ends
// equal to a full extraction. force_all re-meshes everything at once.
TEST(MeshExtractor, BudgetLeavesTheRestForLaterUpdatesOldestFirst) {
  const Eigen::Vector3d centre(0.123, -0.456, 0.0789);
  const double voxel = 0.05;
  VoxelBlockGrid grid = sphereGrid(voxel, 8, centre, 1.0);
  const std::size_t blocks = grid.blockCount();
  ASSERT_GT(blocks, 100u);
  MeshOptions options;
  options.max_blocks_per_update = 40;
  MeshExtractor extractor(options);

  MeshUpdate update = extractor.update(grid);
  EXPECT_EQ(update.changed.size(), 40u);
  EXPECT_EQ(update.pending, blocks - 40);
  EXPECT_EQ(extractor.pendingCount(), blocks - 40);
  // The first 40 in key order (all waited since the same generation).
  std::vector<BlockKey> all_keys;
  for (const VoxelBlock* block : grid.blocks()) all_keys.push_back(block->key);
  all_keys = sortedKeys(all_keys);
  EXPECT_EQ(update.changed, std::vector<BlockKey>(all_keys.begin(), all_keys.begin() + 40));

  // The sphere grows in every block, and every block is marked again: the
  // 40 re-meshed ones queue behind those still waiting, which are re-meshed once.
  const auto refill = [&](double radius) {
    const uint64_t generation = grid.nextGeneration();
    const auto distance = sphereDistance(centre, radius);
    for (VoxelBlock* block : grid.blocks()) {
      for (int k = 0; k < 8; ++k)
        for (int j = 0; j < 8; ++j)
          for (int i = 0; i < 8; ++i)
            block->sdf[i + 8 * (j + 8 * k)] =
                float(std::clamp(distance(grid.voxelPosition(block->key, i, j, k)), -3 * voxel, 3 * voxel));
      block->changed_generation = generation;
    }
  };
  refill(1.0 + 0.3 * voxel);
  update = extractor.update(grid);
  EXPECT_EQ(update.changed, std::vector<BlockKey>(all_keys.begin() + 40, all_keys.begin() + 80));
  std::size_t updates = 2;
  while (extractor.pendingCount() > 0) {
    update = extractor.update(grid);
    EXPECT_LE(update.changed.size(), 40u);
    ASSERT_LT(++updates, 100u);
  }
  // After the first update every block waited once more: the 40 re-meshed
  // blocks for the second fill, the others for both fills together.
  EXPECT_EQ(updates, 1 + (blocks + 39) / 40);
  expectSameMesh(extractor.combined(), extractMesh(grid));

  // force_all: everything at once, budget or not.
  refill(1.0 - 0.2 * voxel);
  update = extractor.update(grid, /*force_all=*/true);
  EXPECT_EQ(update.changed.size(), blocks);
  EXPECT_EQ(update.pending, 0u);
  expectSameMesh(extractor.combined(), extractMesh(grid));

  // A time budget stops between batches: a budget far below one block's
  // time still re-meshes one batch, and never everything at once.
  MeshOptions timed;
  timed.update_budget_s = 1e-9;
  MeshExtractor budgeted(timed);
  update = budgeted.update(grid);
  EXPECT_GT(update.changed.size(), 0u);
  EXPECT_LT(update.changed.size(), blocks);
  EXPECT_EQ(update.pending, blocks - update.changed.size());
}

TEST(MeshExtractor, SpeedOnAMillionVoxelsWithTwoThreads) {
  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, 2);
  const Eigen::Vector3d centre(0.31, -0.17, 0.05);
  VoxelBlockGrid grid = sphereGrid(0.05, 8, centre, 3.0);
  const std::size_t voxels = grid.blockCount() * std::size_t(grid.voxelsPerBlock());
  EXPECT_GT(voxels, 800000u);

  auto start = std::chrono::steady_clock::now();
  const TriangleMesh mesh = extractMesh(grid);
  const double whole_seconds = secondsSince(start);

  MeshExtractor extractor;
  const MeshUpdate first = extractor.update(grid);
  start = std::chrono::steady_clock::now();
  const TriangleMesh combined = extractor.combined();
  const double combine_seconds = secondsSince(start);
  EXPECT_EQ(combined.triangles.size(), mesh.triangles.size());

  // 200 neighbouring surface blocks changed (the first in key order: a slab).
  const std::vector<const MeshChunk*> chunks = extractor.chunks();
  const uint64_t generation = grid.nextGeneration();
  for (std::size_t i = 0; i < 200; ++i) grid.find(chunks[i]->key)->changed_generation = generation;
  const MeshUpdate incremental = extractor.update(grid);
  std::printf("%zu blocks (%zu voxels), %zu triangles on 2 threads: extractMesh %.3f s, first "
              "update %.3f s, combined() %.3f s; 200 blocks changed: update re-meshes %zu blocks "
              "in %.4f s\n",
              grid.blockCount(), voxels, mesh.triangles.size(), whole_seconds, first.seconds,
              combine_seconds, incremental.changed.size(), incremental.seconds);
  EXPECT_GE(incremental.changed.size(), 200u);
  EXPECT_LT(incremental.changed.size(), grid.blockCount() / 2);
}

// ---------------------------------------------------------------- files and bad input

TEST(MarchingCubes, SavedMeshKeepsVerticesTrianglesNormalsAndIntensity) {
  FillOptions fill;
  fill.intensity = [](const Eigen::Vector3d& p) { return 100.0 * p.z(); };
  const TriangleMesh mesh = extractMesh(sphereGrid(0.1, 8, {0.01, 0.02, 0.03}, 0.6, fill));
  ASSERT_FALSE(mesh.triangles.empty());
  const std::string path = temporaryPath("sphere.ply");
  io::saveMeshFile(path, mesh);
  const TriangleMesh read = io::readPlyMesh(path);
  EXPECT_EQ(read.vertices, mesh.vertices);
  EXPECT_EQ(read.triangles, mesh.triangles);

  // Normals and intensity follow x y z in each binary vertex record.
  std::ifstream file(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  const std::size_t body = bytes.find("end_header\n") + std::strlen("end_header\n");
  const std::string header = bytes.substr(0, body);
  EXPECT_NE(header.find("property float nx\nproperty float ny\nproperty float nz\nproperty float intensity\n"),
            std::string::npos)
      << header;
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
    std::array<float, 7> record;
    std::memcpy(record.data(), bytes.data() + body + v * sizeof(record), sizeof(record));
    EXPECT_EQ(Eigen::Vector3f(record[3], record[4], record[5]), mesh.normals[v]);
    EXPECT_EQ(record[6], mesh.intensities[v]);
  }
  std::remove(path.c_str());

  TriangleMesh bad = mesh;
  bad.intensities.pop_back();
  EXPECT_THROW(io::saveMeshFile(path, bad), std::invalid_argument);
  bad = mesh;
  bad.normals.pop_back();
  EXPECT_THROW(io::saveMeshFile(path, bad), std::invalid_argument);
}

TEST(MarchingCubes, BadInputIsRefusedWithAClearError) {
  MeshOptions negative;
  negative.min_weight = -1.0f;
  EXPECT_THROW(MeshExtractor{negative}, MappingError);
  MeshOptions negative_budget;
  negative_budget.update_budget_s = -0.01;
  EXPECT_THROW(MeshExtractor{negative_budget}, MappingError);
  MeshOptions infinite_budget;
  infinite_budget.update_budget_s = std::numeric_limits<double>::infinity();
  EXPECT_THROW(MeshExtractor{infinite_budget}, MappingError);
  MeshOptions not_a_number;
  not_a_number.min_weight = std::nanf("");
  VoxelBlockGrid grid = sphereGrid(0.1, 8, {0.0, 0.0, 0.0}, 0.5);
  EXPECT_THROW(extractMesh(grid, not_a_number), MappingError);

  // A block whose arrays were resized behind the grid's back.
  const std::size_t triangles = extractMesh(grid).triangles.size();
  VoxelBlock* block = grid.blocks().front();
  const std::vector<float> saved = block->sdf;
  block->sdf.resize(5);
  try {
    extractMesh(grid);
    ADD_FAILURE() << "no MappingError";
  } catch (const MappingError& error) {
    EXPECT_NE(std::string(error.what()).find("sdf"), std::string::npos) << error.what();
  }
  MeshExtractor extractor;
  EXPECT_THROW(extractor.update(grid), MappingError);
  block->sdf = saved;
  EXPECT_EQ(extractMesh(grid).triangles.size(), triangles);
  // The failed update changed nothing: the next one meshes everything.
  extractor.update(grid);
  EXPECT_EQ(extractor.triangleCount(), triangles);

  // Non-finite values count as unobserved instead of spreading NaN vertices.
  for (float& sdf : block->sdf) sdf = std::nanf("");
  for (const Eigen::Vector3f& v : extractMesh(grid).vertices) EXPECT_TRUE(v.allFinite());

  // Empty input.
  EXPECT_EQ(countBoundaryEdges({}), 0u);
  EXPECT_TRUE(extractMesh(VoxelBlockGrid({0.1, 8, false})).triangles.empty());
}

}  // namespace
}  // namespace range_image_mapping::mapping
