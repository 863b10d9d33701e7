// The reference a scan is registered to (scan-to-model, beyond the paper's
// frame-to-frame): the last few keyframes, deskewed to their scan times and
// kept at their odometry poses, rendered as a range image in the scan's own
// beam geometry at the predicted pose. A keyframe is renewed every
// keyframe_distance_m or keyframe_angle_rad, so the odometry chains one error
// per keyframe instead of one per scan, and the rendered image sees what any
// of the keyframes saw (surfaces the last scan missed, the far ground
// between beam rings), z-buffered nearest first as the sensor would.
#pragma once

#include "range_image_mapping/normal_map.h"

#include <Eigen/Geometry>

#include <cstdint>
#include <deque>
#include <memory>
#include <vector>

namespace range_image_mapping::registration {

struct LocalModelOptions {
  std::size_t keyframes = 4;  // kept in the model; 1 with distance and angle 0: the previous scan
  // A scan becomes a keyframe when it is this far from the newest one (0:
  // every scan does).
  double keyframe_distance_m = 0.5;
  double keyframe_angle_rad = 5.0 * M_PI / 180.0;
};

class LocalModel {
 public:
  explicit LocalModel(LocalModelOptions options = {});

  void clear();
  bool empty() const { return keyframes_.empty(); }
  std::size_t size() const { return keyframes_.size(); }
  // Pose of the newest keyframe (odometry frame); identity when empty.
  Eigen::Isometry3d newestPose() const;
  // Whether a scan at odom_from_lidar is far enough from the newest keyframe
  // to become one (always when empty, or when the newest is provisional).
  bool wantsKeyframe(const Eigen::Isometry3d& odom_from_lidar) const;
  // Adds a scan at odom_from_lidar: one map per pyramid level (points and
  // normals in its lidar frame at its scan time, NaN where invalid; each
  // level's normals computed at its own stride, as the registration's target
  // pyramid has them). A provisional keyframe (not deskewed: the first after
  // a restart) is replaced by the next one added. The oldest keyframe beyond
  // `keyframes` is dropped.
  void add(const std::vector<VertexNormalMap>& levels, const Eigen::Isometry3d& odom_from_lidar, bool provisional);
  bool provisional() const { return !keyframes_.empty() && keyframes_.back().provisional; }

  // The model seen from odom_from_view: for every level (stride as added),
  // one map of rows/stride x columns/stride pixels (as levelPixelIndex files
  // them) with the nearest point of that level projecting there and its
  // normal, in the view's lidar frame; NaN where nothing projects. Of the
  // points on a pixel's nearest surface, the newest keyframe's wins.
  // Parallel (TBB) and deterministic.
  void render(const LidarModel& model, const Eigen::Isometry3d& odom_from_view, std::vector<VertexNormalMap>& levels) const;

  const LocalModelOptions& options() const { return options_; }

 private:
  struct Level {
    int stride = 1;
    std::vector<Eigen::Vector3f> points, normals;  // valid pixels with normals only
    // A coarser level's pixel (s i, s j) is the same point as the finest
    // level's pixel there: per point, that twin's number in the finest
    // level (kNoTwin where the finest has no normal there), so that the
    // render projects it once for every level.
    std::vector<uint32_t> finest_twin;
  };
  struct Keyframe {
    Eigen::Isometry3d odom_from_lidar;
    std::vector<Level> levels;
    bool provisional = false;
  };
  LocalModelOptions options_;
  std::deque<Keyframe> keyframes_;
  // Per level pixel: the nearest range's bits, then the winning point's
  // number (atomic compare-and-swap minimums); per point its pixel and range.
  mutable std::vector<std::vector<uint32_t>> nearest_, winner_;
  mutable std::vector<uint32_t> pixel_of_point_;
  mutable std::vector<float> range_of_point_;
  mutable std::vector<std::size_t> first_point_;  // per keyframe, newest first, of the level rendered
  mutable std::vector<Eigen::Isometry3f> view_from_keyframe_;  // the same order
  mutable std::vector<const Level*> level_points_;  // the same order, of the level rendered
  mutable LevelPixelTables pixel_tables_;  // of the level rendered
  // Per keyframe (render order), its points of the level rendered projected
  // (hit flags apart); the finest level's are kept for the coarser ones.
  mutable std::vector<std::vector<ProjectedPixel>> level_pixels_, finest_pixels_;
  mutable std::vector<std::vector<uint8_t>> level_hits_, finest_hits_;
  std::vector<uint32_t> finest_number_of_pixel_;  // add(): the finest level's point number per pixel
};

}  // namespace range_image_mapping::registration
