#include "range_image_mapping/mapping/voxel_block_grid.h"

#include "number_text.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tsl/robin_map.h>

#include <cmath>
#include <deque>

namespace range_image_mapping::mapping {
namespace {

constexpr double kSmallestVoxelSize = 0.001;
constexpr double kLargestVoxelSize = 10.0;

using BlockSlots = tsl::robin_map<BlockKey, uint32_t, BlockKeyHash>;
// What one hash bucket costs (robin_map.h documents this entry type).
constexpr std::size_t kBucketBytes =
    sizeof(tsl::detail_robin_hash::bucket_entry<std::pair<BlockKey, uint32_t>, false>);

// Floor division for negative lattice indices too (C++ division truncates).
int floorDivide(int value, int divisor) {
  const int quotient = value / divisor;
  return quotient - (value % divisor < 0);
}

}  // namespace

void VoxelBlockGridOptions::validate() const {
  if (!(voxel_size_m >= kSmallestVoxelSize && voxel_size_m <= kLargestVoxelSize))
    throw MappingError("voxel_size_m must be within [0.001, 10] m, got " + numberText(voxel_size_m));
  if (block_edge != 8 && block_edge != 16)
    throw MappingError("block_edge must be 8 or 16 voxels, got " + std::to_string(block_edge));
}

// Blocks live in a deque (stable addresses whatever is appended); a removed
// block's slot goes to the free list and keeps its arrays for the next block,
// so a map moving with the sensor stops allocating once it has its size.
struct VoxelBlockGrid::Storage {
  BlockSlots slots;
  std::deque<VoxelBlock> pool;
  std::vector<uint32_t> free_slots;
};

VoxelBlockGrid::VoxelBlockGrid(VoxelBlockGridOptions options)
    : options_(options), storage_(std::make_unique<Storage>()) {
  options_.validate();
}

VoxelBlockGrid::~VoxelBlockGrid() = default;
VoxelBlockGrid::VoxelBlockGrid(VoxelBlockGrid&&) noexcept = default;
VoxelBlockGrid& VoxelBlockGrid::operator=(VoxelBlockGrid&&) noexcept = default;

BlockKey VoxelBlockGrid::blockKeyOf(const Eigen::Vector3d& point_world) const {
  BlockKey key;
  for (int axis = 0; axis < 3; ++axis) {
    const double lattice = point_world[axis] / options_.voxel_size_m;
    // A lattice point computed as index * voxel_size may divide back to a hair
    // below its index; it still belongs to the block voxelPosition() put it in.
    const double nearest = std::round(lattice);
    const double index = std::abs(lattice - nearest) < 1e-6 ? nearest : std::floor(lattice);
    if (!(std::abs(index) < VoxelBlockGrid::kLargestLatticeIndex))  // also NaN
      throw MappingError("blockKeyOf: point coordinate " + numberText(point_world[axis]) +
                         " m is not finite or beyond the grid's integer range");
    key[axis] = floorDivide(static_cast<int>(index), options_.block_edge);
  }
  return key;
}

Eigen::Vector3d VoxelBlockGrid::voxelPosition(const BlockKey& key, int i, int j, int k) const {
  const int edge = options_.block_edge;
  return Eigen::Vector3d(double(key.x()) * edge + i, double(key.y()) * edge + j, double(key.z()) * edge + k) *
         options_.voxel_size_m;
}

VoxelBlock* VoxelBlockGrid::activate(const BlockKey& key, bool* created) {
  bool is_new = false;
  VoxelBlock* block = findOrAddSlot(key, &is_new);
  if (is_new) clearArrays(*block);
  if (created) *created = is_new;
  return block;
}

void VoxelBlockGrid::activateMany(const BlockKey* keys, std::size_t count, VoxelBlock** blocks,
                                  uint8_t* created) {
  std::vector<VoxelBlock*> fresh;
  for (std::size_t n = 0; n < count; ++n) {
    bool is_new = false;
    blocks[n] = findOrAddSlot(keys[n], &is_new);
    created[n] = is_new;
    if (is_new) fresh.push_back(blocks[n]);
  }
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, fresh.size(), 16),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t n = range.begin(); n != range.end(); ++n) clearArrays(*fresh[n]);
                    });
}

VoxelBlock* VoxelBlockGrid::findOrAddSlot(const BlockKey& key, bool* created) {
  Storage& storage = *storage_;
  const auto found = storage.slots.find(key);
  if (found != storage.slots.end()) return &storage.pool[found->second];
  if (options_.max_blocks != 0 && storage.slots.size() >= options_.max_blocks) return nullptr;
  uint32_t slot;
  if (!storage.free_slots.empty()) {
    slot = storage.free_slots.back();
    storage.free_slots.pop_back();
  } else {
    slot = static_cast<uint32_t>(storage.pool.size());
    storage.pool.emplace_back();
  }
  VoxelBlock& block = storage.pool[slot];
  block.key = key;
  block.changed_generation = 0;
  storage.slots.emplace(key, slot);
  *created = true;
  return &block;
}

void VoxelBlockGrid::clearArrays(VoxelBlock& block) const {
  const std::size_t voxels = static_cast<std::size_t>(voxelsPerBlock());
  block.sdf.assign(voxels, 0.0f);
  block.weight.assign(voxels, 0.0f);
  if (options_.store_intensity)
    block.intensity.assign(voxels, 0.0f);
  else
    block.intensity.clear();
}

VoxelBlock* VoxelBlockGrid::find(const BlockKey& key) {
  const auto found = storage_->slots.find(key);
  return found == storage_->slots.end() ? nullptr : &storage_->pool[found->second];
}

const VoxelBlock* VoxelBlockGrid::find(const BlockKey& key) const {
  const auto found = storage_->slots.find(key);
  return found == storage_->slots.end() ? nullptr : &storage_->pool[found->second];
}

std::size_t VoxelBlockGrid::blockCount() const { return storage_->slots.size(); }

std::size_t VoxelBlockGrid::memoryBytes() const {
  // Every pooled block holds its arrays, free ones too (they are reused).
  const std::size_t arrays = options_.store_intensity ? 3 : 2;
  const std::size_t block_bytes =
      sizeof(VoxelBlock) + arrays * sizeof(float) * static_cast<std::size_t>(voxelsPerBlock());
  return storage_->pool.size() * block_bytes + storage_->slots.bucket_count() * kBucketBytes +
         storage_->free_slots.capacity() * sizeof(uint32_t);
}

std::vector<const VoxelBlock*> VoxelBlockGrid::blocks() const {
  std::vector<const VoxelBlock*> result;
  result.reserve(storage_->slots.size());
  for (const auto& [key, slot] : storage_->slots) result.push_back(&storage_->pool[slot]);
  return result;
}

std::vector<VoxelBlock*> VoxelBlockGrid::blocks() {
  std::vector<VoxelBlock*> result;
  result.reserve(storage_->slots.size());
  for (const auto& [key, slot] : storage_->slots) result.push_back(&storage_->pool[slot]);
  return result;
}

std::vector<BlockKey> VoxelBlockGrid::blocksFartherThan(const Eigen::Vector3d& centre_world, double radius_m) const {
  if (!centre_world.allFinite() || !(radius_m >= 0.0))
    throw MappingError("blocksFartherThan needs a finite centre and a radius >= 0, got radius " +
                       numberText(radius_m));
  const double half_block = 0.5 * blockSize();
  const double radius_squared = radius_m * radius_m;
  std::vector<BlockKey> far;
  for (const auto& [key, slot] : storage_->slots) {
    const Eigen::Vector3d centre = key.cast<double>() * blockSize() + Eigen::Vector3d::Constant(half_block);
    if ((centre - centre_world).squaredNorm() > radius_squared) far.push_back(key);
  }
  return far;
}

std::size_t VoxelBlockGrid::removeBlocksFartherThan(const Eigen::Vector3d& centre_world, double radius_m,
                                                    std::vector<BlockKey>* removed) {
  const std::vector<BlockKey> far = blocksFartherThan(centre_world, radius_m);
  for (const BlockKey& key : far) remove(key);
  if (removed) removed->insert(removed->end(), far.begin(), far.end());
  return far.size();
}

bool VoxelBlockGrid::remove(const BlockKey& key) {
  const auto found = storage_->slots.find(key);
  if (found == storage_->slots.end()) return false;
  storage_->free_slots.push_back(found->second);
  storage_->slots.erase(found);
  return true;
}

void VoxelBlockGrid::clear() {
  // Gives the memory back (a reset map should not keep its peak size).
  *storage_ = Storage();
}

}  // namespace range_image_mapping::mapping
