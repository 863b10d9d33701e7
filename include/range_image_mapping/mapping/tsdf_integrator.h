// Projective TSDF integration of range images (paper section 4.2, eq. 8-10):
// every voxel near the scan (in the cells of blocks that a return's band
// crosses) is projected with Pi into the range image, its signed distance to
// what the pixel saw is truncated and averaged with a weight cap. No ray
// casting, no races: blocks are updated in parallel, each by one thread.
//
// Departures from the paper, both measured on the simulated sequences of
// test/mapping_accuracy_test.cpp and benchmark/mapping_benchmark.cpp: the
// distance is point-to-plane by default, not eq. 9 along the ray
// (SignedDistance), and samples are weighted by cos(incidence).
#pragma once

#include "range_image_mapping/mapping/voxel_block_grid.h"
#include "range_image_mapping/normal_map.h"
#include "range_image_mapping/range_image.h"
#include "range_image_mapping/scan_motion.h"

#include <Eigen/Geometry>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace range_image_mapping::mapping {

// How the signed distance of a voxel to the surface seen by its pixel is measured.
enum class SignedDistance {
  // Paper eq. 9: d = Omega(u, v) - r, along the ray. Exact head-on; at grazing
  // incidence it is 1 / cos(incidence) times the distance to the surface, and
  // a voxel between two beam rings reads the nearest ring's range, so far
  // ground comes out as rings with gaps.
  kAlongRay,
  // Departs from eq. 9: d = n . (x - P(u, v)), the distance from the voxel x
  // to the plane through the pixel's point P with the pixel's image-domain
  // normal n (normal_map.h, facing the sensor). Exact for planar
  // surfaces at any incidence and between beam rings; eq. 9 where a pixel has
  // no normal (depth edges, thin structures). The plane stands for the
  // surface within the truncation along the ray; farther along it (up to the
  // pixel's footprint on the plane, range * pixel angle * tan(incidence),
  // where blocks are activated too) only where the pixel under the voxel's
  // foot on the plane saw that plane, so a plane does not run on past an
  // object's edge into its shadow, and only within plane_fill_m of that
  // pixel's return (the return under the voxel's foot). outdoor_car recall
  // at 3 voxels 0.91 -> 0.99.
  kPointToPlane,
};

struct TsdfIntegratorOptions {
  SignedDistance signed_distance = SignedDistance::kPointToPlane;
  // Truncation distance; 0 = 3 voxels.
  double truncation_m = 0.0;
  // Range clip (paper: 30 m outdoors, 10 m indoors). Pixels outside never write.
  double min_range_m = 0.3;
  double max_range_m = 30.0;
  // Block activation uses every point_stride-th pixel in rows and columns.
  int point_stride = 1;
  // Running-average weight cap: old data fades once a voxel has this weight.
  float max_weight = 64.0f;
  // Optional per-sample weights (a head-on sample near the sensor weighs 1):
  // 1/r^2-like falloff past range_weighting_start_m (off by default), and
  // cos(incidence) from the image-domain normal, at least 0.1 (on: F at half
  // a voxel +0.004 to +0.008 on both simulated sequences, no loss at 3 voxels).
  bool range_weighting = false;
  double range_weighting_start_m = 10.0;
  bool incidence_weighting = true;
  // A sample that puts a voxel farther in front of its pixel's surface than
  // the truncation says only "free space here" (its value is truncated to
  // +truncation), and weighs this many times a surface sample. A voxel on a
  // thin or grazing surface (a table top seen edge-on, a shelf board, a pole)
  // projects into pixels whose rays pass beside it and read the wall behind
  // in most scans; at full weight those erase it. At 0.1 what moves away
  // still fades, over a few scans (a surface sample's weight is 0.1-1 with
  // incidence weighting). 1 = every sample alike (the paper's eq. 10).
  // Measured (mapping_benchmark, 30 scans): recall at 3 voxels 0.9943 ->
  // 0.998 indoors, 0.9915 -> 0.9925 outdoors; lb_n3 mesh within 30 cm of
  // the reference map 93.7 -> 98.1 %.
  float free_space_weight = 0.1f;
  // Point-to-plane: how far from a return (along its plane) the plane may
  // stand for the surface; 0 = the truncation, so a return speaks for the
  // surface within the truncation of it across the plane as well as along
  // its normal. Where beam rings are farther apart than twice this (ground
  // seen at grazing incidence far away: 0.6 m apart 13 m from an OS1-128
  // 1.8 m up) the mesh has gaps between them, as the measurements do; a
  // large value fills the gaps with the plane (whole ground to 25 m), at
  // the price of surface nobody measured: mapping_benchmark, 30 scans, F at
  // 3 voxels indoors 0.9967 unlimited -> 0.9991 at the truncation (precision
  // 0.9950 -> 0.9999, the unmeasured floor between far rings and "curtains"
  // a plane drew across the gap behind an edge), outdoors 0.9860 -> 0.9960.
  double plane_fill_m = 0.0;
  // Incremental meshing (MeshExtractor re-meshes blocks whose
  // changed_generation is new): a block is marked only when the scan changed
  // something that can matter to its mesh: a voxel gained or lost its
  // observation, crossed mesh_min_weight (keep it equal to
  // MeshOptions::min_weight) or changed sign, or the block's voxels drifted
  // by more than mesh_tolerance_voxels (the largest change per scan, summed
  // over scans) since the block was last marked. The incremental mesh then
  // has the grid's topology, meshed from values within that tolerance of the
  // grid's; a vertex interpolated between two close values of opposite sign
  // can still move several times the tolerance. 0 marks every change (exact).
  double mesh_tolerance_voxels = 0.1;
  float mesh_min_weight = 0.0f;
  // Throws MappingError naming the field (truncation below one voxel or above
  // 100 voxels, min >= max range, stride < 1, max_weight <= 0, ...).
  void validate(const VoxelBlockGridOptions& grid) const;
  double truncationFor(const VoxelBlockGridOptions& grid) const {
    return truncation_m > 0.0 ? truncation_m : 3.0 * grid.voxel_size_m;
  }
  double planeFillFor(const VoxelBlockGridOptions& grid) const {
    return plane_fill_m > 0.0 ? plane_fill_m : truncationFor(grid);
  }
};

// Pose of a scan: T_world_lidar at the scan time, and the body twist over
// the sweep. With a nonzero twist and column timestamps, a voxel is projected
// into the sensor as it was when its column was measured (motion compensation
// without resampling the image), relative to scan_time_ns; a zero twist
// integrates the scan as if it were taken at one instant.
struct ScanPose {
  Eigen::Isometry3d world_from_lidar = Eigen::Isometry3d::Identity();
  Twist twist = Twist::Zero();
  // The time world_from_lidar refers to (scanTime()): needed with a nonzero
  // twist and column times, refused as 0 then.
  uint64_t scan_time_ns = 0;
};

struct IntegrationStatistics {
  std::size_t points_used = 0;       // valid pixels in range, after stride
  std::size_t blocks_touched = 0;    // blocks integrated this scan
  // New blocks kept: a new block that no voxel projection wrote to is removed again.
  std::size_t blocks_created = 0;
  std::size_t blocks_refused = 0;    // not created: the grid's max_blocks was reached
  std::size_t voxels_updated = 0;
  std::size_t voxels_selected = 0;   // voxels of the blocks' activated cells: those projected
  std::size_t blocks_removed = 0;    // deintegrate: blocks left without any observation, removed
  std::size_t blocks_marked = 0;     // changed_generation set: a change that matters to the mesh
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
  // normals: the scan's full-resolution normal map (stride 1, as measured,
  // not deskewed) where the caller has it already, e.g. the odometry's;
  // computed here with default options otherwise.
  IntegrationStatistics integrate(VoxelBlockGrid& grid, const RangeImage& scan, const ScanPose& pose,
                                  const VertexNormalMap* normals = nullptr);
  // The checks integrate() makes first: throws MappingError naming the
  // problem (for callers that refuse a scan without an exception).
  void validate(const VoxelBlockGrid& grid, const RangeImage& scan, const ScanPose& pose) const;
  // Removes a scan integrated before with the same pose (weights subtract;
  // voxels whose weight returns to 0 become unobserved). Used to undo a scan.
  IntegrationStatistics deintegrate(VoxelBlockGrid& grid, const RangeImage& scan, const ScanPose& pose);

 private:
  IntegrationStatistics update(VoxelBlockGrid& grid, const RangeImage& scan, const ScanPose& pose,
                               float sign, const VertexNormalMap* normals);
  TsdfIntegratorOptions options_;
  // Reused between scans: the keys of the blocks this scan creates.
  std::vector<BlockKey> touched_keys_;
  std::vector<VoxelBlock*> touched_blocks_;
  std::vector<ColumnMotion> column_motion_;
  // Per block, how far its voxels drifted (largest change per scan, summed)
  // since changed_generation was last set (mesh_tolerance_voxels > 0 only).
  struct DriftSinceMarked;
  std::unique_ptr<DriftSinceMarked> drift_;
  // Per-thread block sets and voxel buffers, per-pixel sample weights, ...
  struct Workspace;
  std::unique_ptr<Workspace> workspace_;
};

}  // namespace range_image_mapping::mapping
