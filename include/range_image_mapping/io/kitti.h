// KITTI odometry files: Velodyne scans (.bin), pose files and the calibration's
// Tr (velodyne -> camera 0); the HDL-64E intrinsics are the sensor catalog's.
#pragma once

#include "range_image_mapping/lidar_intrinsics.h"
#include "range_image_mapping/point_cloud_projection.h"
#include "range_image_mapping/sensor_catalog.h"

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

// KITTI's Velodyne HDL-64E (the sensor catalog's HDL-64E, sensor_catalog.h).
using range_image_mapping::kittiHdl64Intrinsics;

}  // namespace range_image_mapping::io
