// The voxel block grid: lattice <-> key arithmetic (negative coordinates too),
// stable block addresses, the memory budget, removal by radius, memory
// accounting and option checks.
#include "range_image_mapping/mapping/voxel_block_grid.h"
#include "error_text.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <set>
#include <vector>

namespace range_image_mapping::mapping {
namespace {

using test::contains;
using test::errorOf;

VoxelBlockGridOptions gridOptions(double voxel_size, int edge, std::size_t max_blocks = 0) {
  VoxelBlockGridOptions options;
  options.voxel_size_m = voxel_size;
  options.block_edge = edge;
  options.max_blocks = max_blocks;
  return options;
}

TEST(VoxelBlockGrid, EveryVoxelPositionMapsBackToItsBlock) {
  for (const int edge : {8, 16})
    for (const double voxel_size : {0.1, 0.05, 0.37}) {
      const VoxelBlockGrid grid(gridOptions(voxel_size, edge));
      for (int x = -3; x <= 2; ++x)
        for (int y = -2; y <= 2; ++y)
          for (int z = -2; z <= 1; ++z) {
            const BlockKey key(x * 7, y * 1001, z - 50);
            for (int i = 0; i < edge; i += edge / 4 + 1)
              for (int j = 0; j < edge; j += 3)
                for (int k = 0; k < edge; k += edge - 1) {
                  const Eigen::Vector3d position = grid.voxelPosition(key, i, j, k);
                  ASSERT_EQ(grid.blockKeyOf(position), key) << "voxel " << i << " " << j << " " << k;
                  // Half a voxel further along stays in the block's cell of that voxel.
                  const Eigen::Vector3d inside = position + Eigen::Vector3d::Constant(0.5 * voxel_size);
                  ASSERT_EQ(grid.blockKeyOf(inside), key);
                }
            // Just below the block's first lattice point is the previous block.
            const Eigen::Vector3d below = grid.voxelPosition(key, 0, 0, 0) - Eigen::Vector3d::Constant(0.01 * voxel_size);
            ASSERT_EQ(grid.blockKeyOf(below), BlockKey(key - BlockKey::Ones()));
          }
    }
}

TEST(VoxelBlockGrid, KeysAreFloorDivisionAlsoBelowZero) {
  const VoxelBlockGrid grid(gridOptions(0.1, 8));  // 0.8 m blocks
  EXPECT_EQ(grid.blockKeyOf(Eigen::Vector3d(0.05, 0.79, 0.81)), BlockKey(0, 0, 1));
  EXPECT_EQ(grid.blockKeyOf(Eigen::Vector3d(-0.05, -0.8, -0.81)), BlockKey(-1, -1, -2));
  EXPECT_EQ(grid.blockKeyOf(Eigen::Vector3d(-1234.5, 0.0, 1e5)), BlockKey(-1544, 0, 125000));
  EXPECT_TRUE(grid.voxelPosition(BlockKey(-1, 2, 0), 3, 0, 7).isApprox(Eigen::Vector3d(-0.5, 1.6, 0.7), 1e-12));
  EXPECT_TRUE(contains(errorOf([&] { grid.blockKeyOf(Eigen::Vector3d(0, std::nan(""), 0)); }), "not finite"));
  EXPECT_THROW(grid.blockKeyOf(Eigen::Vector3d(1e9, 0, 0)), MappingError);
}

TEST(VoxelBlockGrid, ActivatedBlocksStartUnobservedAndKeepTheirAddress) {
  VoxelBlockGridOptions options = gridOptions(0.1, 8);
  options.store_intensity = true;
  VoxelBlockGrid grid(options);
  bool created = false;
  VoxelBlock* first = grid.activate(BlockKey(-5, 3, 9), &created);
  ASSERT_NE(first, nullptr);
  EXPECT_TRUE(created);
  EXPECT_EQ(first->key, BlockKey(-5, 3, 9));
  ASSERT_EQ(first->sdf.size(), 512u);
  ASSERT_EQ(first->intensity.size(), 512u);
  for (int i = 0; i < 512; ++i) ASSERT_EQ(first->weight[i], 0.0f);
  first->sdf[17] = 0.25f;
  first->weight[17] = 3.0f;
  // 100k more blocks: the table rehashes many times, the blocks never move.
  for (int n = 0; n < 100000; ++n) ASSERT_NE(grid.activate(BlockKey(n % 47, n / 47, -n % 13)), nullptr);
  EXPECT_EQ(grid.blockCount(), 100001u);
  EXPECT_EQ(grid.activate(BlockKey(-5, 3, 9), &created), first);
  EXPECT_FALSE(created);
  EXPECT_EQ(grid.find(BlockKey(-5, 3, 9)), first);
  EXPECT_EQ(first->sdf[17], 0.25f);
  EXPECT_EQ(first->weight[17], 3.0f);
  EXPECT_EQ(grid.find(BlockKey(1000, 0, 0)), nullptr);
  EXPECT_EQ(grid.blocks().size(), 100001u);
}

TEST(VoxelBlockGrid, MemoryBudgetRefusesNewBlocksAndKeepsTheOthers) {
  VoxelBlockGrid grid(gridOptions(0.1, 16, 10));
  std::vector<VoxelBlock*> kept;
  for (int n = 0; n < 10; ++n) {
    kept.push_back(grid.activate(BlockKey(n, 0, 0)));
    ASSERT_NE(kept.back(), nullptr);
    kept.back()->weight[0] = float(n + 1);
  }
  bool created = true;
  EXPECT_EQ(grid.activate(BlockKey(10, 0, 0), &created), nullptr);
  EXPECT_FALSE(created);
  EXPECT_EQ(grid.blockCount(), 10u);
  EXPECT_EQ(grid.find(BlockKey(10, 0, 0)), nullptr);
  // Existing blocks are still found through activate().
  EXPECT_EQ(grid.activate(BlockKey(4, 0, 0)), kept[4]);
  for (int n = 0; n < 10; ++n) EXPECT_EQ(kept[n]->weight[0], float(n + 1));
  // Room again after a removal.
  EXPECT_TRUE(grid.remove(BlockKey(0, 0, 0)));
  EXPECT_FALSE(grid.remove(BlockKey(0, 0, 0)));
  EXPECT_NE(grid.activate(BlockKey(10, 0, 0)), nullptr);
}

TEST(VoxelBlockGrid, ActivatingManyIsActivatingEachInTurn) {
  // Two grids with the same history (a budget, a removed block whose slot and
  // arrays are reused, intensity): activateMany must give each key the block,
  // slot, creation flag, refusal and cleared arrays that activate() would.
  VoxelBlockGridOptions options = gridOptions(0.1, 8, 7);
  options.store_intensity = true;
  VoxelBlockGrid one_by_one(options), together(options);
  for (VoxelBlockGrid* grid : {&one_by_one, &together}) {
    for (int n = 0; n < 4; ++n) grid->activate(BlockKey(n, 0, 0))->weight[5] = 2.0f;
    grid->activate(BlockKey(2, 0, 0))->sdf[7] = 0.5f;
    ASSERT_TRUE(grid->remove(BlockKey(1, 0, 0)));  // its slot (and arrays) go to the next new block
  }
  const std::vector<BlockKey> keys{BlockKey(9, 1, 0), BlockKey(2, 0, 0),  BlockKey(-3, 4, 5), BlockKey(0, 0, 0),
                                   BlockKey(7, 7, 7), BlockKey(8, -1, 2), BlockKey(6, 6, 6)};
  std::vector<VoxelBlock*> expected, blocks(keys.size());
  std::vector<uint8_t> expected_created, created(keys.size(), 2);
  for (const BlockKey& key : keys) {
    bool is_new = false;
    expected.push_back(one_by_one.activate(key, &is_new));
    expected_created.push_back(is_new);
  }
  together.activateMany(keys.data(), keys.size(), blocks.data(), created.data());
  std::vector<const VoxelBlock*> all_expected = const_cast<const VoxelBlockGrid&>(one_by_one).blocks();
  std::vector<const VoxelBlock*> all = const_cast<const VoxelBlockGrid&>(together).blocks();
  ASSERT_EQ(all.size(), all_expected.size());
  EXPECT_EQ(together.blockCount(), 7u);  // the budget refused the last two new keys
  for (std::size_t n = 0; n < keys.size(); ++n) {
    EXPECT_EQ(int(created[n]), int(expected_created[n])) << n;
    ASSERT_EQ(blocks[n] == nullptr, expected[n] == nullptr) << n;
    if (!blocks[n]) continue;
    EXPECT_EQ(blocks[n]->key, keys[n]);
    EXPECT_EQ(blocks[n]->sdf, expected[n]->sdf) << n;
    EXPECT_EQ(blocks[n]->weight, expected[n]->weight) << n;
    EXPECT_EQ(blocks[n]->intensity, expected[n]->intensity) << n;
    EXPECT_EQ(blocks[n]->changed_generation, expected[n]->changed_generation) << n;
  }
  EXPECT_EQ(blocks[1]->sdf[7], 0.5f);  // an existing block is kept as it is
  EXPECT_EQ(blocks[0]->weight[5], 0.0f);  // a new one in a reused slot is cleared
  EXPECT_EQ(blocks[0]->sdf.size(), 512u);
  // The same slots: the grids list their blocks in the same order.
  for (std::size_t n = 0; n < all.size(); ++n) EXPECT_EQ(all[n]->key, all_expected[n]->key) << n;
}

TEST(VoxelBlockGrid, RemovesExactlyTheBlocksBeyondTheRadius) {
  VoxelBlockGrid grid(gridOptions(0.1, 8));  // 0.8 m blocks
  const Eigen::Vector3d centre(1.0, -2.0, 0.5);
  const double radius = 3.3;
  std::set<std::array<int, 3>> expected_removed;
  for (int x = -8; x <= 8; ++x)
    for (int y = -8; y <= 8; ++y)
      for (int z = -3; z <= 3; ++z) {
        VoxelBlock* block = grid.activate(BlockKey(x, y, z));
        block->weight[5] = 1.0f;
        const Eigen::Vector3d block_centre = (Eigen::Vector3d(x, y, z) + Eigen::Vector3d::Constant(0.5)) * 0.8;
        if ((block_centre - centre).norm() > radius) expected_removed.insert({x, y, z});
      }
  const std::size_t before = grid.blockCount();
  std::vector<BlockKey> removed;
  EXPECT_EQ(grid.removeBlocksFartherThan(centre, radius, &removed), expected_removed.size());
  ASSERT_EQ(removed.size(), expected_removed.size());
  for (const BlockKey& key : removed) EXPECT_EQ(expected_removed.count({key.x(), key.y(), key.z()}), 1u);
  EXPECT_EQ(grid.blockCount(), before - expected_removed.size());
  for (const VoxelBlock* block : grid.blocks()) {
    EXPECT_EQ(expected_removed.count({block->key.x(), block->key.y(), block->key.z()}), 0u);
    EXPECT_EQ(block->weight[5], 1.0f);
  }
  // Reused slots start unobserved again.
  for (int n = 0; n < 50; ++n) {
    const VoxelBlock* block = grid.activate(BlockKey(100 + n, 0, 0));
    EXPECT_EQ(block->weight[5], 0.0f);
  }
  EXPECT_THROW(grid.removeBlocksFartherThan(centre, std::nan(""), nullptr), MappingError);
}

TEST(VoxelBlockGrid, MemoryGrowsLinearlyWithTheBlocks) {
  for (const bool intensity : {false, true}) {
    VoxelBlockGridOptions options = gridOptions(0.1, 8);
    options.store_intensity = intensity;
    VoxelBlockGrid grid(options);
    const std::size_t voxel_bytes = (intensity ? 3 : 2) * sizeof(float) * 512;
    std::size_t previous = grid.memoryBytes();
    for (int count : {1000, 2000, 4000, 8000}) {
      for (int n = int(grid.blockCount()); n < count; ++n) grid.activate(BlockKey(n, -n, 2 * n));
      const std::size_t bytes = grid.memoryBytes();
      EXPECT_GE(bytes, count * voxel_bytes);
      // Hash buckets and bookkeeping stay a small fraction of the voxels.
      EXPECT_LE(bytes, std::size_t(1.1 * count * voxel_bytes));
      EXPECT_GT(bytes, previous);
      previous = bytes;
    }
    grid.clear();
    EXPECT_EQ(grid.blockCount(), 0u);
    EXPECT_LT(grid.memoryBytes(), voxel_bytes);
  }
}

TEST(VoxelBlockGrid, BadOptionsNameTheFieldAndValue) {
  const auto message = [](double voxel_size, int edge) {
    return errorOf([&] { VoxelBlockGrid grid(gridOptions(voxel_size, edge)); });
  };
  EXPECT_TRUE(contains(message(0.0, 8), "voxel_size_m")) << message(0.0, 8);
  EXPECT_TRUE(contains(message(0.0, 8), "got 0"));
  EXPECT_TRUE(contains(message(-0.1, 8), "-0.1"));
  EXPECT_TRUE(contains(message(std::nan(""), 8), "nan"));
  EXPECT_TRUE(contains(message(10.5, 8), "10.5"));
  EXPECT_TRUE(contains(message(0.0005, 8), "voxel_size_m"));
  EXPECT_TRUE(contains(message(0.1, 10), "block_edge"));
  EXPECT_TRUE(contains(message(0.1, 10), "got 10"));
  EXPECT_TRUE(contains(message(0.1, 0), "block_edge"));
  EXPECT_EQ(message(10.0, 16), "no exception");
  EXPECT_EQ(message(0.001, 8), "no exception");
  EXPECT_THROW(VoxelBlockGrid(gridOptions(0.1, 7)), MappingError);
}

}  // namespace
}  // namespace range_image_mapping::mapping
