// Marching cubes over a voxel block grid: the zero crossing of the TSDF as a
// triangle mesh with welded vertices and normals from the SDF gradient.
// Cubes that span a block border read the neighbouring blocks, so there are
// no cracks: ambiguous faces are resolved by the asymptotic decider, which
// reads only the face, so both cubes of a face agree (the case table is
// generated from the cube's topology, src/mapping/marching_cubes_cases.h).
// Incremental: a MeshExtractor re-meshes only the blocks changed
// since its last update (and those of their -1 neighbours whose border cubes
// read a changed part of them), keeping one mesh chunk per block, optionally
// within a time budget per update.
#pragma once

#include "range_image_mapping/mapping/voxel_block_grid.h"
#include "range_image_mapping/triangle_mesh.h"

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace range_image_mapping::mapping {

struct MeshOptions {
  // A cube is meshed only if all 8 corners are observed and have at least
  // this weight. Unobserved corners (weight 0, or a non-finite SDF) never
  // produce triangles, so the mesh ends where observations end instead of
  // closing on invented surfaces. Weights count full observations: a sample
  // weighs 1, less with the integrator's incidence or range weighting (down
  // to 0.1 for a grazing one), so 0, the default, meshes everything observed
  // whatever the weighting, and 1 asks for at least one full observation's
  // worth (TsdfIntegratorOptions::mesh_min_weight must then say the same).
  float min_weight = 0.0f;
  // MeshExtractor::update() only: a budget per update, so that a live map's
  // mesh costs bounded time per scan. Blocks that changed wait in a queue,
  // oldest change first, and are re-meshed by later updates; a block that
  // changes again while it waits is re-meshed once. 0 = no limit (every
  // changed block in every update). The time budget is checked between
  // batches of blocks, so an update may pass it by one batch.
  double update_budget_s = 0.0;
  std::size_t max_blocks_per_update = 0;
  // Throws MappingError for a negative or non-finite min_weight or budget.
  void validate() const;
};

// A vertex named independently of the chunk that made it: the block holding
// the lower end of its lattice edge and, within that block, axis + 3 * voxel
// index. Two chunks that cut the same edge made the same vertex. The few
// vertices inside a cube (the centre of a tunnel's iso-line loop) are named
// 3 * block_edge^3 + voxel index of the cube's lower corner.
struct LatticeEdge {
  BlockKey block = BlockKey::Zero();
  int index = 0;
  bool operator==(const LatticeEdge& other) const {
    return index == other.index && block == other.block;
  }
};

struct LatticeEdgeHash {
  std::size_t operator()(const LatticeEdge& edge) const {
    return BlockKeyHash()(edge.block) ^ (std::size_t(edge.index) * 0x9E3779B97F4A7C15ull);
  }
};

// The triangles of one block: vertices welded within the chunk (each edge
// crossing is one vertex shared by the triangles around it).
struct MeshChunk {
  BlockKey key = BlockKey::Zero();
  std::vector<Eigen::Vector3f> vertices;   // world frame
  std::vector<Eigen::Vector3f> normals;    // unit, from the SDF gradient, pointing to free space
  std::vector<float> intensities;          // per vertex when the grid stores intensity
  std::vector<Eigen::Vector3i> triangles;  // indices into vertices
  std::vector<LatticeEdge> vertex_edges;   // each vertex's name, for welding chunks
  // The grid's block edge (voxels); with it welding looks up only the
  // vertices another chunk can share (those on the block's lower faces or
  // named after a +1 neighbour). 0: every vertex is looked up by name.
  int block_edge = 0;
};

// Meshes one block (cubes whose lower corner is in the block, reading the +1
// neighbours for the far corners). Vertex normals are SDF gradients by
// central differences, one-sided where a neighbour is unobserved or lies
// below a block's lower face, so a chunk reads only its block and the +1
// neighbours and every lattice edge gets the same vertex from any chunk.
// Throws MappingError for invalid options or a block whose arrays do not
// have block_edge^3 entries.
MeshChunk meshBlock(const VoxelBlockGrid& grid, const VoxelBlock& block, const MeshOptions& options = {});

// The whole grid as one mesh, vertices welded across block borders too
// (a closed surface has no boundary edges). Blocks are meshed and welded in parallel;
// the output order is deterministic (blocks sorted by key). Normals are one
// per vertex, intensities too when the grid stores intensity (saved with
// io::saveMeshFile).
TriangleMesh extractMesh(const VoxelBlockGrid& grid, const MeshOptions& options = {});

// Number of edges used by exactly one triangle: 0 for a watertight mesh.
std::size_t countBoundaryEdges(const std::vector<Eigen::Vector3i>& triangles);

struct MeshUpdate {
  std::vector<BlockKey> changed;  // chunks rebuilt (possibly now empty)
  std::vector<BlockKey> removed;  // chunks whose block is gone
  std::size_t pending = 0;        // changed blocks left for later updates by the budget
  double seconds = 0.0;
};

// Keeps the mesh of a grid up to date block by block.
class MeshExtractor {
 public:
  explicit MeshExtractor(MeshOptions options = {});
  // Re-meshes the blocks changed since the last call (and their lower
  // neighbours, unless the first voxel layers they read of the changed block
  // are as they last read them, by a 64-bit fingerprint per slab), in
  // parallel, within the options' budget (the rest wait).
  // Blocks removed from the grid lose their chunk. "Changed" means
  // changed_generation above the grid's generation at the last call, or new
  // since the last call; a grid whose generation went backwards (reset or
  // replaced) is re-meshed whole. Blocks rebuilt without triangles keep no
  // chunk. force_all: re-mesh every block of the grid, whatever the budget
  // and whatever the integrator left unmarked (TsdfIntegratorOptions::
  // mesh_tolerance_voxels): combined() then equals extractMesh(grid).
  MeshUpdate update(const VoxelBlockGrid& grid, bool force_all = false);
  // nullptr when the block has no triangles.
  const MeshChunk* chunk(const BlockKey& key) const;
  // Sorted by key.
  std::vector<const MeshChunk*> chunks() const;
  std::size_t triangleCount() const;
  // All chunks as one mesh (vertices welded across chunk borders).
  TriangleMesh combined() const;
  // Changed blocks waiting for an update (the budget left them out).
  std::size_t pendingCount() const;
  void clear();

 private:
  struct State;
  MeshOptions options_;
  std::shared_ptr<State> state_;
  uint64_t meshed_generation_ = 0;
};

}  // namespace range_image_mapping::mapping
