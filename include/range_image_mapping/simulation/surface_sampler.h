// The ground-truth surface for reconstruction metrics: a mesh sampled densely
// (range_image_mapping::sampleSurface), restricted to what the sensor actually
// saw (so recall is not charged for walls no ray ever reached). Written with
// io::writePlyPointCloud.
#pragma once

#include "range_image_mapping/surface_sampling.h"

#include <tsl/robin_map.h>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace range_image_mapping::simulation {

// The seen part of a scene, as voxels holding noise-free ray hits. A point is
// near the seen region when a voxel holding a hit lies within seen_distance of
// it (voxel edge = seen_distance): every point within seen_distance of a hit is
// near, and no point farther than (1 + sqrt 3) * seen_distance from every hit.
class SeenRegion : public SurfaceRegion {
 public:
  // Throws std::invalid_argument for a distance that is not positive and finite.
  explicit SeenRegion(double seen_distance_m);

  // World coordinates; non-finite points (no return) are skipped. Throws
  // std::invalid_argument for a point beyond +-2^20 voxels of the origin.
  void addHit(const Eigen::Vector3f& point);
  void addHits(const std::vector<Eigen::Vector3f>& points);

  bool isNear(const Eigen::Vector3f& point) const override;
  // Cheap test for a whole patch: false when no hit lies within radius +
  // seen_distance of centre (true does not promise one does).
  bool mayBeNear(const Eigen::Vector3f& centre, float radius) const override;
  // Tiles of a few seen distances: large unseen patches are skipped at once.
  double tileEdge() const override;

  double seenDistance() const { return voxel_size_; }
  std::size_t voxelCount() const { return hits_per_voxel_.size(); }

 private:
  // The map keeps the low bits of the hash, and packed voxel keys of one plane
  // share them: mix every bit in (the SplitMix64 finaliser).
  struct VoxelKeyHash {
    std::size_t operator()(uint64_t key) const {
      key = (key ^ (key >> 30)) * 0xBF58476D1CE4E5B9ull;
      key = (key ^ (key >> 27)) * 0x94D049BB133111EBull;
      return static_cast<std::size_t>(key ^ (key >> 31));
    }
  };
  using VoxelHits = tsl::robin_map<uint64_t, uint32_t, VoxelKeyHash>;  // packed key -> hits

  // Voxel (grid of edge size) holding a hit within distance of point.
  static bool anyVoxelWithin(const VoxelHits& voxels, double size, const Eigen::Vector3f& point,
                             float distance);

  double voxel_size_;
  VoxelHits hits_per_voxel_;
  // The same at kCoarseFactor times the edge, to skip large unseen patches fast.
  VoxelHits hits_per_coarse_voxel_;
};

// The samples near the seen region only; the work grows with the seen area,
// not the scene's.
std::vector<Eigen::Vector3f> sampleSeenSurface(const TriangleMesh& mesh, const SeenRegion& seen,
                                               const SurfaceSampleOptions& options);

}  // namespace range_image_mapping::simulation
