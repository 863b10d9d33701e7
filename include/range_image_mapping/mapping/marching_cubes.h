// Marching cubes over a voxel block grid: the zero crossing of the TSDF as a
// triangle mesh with welded vertices and normals from the SDF gradient.
// Cubes that span a block border read the neighbouring blocks, so there are
// no cracks. Incremental: a MeshExtractor re-meshes only the blocks changed
// since its last update (and their -1 neighbours, whose border cubes read
// them), keeping one mesh chunk per block.
#pragma once

#include "range_image_mapping/mapping/voxel_block_grid.h"

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace range_image_mapping::mapping {

struct MeshOptions {
  // A cube is meshed only if all 8 corners have at least this weight.
  // Unobserved corners (weight 0) never produce triangles, so the mesh ends
  // where observations end instead of closing on invented surfaces.
  float min_weight = 1.0f;
};

// The triangles of one block: vertices welded within the chunk (each edge
// crossing is one vertex shared by the triangles around it).
struct MeshChunk {
  BlockKey key = BlockKey::Zero();
  std::vector<Eigen::Vector3f> vertices;   // world frame
  std::vector<Eigen::Vector3f> normals;    // unit, from the SDF gradient, pointing to free space
  std::vector<float> intensities;          // per vertex when the grid stores intensity
  std::vector<Eigen::Vector3i> triangles;  // indices into vertices
};

struct TriangleMeshData {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Eigen::Vector3f> normals;
  std::vector<float> intensities;  // empty or one per vertex
  std::vector<Eigen::Vector3i> triangles;
};

// Meshes one block (cubes whose lower corner is in the block, reading the +1
// neighbours for the far corners).
MeshChunk meshBlock(const VoxelBlockGrid& grid, const VoxelBlock& block, const MeshOptions& options = {});

// The whole grid as one mesh, vertices welded across block borders too
// (a closed surface has no boundary edges).
TriangleMeshData extractMesh(const VoxelBlockGrid& grid, const MeshOptions& options = {});

// Number of edges used by exactly one triangle: 0 for a watertight mesh.
std::size_t countBoundaryEdges(const std::vector<Eigen::Vector3i>& triangles);

// Binary PLY with normals (and "intensity" when present).
void writeMeshPly(const std::string& path, const TriangleMeshData& mesh);

struct MeshUpdate {
  std::vector<BlockKey> changed;  // chunks rebuilt (possibly now empty)
  std::vector<BlockKey> removed;  // chunks whose block is gone
  double seconds = 0.0;
};

// Keeps the mesh of a grid up to date block by block.
class MeshExtractor {
 public:
  explicit MeshExtractor(MeshOptions options = {});
  // Re-meshes the blocks changed since the last call (and their lower
  // neighbours), in parallel. Blocks removed from the grid lose their chunk.
  MeshUpdate update(const VoxelBlockGrid& grid);
  const MeshChunk* chunk(const BlockKey& key) const;
  std::vector<const MeshChunk*> chunks() const;
  std::size_t triangleCount() const;
  // All chunks as one mesh (vertices welded across chunk borders).
  TriangleMeshData combined() const;
  void clear();

 private:
  struct State;
  MeshOptions options_;
  std::shared_ptr<State> state_;
  uint64_t meshed_generation_ = 0;
};

}  // namespace range_image_mapping::mapping
