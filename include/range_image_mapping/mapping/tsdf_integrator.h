// Projective TSDF integration of range images (paper section 4.2, eq. 8-10):
// every voxel of every block near the scan is projected with Pi into the
// range image, d = Omega(u, v) - r is truncated and averaged with a weight
// cap. No ray casting, no races: blocks are updated in parallel, each by one
// thread.
#pragma once

#include "range_image_mapping/mapping/voxel_block_grid.h"
#include "range_image_mapping/range_image.h"
#include "range_image_mapping/scan_motion.h"

#include <Eigen/Geometry>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace range_image_mapping::mapping {

struct TsdfIntegratorOptions {
  // Truncation distance; 0 = 3 voxels.
  double truncation_m = 0.0;
  // Range clip (paper: 30 m outdoors, 10 m indoors). Pixels outside never write.
  double min_range_m = 0.3;
  double max_range_m = 30.0;
  // Block activation uses every point_stride-th pixel in rows and columns.
  int point_stride = 1;
  // Running-average weight cap: old data fades once a voxel has this weight.
  float max_weight = 64.0f;
  // Optional per-sample weights: 1/r^2-like falloff past falloff_start_m, and
  // cos(incidence) from the image-domain normal. Off by default.
  bool range_weighting = false;
  double range_weighting_start_m = 10.0;
  bool incidence_weighting = false;
  // Throws MappingError naming the field (truncation below one voxel or above
  // 100 voxels, min >= max range, stride < 1, max_weight <= 0, ...).
  void validate(const VoxelBlockGridOptions& grid) const;
  double truncationFor(const VoxelBlockGridOptions& grid) const {
    return truncation_m > 0.0 ? truncation_m : 3.0 * grid.voxel_size_m;
  }
};

// Pose of a scan: T_world_lidar at the scan time (scanTime()), and the body
// twist over the sweep. With a nonzero twist and column timestamps, a voxel is
// projected into the sensor as it was when its column was measured (motion
// compensation without resampling the image); a zero twist integrates the
// scan as if it were taken at one instant.
struct ScanPose {
  Eigen::Isometry3d world_from_lidar = Eigen::Isometry3d::Identity();
  Twist twist = Twist::Zero();
};

struct IntegrationStatistics {
  std::size_t points_used = 0;       // valid pixels in range, after stride
  std::size_t blocks_touched = 0;    // blocks integrated this scan
  // New blocks kept: a new block that no voxel projection wrote to is removed again.
  std::size_t blocks_created = 0;
  std::size_t blocks_refused = 0;    // not created: the grid's max_blocks was reached
  std::size_t voxels_updated = 0;
  std::size_t blocks_removed = 0;    // deintegrate: blocks left without any observation, removed
  double activation_seconds = 0.0;   // finding / creating blocks
  double integration_seconds = 0.0;  // projecting voxels and averaging
};

// Move-only: it keeps per-thread buffers between scans, so one integrator
// integrates one scan at a time (it is parallel inside).
class TsdfIntegrator {
 public:
  // The options are checked against the grid by integrate().
  explicit TsdfIntegrator(TsdfIntegratorOptions options = {});
  ~TsdfIntegrator();
  TsdfIntegrator(TsdfIntegrator&&) noexcept;
  TsdfIntegrator& operator=(TsdfIntegrator&&) noexcept;
  const TsdfIntegratorOptions& options() const { return options_; }

  // Integrates a staggered range image. Throws MappingError for a
  // non-finite pose or twist, an image without a model, a destaggered image
  // or options that do not fit the grid; the grid is unchanged then. An image
  // without valid pixels integrates nothing. Bumps grid.nextGeneration().
  IntegrationStatistics integrate(VoxelBlockGrid& grid, const RangeImage& scan, const ScanPose& pose);
  // The checks integrate() makes first: throws MappingError naming the
  // problem (for callers that refuse a scan without an exception).
  void validate(const VoxelBlockGrid& grid, const RangeImage& scan, const ScanPose& pose) const;
  // Removes a scan integrated before with the same pose (weights subtract;
  // voxels whose weight returns to 0 become unobserved). Used to undo a scan.
  IntegrationStatistics deintegrate(VoxelBlockGrid& grid, const RangeImage& scan, const ScanPose& pose);

 private:
  IntegrationStatistics update(VoxelBlockGrid& grid, const RangeImage& scan, const ScanPose& pose,
                               float sign);
  TsdfIntegratorOptions options_;
  // Reused between scans: the keys of the blocks this scan touches.
  std::vector<BlockKey> touched_keys_;
  std::vector<VoxelBlock*> touched_blocks_;
  std::vector<ColumnMotion> column_motion_;
  // Per-thread block sets and voxel buffers, per-pixel sample weights, ...
  struct Workspace;
  std::unique_ptr<Workspace> workspace_;
};

}  // namespace range_image_mapping::mapping
