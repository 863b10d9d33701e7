// Rigid motion of a sensor during one sweep: SE(3) exponential and logarithm
// of a body-frame twist, the scan time, and the per-column transforms that
// move each column's points to the scan time (deskew). Shared by the odometry
// (deskewing points) and the TSDF integrator (projecting voxels into a moving
// sensor), so both agree on what a twist means.
#pragma once

#include "range_image_mapping/range_image.h"

#include <Eigen/Geometry>

#include <cstdint>
#include <vector>

namespace range_image_mapping {

using Twist = Eigen::Matrix<double, 6, 1>;  // [angular rad/s, linear m/s], body frame

// SE(3) exponential: the pose reached after one unit of time at this constant
// body-frame velocity.
Eigen::Isometry3d twistExponential(const Twist& twist);
// Inverse of twistExponential(): the twist with a rotation angle in [0, pi].
// Both are exact to double precision at every angle (series near zero).
Twist twistLogarithm(const Eigen::Isometry3d& pose);

// The constant body twist that moves `previous` to `current` in dt_s seconds:
// log(previous^-1 current) / dt_s; zero when dt_s is not positive. How poses
// given at scan times (a pose file, tf) yield the motion within a sweep.
Twist twistBetween(const Eigen::Isometry3d& previous, const Eigen::Isometry3d& current, double dt_s);

// The body twist of a frame rigidly attached to the moving one:
// Ad(to_from_frame) twist, for a twist given in `frame`. E.g. the base's
// twist from the lidar's with base_from_lidar, and back with its inverse.
Twist twistInFrame(const Eigen::Isometry3d& to_from_frame, const Twist& twist);

// Which clock gives a scan its time: the pose's and the deskewed points' time
// (design.md: scan time).
enum class ScanTimeSource {
  // The first valid column's timestamp, on the sensor's clock: what the column
  // times of the deskew are measured from. Without column times, the stamp.
  kFirstValidColumn,
  // The image's stamp_ns (e.g. a header stamp), even when columns carry times.
  kStamp,
};

// The scan's time by that source; 0 when it has none.
uint64_t scanTime(const RangeImage& scan, ScanTimeSource source);

// Per column u, [R | t] = exp((t_u - t0) * twist): a point measured in the
// lidar frame at the column's time, in the lidar frame at the scan time t0.
// Columns without a timestamp get the identity. Returns false (and leaves
// `motion` untouched) when there is nothing to move: a zero twist or no column
// times.
using ColumnMotion = Eigen::Matrix<float, 3, 4>;
bool computeColumnMotion(const RangeImage& scan, uint64_t scan_time_ns, const Twist& twist,
                         std::vector<ColumnMotion>& motion);

}  // namespace range_image_mapping
