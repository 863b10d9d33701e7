// The reference a scan is registered to (scan-to-model, beyond the paper's
// frame-to-frame): the last few keyframes, deskewed to their scan times and
// kept at their odometry poses, rendered as a range image in the scan's own
// beam geometry at the predicted pose. A keyframe is renewed every
// keyframe_distance_m or keyframe_angle_rad, so the odometry chains one error
// per keyframe instead of one per scan, and the rendered image sees what any
// of the keyframes saw (surfaces the last scan missed, the far ground
// between beam rings), z-buffered nearest first as the sensor would.
#pragma once

#include "range_image_mapping/lattice_key.h"
#include "range_image_mapping/normal_map.h"

#include <Eigen/Geometry>
#include <tsl/robin_map.h>

#include <array>
#include <cstdint>
#include <deque>
#include <limits>
#include <memory>
#include <vector>

namespace range_image_mapping::registration {

struct LocalModelOptions {
  std::size_t keyframes = 4;  // kept in the model; 1 with distance and angle 0: the previous scan
  // A scan becomes a keyframe when it is this far from the newest one (0:
  // every scan does).
  double keyframe_distance_m = 0.5;
  double keyframe_angle_rad = 5.0 * M_PI / 180.0;
  // Normals of the model from the model itself: each new keyframe's points
  // get the plane of the model's points (its own and the older keyframes')
  // within this radius, so that on a sparse sensor the rings of keyframes
  // taken from other positions fill between its own; where they make no
  // plane, the keyframe's own normal stays. 0: each keyframe keeps the
  // normals computed on its own scan (chords across its beam rows, biased
  // on sparse sensors: issue 14).
  double normal_radius_m = 1.0;
  // The distance follows the scene's scale: it is raised to this share of
  // the newest keyframe's median range, up to max_keyframe_distance_m, so
  // that keyframes are about as far apart in view angle in a street as in a
  // room (a dense sensor's keyframes every 0.5 m on a car doing 0.7 m a scan
  // made every scan a keyframe and chained one error per scan). 0: off.
  double keyframe_range_share = 0.2;
  double max_keyframe_distance_m = 1.5;
};

// The least keyframe distance with a sensor: options.keyframe_distance_m,
// raised on a sensor with rows a degree or more apart to a metre per degree
// of its median beam spacing (VLP-16 2 m, HDL-32E 1.33 m; 0 stays 0: every
// scan). LocalModel::keyframeDistance raises it further with the scene.
double keyframeDistance(const LocalModelOptions& options, const LidarModel& model);

class LocalModel {
 public:
  explicit LocalModel(LocalModelOptions options = {});

  void clear();
  bool empty() const { return keyframes_.empty(); }
  std::size_t size() const { return keyframes_.size(); }
  // Pose of the newest keyframe (odometry frame); identity when empty.
  Eigen::Isometry3d newestPose() const;
  // The keyframe distance in force with the sensor model: the least one
  // (keyframeDistance(options, model)), raised to keyframe_range_share of the
  // newest keyframe's median range up to max_keyframe_distance_m (the cap
  // does not lower the least one); 0 when that is 0.
  double keyframeDistance(const LidarModel& model) const;
  // Whether a scan at odom_from_lidar, seen by model, is far enough from the
  // newest keyframe to become one (always when empty, or when the newest is
  // provisional), by keyframeDistance(model) or keyframe_angle_rad.
  bool wantsKeyframe(const Eigen::Isometry3d& odom_from_lidar, const LidarModel& model) const;
  // The newest keyframe's median range (of its finest level's points); 0 when empty.
  double newestMedianRange() const { return keyframes_.empty() ? 0.0 : keyframes_.back().median_range_m; }
  // Adds a scan at odom_from_lidar: one map per pyramid level (points and
  // normals in its lidar frame at its scan time, NaN where invalid; each
  // level's normals computed at its own stride, as the registration's target
  // pyramid has them). A provisional keyframe (not deskewed: the first after
  // a restart) is replaced by the next one added. The oldest keyframe beyond
  // `keyframes` is dropped.
  // model_normals false: the keyframe keeps its own normals whatever
  // normal_radius_m says.
  void add(const std::vector<VertexNormalMap>& levels, const Eigen::Isometry3d& odom_from_lidar, bool provisional,
           bool model_normals = true);
  bool provisional() const { return !keyframes_.empty() && keyframes_.back().provisional; }

  // The model seen from odom_from_view: for every level (stride as added),
  // one map of rows/stride x columns/stride pixels (as levelPixelIndex files
  // them) with the nearest point of that level projecting there and its
  // normal, in the view's lidar frame; NaN where nothing projects. Of the
  // points on a pixel's nearest surface, the newest keyframe's with a normal
  // wins (points without one only occlude).
  // Parallel (TBB) and deterministic.
  void render(const LidarModel& model, const Eigen::Isometry3d& odom_from_view, std::vector<VertexNormalMap>& levels) const;

  const LocalModelOptions& options() const { return options_; }

  // computeModelNormals sums the voxel moments in this many maps, in parallel.
  static constexpr std::size_t kVoxelPartitions = 8;

 private:
  struct Level {
    int stride = 1;
    std::vector<Eigen::Vector3f> points, normals;  // valid pixels; normals NaN where none
  };
  struct Keyframe {
    Eigen::Isometry3d odom_from_lidar;
    std::vector<Level> levels;
    bool provisional = false;
    double median_range_m = 0.0;  // of the finest level's points
  };
  std::vector<float> ranges_;  // add: a sample of the finest level's ranges
  std::vector<std::size_t> kept_before_chunk_;  // add: pixels kept before each chunk of a level
  // normal_radius_m > 0: the newest keyframe's normals from the model's points.
  void computeModelNormals();

  LocalModelOptions options_;
  std::deque<Keyframe> keyframes_;
  // computeModelNormals: the finest level's points of every keyframe, in the
  // newest one's frame, as moments (about the voxel's centre) per voxel, in
  // maps by partitionOf(key).
  struct VoxelMoments {
    double count = 0.0;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    Eigen::Matrix3d outer = Eigen::Matrix3d::Zero();  // sum of d d^T, lower triangle
    // Its number among its map's voxels of the newest keyframe; none (max) if not one.
    uint32_t slot = std::numeric_limits<uint32_t>::max();
  };
  using VoxelKey = LatticeKey;
  // Numbers 0..n-1 sorted by their map (a counting sort by fixed chunks, in
  // parallel): map p's in order[first[p], first[p + 1]), in increasing order.
  struct PartitionOrder {
    std::vector<uint32_t> order;
    std::array<uint32_t, kVoxelPartitions + 1> first{};
    std::vector<uint32_t> chunk_counts;
    void sort(const std::vector<uint8_t>& partitions);
  };
  using VoxelMap = tsl::robin_map<VoxelKey, VoxelMoments, LatticeKeyHash>;
  std::array<VoxelMap, kVoxelPartitions> model_voxels_;
  // Those points (all keyframes, oldest first), their voxels and maps, and
  // the points' numbers by map (map by map, each in the points' order).
  std::vector<Eigen::Vector3f> moved_points_;
  std::vector<VoxelKey> key_of_point_;
  std::vector<uint8_t> partition_of_point_;
  PartitionOrder points_by_partition_;
  // The newest keyframe's points of every level (concatenated): their
  // voxels, maps and order by map, and their voxel's slot in its map.
  std::vector<VoxelKey> newest_keys_;
  std::vector<uint8_t> newest_partitions_;
  PartitionOrder newest_by_partition_;
  std::vector<uint32_t> slot_of_point_;
  // The newest keyframe's voxels, map by map (map p's slots from
  // first_slot_[p]), and each one's plane normal (NaN where the block is no
  // plane).
  std::array<std::vector<VoxelKey>, kVoxelPartitions> newest_voxels_of_partition_;
  std::array<uint32_t, kVoxelPartitions + 1> first_slot_{};
  std::vector<VoxelKey> newest_voxels_;
  std::vector<Eigen::Vector3f> slot_normals_;
  // Per level pixel: the nearest range's bits, then the winning point's
  // number (minimums over the render's lanes); per point its pixel and range.
  mutable std::vector<std::vector<uint32_t>> nearest_, winner_;
  mutable std::vector<std::vector<uint32_t>> lane_buffers_;  // per render lane: its z-buffer, then its winners
  mutable std::vector<uint32_t> pixel_of_point_;
  mutable std::vector<float> range_of_point_;
  mutable std::vector<std::size_t> first_point_;  // per keyframe, newest first, of the level rendered
  mutable std::vector<std::size_t> first_chunk_;  // the same, of render's chunks of points
  mutable std::vector<Eigen::Isometry3f> view_from_keyframe_;  // the same order
  mutable std::vector<const Level*> level_points_;  // the same order, of the level rendered
  mutable LevelPixelTables pixel_tables_;  // of the level rendered
};

}  // namespace range_image_mapping::registration
