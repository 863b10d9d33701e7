// Scan-to-model LiDAR odometry on range images, beyond the paper's
// frame-to-frame: each scan is registered to the local model (recent deskewed
// keyframes rendered at the predicted pose), with a constant-velocity prior,
// per-column deskew, degeneracy fallback, physical limits, covariance and
// resets on time jumps.
#pragma once

#include "range_image_mapping/registration/local_model.h"
#include "range_image_mapping/registration/projective_icp.h"
#include "range_image_mapping/scan_motion.h"

#include <Eigen/Geometry>

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace range_image_mapping::registration {

struct OdometryOptions {
  RegistrationOptions registration;
  bool deskew = true;
  bool constant_velocity_prior = true;
  // At the finest level, at most this many times the source is deskewed
  // again with the velocity the current pose implies (blended with the
  // previous deskew's), between single Gauss-Newton steps, until a deskew
  // no longer moves the pose; once they are spent the pose converges on the
  // last deskew. 0: deskewed with the previous step's velocity only. Scans
  // settle in 4-7 passes (fast handheld motion up to 13); 3 already gives
  // the converged poses on the simulated presets.
  int deskew_passes = 10;
  // ... "no longer moves": a step below these. Each pass shrinks the step
  // about threefold, so what is left is a fraction of them, far below the
  // drift; every finest step costs a full-resolution pass over the scan.
  double deskew_convergence_rad = 2e-5;
  double deskew_convergence_m = 2e-4;
  // Degenerate when the hessian's condition number exceeds this or fewer pairs
  // than min_inliers remain: the motion prior is used instead, and reported.
  double max_condition_number = 1e6;
  std::size_t min_inliers = 200;
  // The reference: model.keyframes recent keyframes, one renewed every
  // keyframe_distance_m or keyframe_angle_rad (keyframes 1 and both 0: the
  // previous scan, the paper's frame-to-frame).
  LocalModelOptions model;
  // A scan more than this after the previous one, or before it, resets the odometry.
  double max_time_gap_s = 1.0;
  // Physical limits of the platform. A registration whose motion breaks one
  // (a registration that followed a moving object, or jumped to a wrong
  // minimum) is not trusted: the motion prior is used, and said. 0 turns a
  // limit off. The defaults admit a car at 180 km/h braking at 3 g and a
  // sensor swung by hand at a turn per second; config/*.yaml narrow them.
  double max_speed_mps = 50.0;
  double max_angular_rate_radps = 2.0 * M_PI;
  // Of the linear velocity between two trusted steps; not checked on the
  // first step after a restart, whose velocity is unknown.
  double max_acceleration_mps2 = 30.0;
  // On a step that fell back to the prior the velocity decays as
  // exp(-dt / velocity_decay_time_s), so that a long run of degenerate scans
  // comes to rest instead of carrying one velocity for ever. 0: kept as is.
  double velocity_decay_time_s = 1.0;
  // Moving objects: after registration, a pixel whose point lies this far in
  // front of the model's surface (along the surface normal, towards the
  // sensor: in space the keyframes saw empty) is moving; so is one a third
  // of this in front (at least its beam row's gap at its range) in this
  // scan and the last at the same pixel (an object creeping up, taken into
  // each keyframe before it is a whole margin off). Moving pixels are
  // left out of keyframes, so the model (and the map, through the pipeline)
  // keeps the static world; a scan with more than moving_warning_share of
  // its pixels moving is reported. A pixel this far behind the model's
  // surface, facing the same way, in this scan and the last, is stale: the
  // surface the keyframes saw there has moved away (the rear of a vehicle
  // pulling ahead); it is left out of the next registration only (what it
  // sees may be the static world uncovered). 0: no classification.
  double moving_margin_m = 0.3;
  double moving_warning_share = 0.3;
  // A registration that pairs fewer than this share of the scan's pixels
  // with the model is reported as suspect (the scene changed, a wrong
  // match, the wrong sensor model).
  double min_inlier_share = 0.2;
};

// Why a scan started a new odometry.
enum class RestartReason {
  kNone,
  kFirstScan,     // the first scan, or the first after reset()
  kTimeWentBack,  // the scan is older than the previous one (a bag loop, a clock step)
  kTimeGap,       // more than max_time_gap_s since the previous scan
};

struct OdometryUpdate {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // T_odom_lidar at the scan time
  // Of the registration T_target_scan (the target: the model rendered at the
  // predicted pose), as a perturbation exp(delta) T_target_scan in the
  // target's lidar frame, order [rotation, translation]:
  // the inverse hessian scaled by the residual variance. Identity (1 rad^2,
  // 1 m^2: unknown) on a reset, a skipped or a degenerate scan.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();
  Eigen::Vector3d linear_velocity = Eigen::Vector3d::Zero();   // lidar frame, m/s
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();  // lidar frame, rad/s
  uint64_t stamp_ns = 0;     // scan time: the pose's and the deskewed points' time
  std::size_t inliers = 0;
  std::size_t valid_pixels = 0;  // source pixels the registration may pair (a point, and a normal unless model normals pair it)
  std::size_t moving_pixels = 0;  // of them, classified as moving
  // How far the registration moved the scan from the motion prior's pose
  // (the constant-velocity prediction): large where the motion changed or
  // the registration followed something else.
  double prior_difference_m = 0.0;
  double prior_difference_rad = 0.0;
  // The keyframe distance in force for this scan (LocalModel::keyframeDistance,
  // with the newest keyframe's scene scale), and whether it became a keyframe.
  double keyframe_distance_m = 0.0;
  bool keyframe = false;
  double inlierShare() const { return valid_pixels ? double(inliers) / double(valid_pixels) : 0.0; }
  double movingShare() const { return valid_pixels ? double(moving_pixels) / double(valid_pixels) : 0.0; }
  int iterations = 0;
  // Coarse pyramid levels passed over for want of pairs
  // (RegistrationOptions::min_coarse_pairs): the finer levels had to capture
  // the motion from the prior alone.
  int levels_passed_over = 0;
  bool every_coarse_level_passed_over = false;  // ... all of them: said in `warning`
  double condition_number = 0.0;  // of the last hessian
  double residual_rms_m = 0.0;
  bool degenerate = false;   // the motion prior was used (degenerate or untrusted registration)
  bool limit_exceeded = false;  // ... because the registration broke a physical limit
  // Registered, but the health figures say the pose may be wrong (few pixels
  // paired, moving objects fill much of the scan): said in `warning`.
  bool suspect = false;
  bool reset = false;        // this scan started a new odometry: see restart
  RestartReason restart = RestartReason::kNone;
  bool skipped = false;      // the scan was not used (empty, all invalid, same stamp)
  std::string warning;       // why a scan was skipped, reset or degenerate; empty if none
  double seconds = 0.0;      // wall time of this step
};

// Scan time: the image's stamp_ns, or its first valid column's timestamp when
// the stamp is 0. Each column's points are moved to that time with the
// constant-velocity motion T(t) = exp((t - t0) * twist) (body-frame twist of
// the last registered step, then refined: see deskew_passes); columns without
// a timestamp are left in place.
// After registration the scan is deskewed again with the new velocity, and
// joins the local model when it is a keyframe; the model is rendered at each
// scan's predicted pose (points filed under the pixels they project to, their
// coordinates kept exact).
class LidarOdometry {
 public:
  explicit LidarOdometry(OdometryOptions options = {});
  // Never returns a non-finite pose, velocity or covariance: bad scans
  // (empty, all invalid, identical, out of order) are reported in `warning`
  // and leave the pose unchanged. A scan before the previous one or more than
  // max_time_gap_s after it restarts the odometry from the current pose
  // (velocity zero, new target), which is always finite.
  // scan_time_ns: the time the pose refers to and the column times are
  // measured from (scanTime(); the pipeline's scan-time source).
  OdometryUpdate process(const RangeImage& scan, uint64_t scan_time_ns);
  // With the first valid column's time (ScanTimeSource::kFirstValidColumn).
  OdometryUpdate process(const RangeImage& scan);
  // Forgets everything: the next scan starts at the identity.
  void reset();
  const Eigen::Isometry3d& pose() const { return pose_; }
  const OdometryOptions& options() const { return options_; }
  // The last used scan's points and normals, deskewed to its scan time (lidar
  // frame, NaN where invalid); e.g. for publishing the deskewed cloud.
  const VertexNormalMap& deskewedScan() const { return deskewed_; }
  // The same scan's points and normals as measured (full resolution, each
  // column in the lidar frame at its own time): what the map integrates, so
  // the normals are computed once per scan for both.
  const VertexNormalMap& measuredScan() const { return measured_; }
  // Per full-resolution pixel of the last used scan (staggered, row-major):
  // 1 where it was classified as moving (see moving_margin_m), else 0.
  const std::vector<uint8_t>& movingPixels() const { return moving_; }

 private:
  void restart(const RangeImage& scan, uint64_t stamp_ns);
  // Which physical limit a registered motion breaks ("" if none): the motion
  // since the last trusted step, over dt_s, against that step's velocity for
  // the acceleration.
  std::string physicalLimitBroken(const Twist& twist, double dt_s) const;
  void moveColumns(const VertexNormalMap& measured, VertexNormalMap& moved) const;
  bool provisional(const RangeImage& scan) const;
  // Marks moving_ and stale_ from deskewed_ registered at target_from_current
  // against the rendered model; returns how many are moving.
  std::size_t classifyMoving(const LidarModel& model, const Eigen::Isometry3d& target_from_current);
  void addKeyframe(const RangeImage& scan, bool deskewed);

  OdometryOptions options_;
  ProjectiveIcp icp_;
  Eigen::Isometry3d pose_ = Eigen::Isometry3d::Identity();       // T_odom_lidar, last scan
  Eigen::Isometry3d target_pose_ = Eigen::Isometry3d::Identity();  // T_odom_target: where the model was rendered
  LocalModel model_;
  Eigen::Matrix<double, 6, 1> twist_ = Eigen::Matrix<double, 6, 1>::Zero();  // [angular, linear], body frame
  bool has_target_ = false;
  bool velocity_known_ = false;  // twist_ was measured since the last restart
  uint64_t last_stamp_ns_ = 0;
  // The last trusted step: registered motion is measured from its pose over
  // the time since, so that steps which fell back to the prior (which drifts
  // from the sensor) do not make a right registration look like a jump.
  Eigen::Isometry3d trusted_pose_ = Eigen::Isometry3d::Identity();
  uint64_t trusted_stamp_ns_ = 0;
  Eigen::Matrix<double, 6, 1> trusted_twist_ = Eigen::Matrix<double, 6, 1>::Zero();
  // Reused buffers: the scan's points as measured, deskewed, and the target.
  VertexNormalMap measured_, deskewed_;
  std::vector<ColumnMotion> column_motion_;  // per column: [R | t] to the scan time
  std::vector<VertexNormalMap> rendered_;  // the model's levels at the predicted pose
  std::vector<VertexNormalMap> keyframe_levels_;
  std::vector<uint8_t> moving_;
  std::vector<uint8_t> stale_;  // behind the model's surface now and in the last scan (see moving_margin_m)
  // The last classified scan's pixels behind (kBehindModel) or in front of
  // (kInFrontOfModel) the model's surface, for the two-scan rules.
  std::vector<uint8_t> model_disagreement_;
  std::vector<ProjectedPixel> projected_;  // classifyMoving: the scan's pixels in the model
  VertexNormalMap source_;  // measured_ without the last scan's moving and stale pixels
  const VertexNormalMap& sourceWithoutMoving();
  RangeImage staggered_;  // destaggered input, re-staggered
};

}  // namespace range_image_mapping::registration
