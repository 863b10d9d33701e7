// KITTI odometry files: Velodyne scans (.bin), pose files and the calibration's
// Tr (velodyne -> camera 0), plus the synthetic HDL-64E intrinsics.
#pragma once

#include "range_image_mapping/lidar_intrinsics.h"
#include "range_image_mapping/point_cloud_projection.h"

#include <Eigen/Geometry>

#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::io {

// A KITTI file that is missing or malformed; what() names the file and the problem.
class KittiFormatError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Headerless little-endian float32 x, y, z, reflectance per point (metres,
// Velodyne frame: x forward, y left, z up). Unorganized, no ring field;
// intensity holds the reflectance in [0, 1].
PointCloudInput readKittiVelodyne(const std::string& path);
// The same format written: intensities empty (written as 0) or one per point.
// Throws std::invalid_argument when the sizes differ, KittiFormatError when the
// file cannot be written.
void writeKittiVelodyne(const std::string& path, const std::vector<Eigen::Vector3f>& points,
                        const std::vector<float>& intensities);

// One pose per line: 12 numbers, the row-major 3x4 [R | t] of T_world_frame.
std::vector<Eigen::Isometry3d> readKittiPoses(const std::string& path);
void writeKittiPoses(const std::string& path, const std::vector<Eigen::Isometry3d>& poses);

// The calibration file's "Tr:" line: T_camera0_velodyne (maps velodyne points
// into the camera 0 frame).
Eigen::Isometry3d readKittiVelodyneToCamera(const std::string& calibration_path);

// KITTI ground truth gives T_world_camera0; the same motion in the Velodyne
// frame is T_world_velodyne = Tr^-1 * T_world_camera0 * Tr (world = the
// Velodyne frame of the first pose).
Eigen::Isometry3d velodynePoseFromCameraPose(const Eigen::Isometry3d& camera_pose,
                                             const Eigen::Isometry3d& velodyne_to_camera);
std::vector<Eigen::Isometry3d> velodynePosesFromCameraPoses(
    const std::vector<Eigen::Isometry3d>& camera_poses,
    const Eigen::Isometry3d& velodyne_to_camera);

// Synthetic intrinsics for KITTI's Velodyne HDL-64E: 64 rows evenly spread
// from +3 deg down to -25 deg, no azimuth offsets, no beam offset. The data
// sheet says +2 to -24.8 deg, but seen from the KITTI Velodyne origin the
// upper lasers reach +3.7 deg (3.4 % of scan 94's points lie above +2.2 deg).
// Share of scan 94's points that get a pixel of their own: 80 % at 2048
// columns, 92 % at 4096 (the lasers' firings do not fall on one regular grid).
LidarIntrinsics kittiHdl64Intrinsics(int columns = 2048);

}  // namespace range_image_mapping::io
