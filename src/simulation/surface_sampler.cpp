#include "range_image_mapping/simulation/surface_sampler.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace range_image_mapping::simulation {
namespace {

// Voxel indices within +-2^20 pack into 21 bits each.
constexpr int kKeyBits = 21;
constexpr int64_t kKeyOffset = int64_t{1} << (kKeyBits - 1);
constexpr double kCoarseFactor = 8.0;
// Tiles of this many seen distances are skipped at once when nothing was seen near them.
constexpr double kTileEdgeInSeenDistances = 4.0;

bool validIndex(int64_t index) { return index >= -kKeyOffset && index < kKeyOffset; }

uint64_t voxelKey(int64_t x, int64_t y, int64_t z) {
  return static_cast<uint64_t>(x + kKeyOffset) << (2 * kKeyBits) |
         static_cast<uint64_t>(y + kKeyOffset) << kKeyBits | static_cast<uint64_t>(z + kKeyOffset);
}

template <typename VoxelHits>
void addToVoxels(VoxelHits& voxels, double size, const Eigen::Vector3f& point) {
  const int64_t x = static_cast<int64_t>(std::floor(point.x() / size));
  const int64_t y = static_cast<int64_t>(std::floor(point.y() / size));
  const int64_t z = static_cast<int64_t>(std::floor(point.z() / size));
  if (!validIndex(x) || !validIndex(y) || !validIndex(z))
    throw std::invalid_argument("SeenRegion: hit (" + std::to_string(point.x()) + ", " +
                                std::to_string(point.y()) + ", " + std::to_string(point.z()) +
                                ") lies beyond 2^20 voxels of " + std::to_string(size) +
                                " m from the origin");
  ++voxels[voxelKey(x, y, z)];
}

}  // namespace

SeenRegion::SeenRegion(double seen_distance_m) : voxel_size_(seen_distance_m) {
  if (!(seen_distance_m > 0.0) || !std::isfinite(seen_distance_m))
    throw std::invalid_argument("SeenRegion: seen_distance_m " + std::to_string(seen_distance_m) +
                                " must be positive and finite");
}

void SeenRegion::addHit(const Eigen::Vector3f& point) {
  if (!point.allFinite()) return;
  addToVoxels(hits_per_voxel_, voxel_size_, point);
  addToVoxels(hits_per_coarse_voxel_, voxel_size_ * kCoarseFactor, point);
}

void SeenRegion::addHits(const std::vector<Eigen::Vector3f>& points) {
  for (const Eigen::Vector3f& point : points) addHit(point);
}

bool SeenRegion::anyVoxelWithin(const VoxelHits& voxels, double size, const Eigen::Vector3f& point,
                                float distance) {
  if (voxels.empty()) return false;
  const Eigen::Vector3d p = point.cast<double>();
  Eigen::Matrix<int64_t, 3, 1> low, high, own;
  for (int axis = 0; axis < 3; ++axis) {
    own[axis] = static_cast<int64_t>(std::floor(p[axis] / size));
    low[axis] = std::max(-kKeyOffset, static_cast<int64_t>(std::floor((p[axis] - distance) / size)));
    high[axis] = std::min(kKeyOffset - 1, static_cast<int64_t>(std::floor((p[axis] + distance) / size)));
  }
  // The point's own voxel first: inside the seen region that is the usual answer.
  if ((own.array() >= low.array()).all() && (own.array() <= high.array()).all() &&
      voxels.count(voxelKey(own.x(), own.y(), own.z())) != 0)
    return true;
  const double squared_distance = double(distance) * distance;
  for (int64_t x = low.x(); x <= high.x(); ++x) {
    const double dx = std::max({x * size - p.x(), 0.0, p.x() - (x + 1) * size});
    for (int64_t y = low.y(); y <= high.y(); ++y) {
      const double dy = std::max({y * size - p.y(), 0.0, p.y() - (y + 1) * size});
      for (int64_t z = low.z(); z <= high.z(); ++z) {
        const double dz = std::max({z * size - p.z(), 0.0, p.z() - (z + 1) * size});
        if (dx * dx + dy * dy + dz * dz <= squared_distance && voxels.count(voxelKey(x, y, z)) != 0)
          return true;
      }
    }
  }
  return false;
}

bool SeenRegion::isNear(const Eigen::Vector3f& point) const {
  return anyVoxelWithin(hits_per_voxel_, voxel_size_, point, static_cast<float>(voxel_size_));
}

bool SeenRegion::mayBeNear(const Eigen::Vector3f& centre, float radius) const {
  return anyVoxelWithin(hits_per_coarse_voxel_, voxel_size_ * kCoarseFactor, centre,
                        radius + static_cast<float>(voxel_size_));
}

double SeenRegion::tileEdge() const { return kTileEdgeInSeenDistances * voxel_size_; }

std::vector<Eigen::Vector3f> sampleSeenSurface(const TriangleMesh& mesh, const SeenRegion& seen,
                                               const SurfaceSampleOptions& options) {
  return sampleSurface(mesh, options, seen);
}

}  // namespace range_image_mapping::simulation
