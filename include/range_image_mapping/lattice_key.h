// Integer lattice coordinates (voxels, blocks, cells) and their hash, shared
// by the layers that keep sparse grids: the TSDF's blocks (mapping) and the
// local model's voxel moments (registration).
#pragma once

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>

namespace range_image_mapping {

using LatticeKey = Eigen::Vector3i;

struct LatticeKeyHash {
  std::size_t operator()(const LatticeKey& key) const {
    // Large primes (Teschner et al. spatial hashing), mixed as 64 bits.
    return std::size_t(uint64_t(int64_t(key.x())) * 73856093ull ^ uint64_t(int64_t(key.y())) * 19349669ull ^
                       uint64_t(int64_t(key.z())) * 83492791ull);
  }
};

}  // namespace range_image_mapping
