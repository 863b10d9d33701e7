// A globally sparse, locally dense voxel grid (the paper's ASH hash grid,
// section 4.2): a hash map (robin-map) from block coordinates to dense blocks
// of block_edge^3 voxels, each holding a TSDF value, a weight and optionally
// an intensity.
//
// Voxel (i, j, k) of block key K is the lattice point
//   world = (K * block_edge + (i, j, k)) * voxel_size,
// so neighbouring blocks share no samples and marching cubes needs the +1
// neighbours to close the seams.
#pragma once

#include "range_image_mapping/lattice_key.h"

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::mapping {

// Bad mapping parameters or input; what() names the field and the value.
class MappingError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

struct VoxelBlockGridOptions {
  double voxel_size_m = 0.1;
  int block_edge = 16;  // voxels per block edge: 8 or 16 (see the README: 16 meshes faster, 8 takes less memory)
  bool store_intensity = false;
  // Memory budget: 0 = unlimited. At the limit activate() creates nothing
  // more (integration skips the missing blocks and reports them), so what is
  // mapped already is never lost.
  std::size_t max_blocks = 0;
  // Throws MappingError: voxel size not in [1 mm, 10 m], block edge not 8 or 16.
  void validate() const;
};

using BlockKey = LatticeKey;
using BlockKeyHash = LatticeKeyHash;

struct VoxelBlock {
  BlockKey key = BlockKey::Zero();
  // block_edge^3 entries, index = i + edge * (j + edge * k).
  std::vector<float> sdf;        // metres, truncated; meaningless where weight == 0
  std::vector<float> weight;     // 0 = never observed
  std::vector<float> intensity;  // empty unless store_intensity
  // Integration generation that last changed this block; meshing compares it
  // with the generation it last meshed.
  uint64_t changed_generation = 0;
};

class VoxelBlockGrid {
 public:
  explicit VoxelBlockGrid(VoxelBlockGridOptions options);  // validates
  ~VoxelBlockGrid();
  VoxelBlockGrid(VoxelBlockGrid&&) noexcept;
  VoxelBlockGrid& operator=(VoxelBlockGrid&&) noexcept;

  const VoxelBlockGridOptions& options() const { return options_; }
  double voxelSize() const { return options_.voxel_size_m; }
  int blockEdge() const { return options_.block_edge; }
  int voxelsPerBlock() const { return options_.block_edge * options_.block_edge * options_.block_edge; }
  double blockSize() const { return options_.voxel_size_m * options_.block_edge; }

  // Block holding the lattice point nearest below `point` (floor division;
  // a lattice point off by rounding counts as that lattice point). Throws
  // MappingError for a coordinate that is not finite or beyond 2^30 voxels.
  BlockKey blockKeyOf(const Eigen::Vector3d& point_world) const;
  // The largest |coordinate / voxel size| the grid accepts: voxel and block
  // indices stay far from int overflow.
  static constexpr double kLargestLatticeIndex = double(1 << 30);
  // World position of voxel (i, j, k) of a block.
  Eigen::Vector3d voxelPosition(const BlockKey& key, int i, int j, int k) const;

  // Finds or creates (sdf = 0, weight = 0) the block; nullptr when creating
  // it would pass max_blocks. Pointers stay valid until
  // the block is removed or the grid cleared, whatever else is inserted.
  // Not thread-safe: activation is serial, integration into existing blocks
  // is parallel.
  VoxelBlock* activate(const BlockKey& key, bool* created = nullptr);
  // activate() for count keys, in their order (the same slots, and the same
  // refusals at max_blocks, as one call each): blocks[n] and created[n] for
  // keys[n]. The new blocks' arrays are then zeroed in parallel: first
  // writes to fresh memory cost a page fault per 4 KB, most of creating a
  // block. Not thread-safe either (it runs its own parallel loop).
  void activateMany(const BlockKey* keys, std::size_t count, VoxelBlock** blocks, uint8_t* created);
  VoxelBlock* find(const BlockKey& key);
  const VoxelBlock* find(const BlockKey& key) const;

  std::size_t blockCount() const;
  // Bytes of voxel storage plus the hash table: what the map costs in RAM.
  // Removed blocks keep their arrays for reuse until clear(), and count.
  std::size_t memoryBytes() const;
  // Every block, in no particular order (stable between modifications).
  std::vector<const VoxelBlock*> blocks() const;
  std::vector<VoxelBlock*> blocks();

  // Blocks whose centre is farther than radius_m from centre_world.
  std::vector<BlockKey> blocksFartherThan(const Eigen::Vector3d& centre_world, double radius_m) const;
  // Removes those blocks (bounded memory for long runs); appends their keys
  // to `removed` if given.
  std::size_t removeBlocksFartherThan(const Eigen::Vector3d& centre_world, double radius_m,
                                      std::vector<BlockKey>* removed = nullptr);
  // Removes one block (false if absent); its slot is reused.
  bool remove(const BlockKey& key);
  // Removes every block and gives the memory back.
  void clear();

  // Monotonic counter bumped by each integration (TsdfIntegrator); blocks
  // record it in changed_generation.
  uint64_t generation() const { return generation_; }
  uint64_t nextGeneration() { return ++generation_; }

 private:
  // The block of key, or a slot taken for it (key set, arrays as the slot
  // left them: *created is then true); nullptr at max_blocks.
  VoxelBlock* findOrAddSlot(const BlockKey& key, bool* created);
  // sdf = weight (= intensity) = 0, voxelsPerBlock() of each.
  void clearArrays(VoxelBlock& block) const;
  struct Storage;
  VoxelBlockGridOptions options_;
  std::unique_ptr<Storage> storage_;
  uint64_t generation_ = 0;
};

}  // namespace range_image_mapping::mapping
