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

// Lexicographic order (x, then y, then z): the one order sorted key lists
// (meshes, block queues, ties between blocks) are kept in.
inline bool latticeKeyLess(const LatticeKey& a, const LatticeKey& b) {
  if (a.x() != b.x()) return a.x() < b.x();
  if (a.y() != b.y()) return a.y() < b.y();
  return a.z() < b.z();
}

}  // namespace range_image_mapping
