#include "range_image_mapping/registration/lidar_odometry.h"

#include "range_image_mapping/point_arrays.h"

#include "range_image_mapping/scan_motion.h"

#include <Eigen/LU>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <sstream>

namespace range_image_mapping::registration {
namespace {

using Vector6d = Twist;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

bool isFinite(const Eigen::Isometry3d& pose) { return pose.matrix().allFinite(); }

// A product of many poses drifts off SO(3); the published quaternion must stay
// a unit one.
Eigen::Isometry3d orthonormalized(const Eigen::Isometry3d& pose) {
  Eigen::Isometry3d result = pose;
  result.linear() = Eigen::Quaterniond(pose.linear()).normalized().toRotationMatrix();
  return result;
}

std::string seconds(double value) {
  std::ostringstream text;
  text.precision(3);
  text << value << " s";
  return text.str();
}

// Classification of a pixel against the model's surface (classifyMoving),
// kept per pixel for the next scan's two-scan rules.
constexpr uint8_t kBehindModel = 1, kInFrontOfModel = 2;
// A pixel in front of the model in this scan and the last at the same pixel
// is moving from this share of moving_margin_m on: an object creeping up
// behind the car (a car following it) is taken into each new keyframe
// before it is a whole margin off the last one, and the registration
// follows it meanwhile. Static surfaces seldom lie in front of the model
// twice in one pixel once registered; a pose that lags lays them a little
// *behind* it, the side the stale rule keeps its whole margin on.
constexpr float kInFrontTwiceMarginShare = 1.0f / 3.0f;
// ... but never less than the wider gap between the pixel's beam row and its
// neighbours at the pixel's range: between a sparse sensor's rings (or a
// sensor's sparse outer rows) the model's surface is that coarse.
constexpr float kInFrontTwiceRowGaps = 1.0f;

// classifyMoving's verdicts on a point against the model's surface at its
// pixel, before the two-scan rules.
enum PointVerdict : uint8_t { kAgrees = 0, kInFrontByMargin, kInFrontByShare, kBehindByMargin };

// classifyMoving's test of one chunk of projected points (x, y, z in the
// target frame) against the target's points and normals (xyz triples, a
// full-resolution map target_columns wide): branch free over plain arrays,
// so that it vectorises (the target look-ups as gathers). A point without a
// hit, or whose pixel has no finite point and normal, agrees. The dot
// products and norms sum three terms as Eigen's do, a + (b + c).
// Cloned for AVX2 and AVX-512 (no FMA).
RANGE_IMAGE_MAPPING_SIMD_CLONES
void judgePoints(const float* x, const float* y, const float* z, const ProjectedPixel* pixels, const uint8_t* hits,
                 std::size_t count, const float* target_points, const float* target_normals, int target_columns,
                 const float* row_gap_rad, float margin, float twice_margin, uint8_t* __restrict verdicts) {
  constexpr float kLargest = std::numeric_limits<float>::max();
  for (std::size_t k = 0; k < count; ++k) {
    const int hit = hits[k];
    const int row = pixels[k].row & -hit;
    const int t = 3 * (row * target_columns + (pixels[k].column & -hit));
    const float sx = target_points[t], sy = target_points[t + 1], sz = target_points[t + 2];
    const float nx = target_normals[t], ny = target_normals[t + 1], nz = target_normals[t + 2];
    const int finite = int(std::abs(sx) <= kLargest) & int(std::abs(sy) <= kLargest) & int(std::abs(sz) <= kLargest) &
                       int(std::abs(nx) <= kLargest) & int(std::abs(ny) <= kLargest) & int(std::abs(nz) <= kLargest);
    // Normals face the sensor: positive is in front of the surface.
    const float in_front_m = nx * (x[k] - sx) + (ny * (y[k] - sy) + nz * (z[k] - sz));
    const float range_m = std::sqrt(x[k] * x[k] + (y[k] * y[k] + z[k] * z[k]));
    const int nearer = int(range_m < std::sqrt(sx * sx + (sy * sy + sz * sz)));
    const int by_margin = int(in_front_m > margin) & nearer;
    const int by_share = nearer & int(in_front_m > std::max(twice_margin, row_gap_rad[row] * range_m));
    const int behind = int(-in_front_m > margin) & (1 - nearer);
    const int verdict = by_margin * kInFrontByMargin +
                        (1 - by_margin) * (by_share * kInFrontByShare + (1 - by_share) * behind * kBehindByMargin);
    verdicts[k] = uint8_t(verdict * (hit & finite));
  }
}

// Whether each normal (xyz triples) is finite. Cloned for AVX2 and AVX-512.
constexpr std::size_t kClassifyChunk = 1024;
RANGE_IMAGE_MAPPING_SIMD_CLONES
void finiteNormals(const float* normals, std::size_t count, uint8_t* __restrict has_normal) {
  constexpr float kLargest = std::numeric_limits<float>::max();
  for (std::size_t k = 0; k < count; ++k)
    has_normal[k] = uint8_t(int(std::abs(normals[3 * k]) <= kLargest) &
                            int(std::abs(normals[3 * k + 1]) <= kLargest) &
                            int(std::abs(normals[3 * k + 2]) <= kLargest));
}

// One image row's points and normals (xyz triples) moved by their columns'
// motions: entry j of column u's [R | t] (column-major) at
// motions[j * columns + u]. Each coordinate as Eigen computes
// motion.leftCols<3>() * p + motion.col(3): the first product plus the sum
// of the other two, then the translation. Plain arrays, so that it
// vectorises; the output must not overlap the input. Cloned for AVX2 and
// AVX-512 (no fused multiply-adds).
RANGE_IMAGE_MAPPING_SIMD_CLONES
void moveRow(const float* points, const float* normals, const float* motions, std::size_t columns,
             float* __restrict moved_points, float* __restrict moved_normals) {
  for (std::size_t u = 0; u < columns; ++u) {
    const float px = points[3 * u], py = points[3 * u + 1], pz = points[3 * u + 2];
    const float nx = normals[3 * u], ny = normals[3 * u + 1], nz = normals[3 * u + 2];
    for (std::size_t axis = 0; axis < 3; ++axis) {
      const float r0 = motions[axis * columns + u], r1 = motions[(3 + axis) * columns + u];
      const float r2 = motions[(6 + axis) * columns + u], t = motions[(9 + axis) * columns + u];
      moved_points[3 * u + axis] = r0 * px + (r1 * py + r2 * pz) + t;
      moved_normals[3 * u + axis] = r0 * nx + (r1 * ny + r2 * nz);
    }
  }
}

// With normals from the model, the source's pixels without a normal of their
// own (a sparse sensor's ground) pair with the model's planes.
RegistrationOptions registrationOptions(const OdometryOptions& options) {
  RegistrationOptions registration = options.registration;
  if (options.model.normal_radius_m > 0.0) registration.pair_source_without_normals = true;
  return registration;
}

}  // namespace

LidarOdometry::LidarOdometry(OdometryOptions options)
    : options_(std::move(options)), icp_(registrationOptions(options_)), model_(options_.model) {
  if (!(options_.max_time_gap_s > 0.0))
    throw std::invalid_argument("odometry: max_time_gap_s must be positive, not " +
                                std::to_string(options_.max_time_gap_s));
  if (!(options_.max_condition_number > 1.0))
    throw std::invalid_argument("odometry: max_condition_number must be above 1, not " +
                                std::to_string(options_.max_condition_number));
  if (options_.deskew_passes < 0)
    throw std::invalid_argument("odometry: deskew_passes must not be negative, not " +
                                std::to_string(options_.deskew_passes));
  if (!(options_.deskew_convergence_rad >= 0.0) || !(options_.deskew_convergence_m >= 0.0))
    throw std::invalid_argument("odometry: deskew convergence thresholds must not be negative");
  if (!(options_.moving_margin_m >= 0.0) || !std::isfinite(options_.moving_margin_m) ||
      !(options_.moving_warning_share > 0.0 && options_.moving_warning_share <= 1.0) ||
      !(options_.min_inlier_share >= 0.0 && options_.min_inlier_share <= 1.0))
    throw std::invalid_argument("odometry: moving_margin_m must be finite and >= 0 (0: off) and "
                                "moving_warning_share within (0, 1], min_inlier_share within [0, 1]");
  const std::pair<const char*, double> limits[] = {
      {"max_speed_mps", options_.max_speed_mps},
      {"max_angular_rate_radps", options_.max_angular_rate_radps},
      {"max_acceleration_mps2", options_.max_acceleration_mps2},
      {"velocity_decay_time_s", options_.velocity_decay_time_s}};
  for (const auto& [name, value] : limits)
    if (!(value >= 0.0) || !std::isfinite(value))
      throw std::invalid_argument(std::string("odometry: ") + name + " must be finite and not negative (0: off), not " +
                                  std::to_string(value));
}

void LidarOdometry::reset() {
  pose_ = target_pose_ = Eigen::Isometry3d::Identity();
  twist_.setZero();
  model_.clear();
  has_target_ = false;
  velocity_known_ = false;
  last_stamp_ns_ = 0;
  trusted_pose_.setIdentity();
  trusted_stamp_ns_ = 0;
  trusted_twist_.setZero();
}

OdometryUpdate LidarOdometry::process(const RangeImage& scan) {
  return process(scan, scanTime(scan, ScanTimeSource::kFirstValidColumn));
}

OdometryUpdate LidarOdometry::process(const RangeImage& input, uint64_t scan_time_ns) {
  const auto started = std::chrono::steady_clock::now();
  OdometryUpdate update;
  // Nothing non-finite ever leaves: a step that would give one is undone.
  const Eigen::Isometry3d previous_pose = pose_, previous_target_pose = target_pose_;
  const Twist previous_twist = twist_;
  const auto finish = [&]() {
    if (!isFinite(pose_) || !twist_.allFinite()) {
      pose_ = previous_pose;
      target_pose_ = previous_target_pose;
      twist_ = previous_twist;
      update.degenerate = true;
      update.warning += std::string(update.warning.empty() ? "" : "; ") +
                        "non-finite pose or velocity: step undone, previous pose kept";
    }
    if (!update.covariance.allFinite()) update.covariance.setIdentity();
    update.pose = pose_;
    update.angular_velocity = twist_.head<3>();
    update.linear_velocity = twist_.tail<3>();
    update.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    return update;
  };
  const auto skip = [&](const std::string& why) {
    update.skipped = true;
    update.warning = why + ": scan skipped";
    return finish();
  };

  // Scans that cannot be registered leave everything as it was.
  if (!input.model || input.rows() == 0 || input.columns() == 0 || input.range.empty())
    return skip("empty range image");
  if (input.range.size() != std::size_t(input.rows()) * input.columns())
    return skip("range image with " + std::to_string(input.range.size()) + " ranges for a " +
                std::to_string(input.rows()) + " x " + std::to_string(input.columns()) + " model");
  const RangeImage& scan = input.column_order == ColumnOrder::kStaggered ? input : (staggered_ = input.staggered());
  if (std::none_of(scan.range.begin(), scan.range.end(), isValidRange))
    return skip("range image without a single valid range");
  const uint64_t stamp = scan_time_ns;
  update.stamp_ns = stamp;

  if (!has_target_) {
    restart(scan, stamp);
    update.reset = true;
    update.keyframe = true;
    update.restart = RestartReason::kFirstScan;
    return finish();
  }
  if (stamp == last_stamp_ns_) return skip("same stamp as the previous scan (" + std::to_string(stamp) + " ns)");
  if (stamp < last_stamp_ns_ ||
      double(stamp - last_stamp_ns_) * 1e-9 > options_.max_time_gap_s) {
    update.warning = stamp < last_stamp_ns_
                         ? "time went back by " + seconds(double(last_stamp_ns_ - stamp) * 1e-9)
                         : seconds(double(stamp - last_stamp_ns_) * 1e-9) + " since the previous scan (more than " +
                               seconds(options_.max_time_gap_s) + ")";
    update.warning += ": odometry restarted from the current pose";
    update.restart = stamp < last_stamp_ns_ ? RestartReason::kTimeWentBack : RestartReason::kTimeGap;
    restart(scan, stamp);
    update.reset = true;
    update.keyframe = true;
    return finish();
  }
  const double dt = double(stamp - last_stamp_ns_) * 1e-9;
  // The registered motion, from the last trusted pose (the previous one
  // unless that step fell back to the prior).
  const double since_trusted_s = double(stamp - trusted_stamp_ns_) * 1e-9;
  const auto motionSinceTrusted = [&](const Eigen::Isometry3d& target_from_current) {
    return twistBetween(trusted_pose_, target_pose_ * target_from_current, since_trusted_s);
  };

  // Constant-velocity prior, the model rendered where it puts the scan, the
  // deskewed source registered to it.
  const Vector6d prior_twist = options_.constant_velocity_prior ? twist_ : Vector6d::Zero();
  const Eigen::Isometry3d prior_step = twistExponential(dt * prior_twist);  // T_previous_current
  target_pose_ = orthonormalized(pose_ * prior_step);
  model_.render(*scan.model, target_pose_, rendered_);
  icp_.setTarget(scan.model, rendered_);
  const Eigen::Isometry3d guess = Eigen::Isometry3d::Identity();  // T_target_current
  computeVertexNormalMap(scan, 1, normalsFor(options_.registration, *scan.model), measured_);
  icp_.setSource(sourceWithoutMoving());
  // The source is deskewed inside the registration: each column moved by
  // exp((t - t0) twist) before the pose (none for a zero twist or a scan
  // without column times).
  // Every step at the finest level asks for the motions; they are computed
  // again only when the deskew twist has changed.
  static const std::vector<ColumnMotion> kNoMotion;
  bool motion_computed = false, has_motion = false;
  Vector6d motion_twist;
  const auto columnMotion = [&](const Vector6d& twist) -> const std::vector<ColumnMotion>& {
    if (!motion_computed || twist != motion_twist) {
      has_motion = computeColumnMotion(scan, stamp, twist, column_motion_);
      motion_twist = twist;
      motion_computed = true;
    }
    return has_motion ? column_motion_ : kNoMotion;
  };
  Vector6d deskew_twist = options_.deskew ? prior_twist : Vector6d::Zero();
  // The prior's twist is one step late: wrong where the motion changes (a
  // turn's start, vibration), and the source deskewed with it warped. So
  // the finest level alternates Gauss-Newton steps with deskews by the
  // velocity the current pose implies, and the pose and the deskew converge
  // together: registering to convergence after every deskew took three to
  // four steps per deskew, twice the steps in all for the same poses. The
  // velocity is measured once a step is small (the pose fits the current
  // deskew to within kMeasurableScale times the convergence thresholds):
  // from a pose still far from that, it is wrong enough that a few passes
  // end worse than none. The measured velocity overshoots the true one,
  // opposite to the deskew error and by about half of it (the registration
  // fits the scan's average warp), so the next deskew blends it with the
  // one used: plain substitution oscillates and converges slowly,
  // extrapolation diverges. Only against a deskewed model: a source
  // deskewed to a target that is not (the first scan after a restart) would
  // be registered to a different shape.
  constexpr double kMeasuredTwistShare = 0.6;
  constexpr double kMeasurableScale = 100.0;
  const std::size_t finest = options_.registration.strides.size() - 1;
  RegistrationResult result;
  const bool column_times = scan.column_timestamp_ns.size() == std::size_t(scan.columns());
  if (!options_.deskew || options_.deskew_passes == 0 || !column_times || model_.provisional()) {
    result = icp_.alignSource(guess, {}, columnMotion(deskew_twist));
  } else {
    LevelSchedule coarse;
    coarse.end_level = finest;
    result = icp_.alignSource(guess, coarse, columnMotion(deskew_twist));
    LevelSchedule step;
    step.first_level = finest;
    step.max_iterations = 1;
    const auto below = [&](const Vector6d& change, double scale) {
      return change.head<3>().norm() < scale * options_.deskew_convergence_rad &&
             change.tail<3>().norm() < scale * options_.deskew_convergence_m;
    };
    int passes = 0;
    bool measurable = false;
    const int max_steps = options_.registration.iterations[finest] + 2 * options_.deskew_passes;
    for (int k = 0; k < max_steps && isFinite(result.target_from_source); ++k) {
      const bool redeskewed = measurable && passes < options_.deskew_passes;
      if (redeskewed) {
        const Vector6d measured_twist = motionSinceTrusted(result.target_from_source);
        deskew_twist = kMeasuredTwistShare * measured_twist + (1.0 - kMeasuredTwistShare) * deskew_twist;
        ++passes;
      }
      const Eigen::Isometry3d before = result.target_from_source;
      const int iterations = result.iterations;
      const int passed_over = result.levels_passed_over;
      result = icp_.alignSource(before, step, columnMotion(deskew_twist));
      result.iterations += iterations;
      result.levels_passed_over += passed_over;
      if (result.inliers < options_.min_inliers) break;  // degenerate: the check below falls back
      const Vector6d change = twistLogarithm(before.inverse() * result.target_from_source);
      // Settled: a deskew that no longer moves the pose, or the passes spent
      // and the pose converged on the last one.
      if (below(change, 1.0) && (redeskewed || passes == options_.deskew_passes)) break;
      measurable = below(change, kMeasurableScale);
    }
  }
  update.inliers = result.inliers;
  update.iterations = result.iterations;
  update.levels_passed_over = result.levels_passed_over;
  update.every_coarse_level_passed_over = finest > 0 && std::size_t(result.levels_passed_over) >= finest;
  update.condition_number = result.condition_number;
  update.residual_rms_m = result.residual_rms_m;

  std::string degeneracy;
  if (!isFinite(result.target_from_source))
    degeneracy = "registration gave a non-finite pose";
  else if (result.inliers < options_.min_inliers)
    degeneracy = std::to_string(result.inliers) + " pairs (fewer than " + std::to_string(options_.min_inliers) + ")";
  else if (!(result.condition_number <= options_.max_condition_number))
    degeneracy = "condition number " + std::to_string(result.condition_number) + " (above " +
                 std::to_string(options_.max_condition_number) + ")";
  // A registration that breaks the platform's limits followed something other
  // than the static world, or a wrong minimum: not trusted.
  Twist registered_twist = Twist::Zero();
  if (degeneracy.empty()) {
    registered_twist = motionSinceTrusted(result.target_from_source);
    const std::string limit = physicalLimitBroken(registered_twist, since_trusted_s);
    if (!limit.empty()) {
      update.limit_exceeded = true;
      update.warning = "registration not trusted, " + limit + ": motion prior used";
    }
  }
  Eigen::Isometry3d target_from_current = result.target_from_source;
  if (isFinite(result.target_from_source)) {
    update.prior_difference_m = result.target_from_source.translation().norm();  // the guess is the identity
    update.prior_difference_rad = Eigen::AngleAxisd(result.target_from_source.linear()).angle();
  }
  if (!degeneracy.empty() || update.limit_exceeded) {
    update.degenerate = true;
    if (!degeneracy.empty()) update.warning = "degenerate registration, " + degeneracy + ": motion prior used";
    target_from_current = guess;
    if (options_.velocity_decay_time_s > 0.0) twist_ *= std::exp(-dt / options_.velocity_decay_time_s);
  } else {
    const std::size_t degrees_of_freedom = std::max<std::size_t>(result.inliers, 7) - 6;
    const double variance = result.residual_rms_m * result.residual_rms_m * double(result.inliers) /
                            double(degrees_of_freedom);
    const Eigen::FullPivLU<Matrix6d> hessian(result.hessian);
    if (hessian.isInvertible()) {
      const Matrix6d covariance = variance * hessian.inverse();
      if (covariance.allFinite()) update.covariance = 0.5 * (covariance + covariance.transpose());
    }
  }
  if (!update.degenerate) {
    twist_ = registered_twist;
    velocity_known_ = true;
  }
  pose_ = orthonormalized(target_pose_ * target_from_current);
  last_stamp_ns_ = stamp;
  if (!update.degenerate && isFinite(pose_) && twist_.allFinite()) {  // else finish() undoes the step
    trusted_pose_ = pose_;
    trusted_stamp_ns_ = stamp;
    trusted_twist_ = twist_;
  }

  // The next target: this scan deskewed with the velocity just estimated.
  const bool deskewed = options_.deskew && computeColumnMotion(scan, stamp, twist_, column_motion_);
  if (deskewed)
    moveColumns(measured_, deskewed_);
  else
    deskewed_ = measured_;
  // The pixels the registration may pair: with a normal, or, where the
  // model's normals pair them too, every pixel with a point.
  const bool pairs_without_normals = icp_.pairsSourceWithoutNormals();
  update.valid_pixels = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, deskewed_.points.size(), 16384), std::size_t(0),
      [&](const tbb::blocked_range<std::size_t>& block, std::size_t count) {
        for (std::size_t i = block.begin(); i < block.end(); ++i)
          count += deskewed_.points[i].allFinite() && (pairs_without_normals || deskewed_.normals[i].allFinite());
        return count;
      },
      std::plus<>());
  moving_.assign(deskewed_.points.size(), 0);
  stale_.assign(deskewed_.points.size(), 0);
  if (update.degenerate) model_disagreement_.clear();
  if (!update.degenerate) {
    update.moving_pixels = classifyMoving(*scan.model, target_from_current);
    const double share = update.valid_pixels ? double(update.moving_pixels) / double(update.valid_pixels) : 0.0;
    if (share > options_.moving_warning_share) {
      update.suspect = true;
      std::ostringstream text;
      text.precision(2);
      text << "moving objects fill " << 100.0 * share
           << " % of the scan: the registration may follow them; their pixels are left out of the model and the map";
      update.warning += std::string(update.warning.empty() ? "" : "; ") + text.str();
    }
    if (update.inlierShare() < options_.min_inlier_share) {
      update.suspect = true;
      std::ostringstream text;
      text.precision(2);
      text << "only " << 100.0 * update.inlierShare()
           << " % of the scan's pixels paired with the model: pose suspect (the scene changed, a wrong match, or a "
              "sensor model that does not fit the data)";
      update.warning += std::string(update.warning.empty() ? "" : "; ") + text.str();
    }
  }
  if (update.every_coarse_level_passed_over) {
    // Not a failure by itself (the finest level registered), but the motion
    // the prior missed had only the full-resolution gate to be captured in.
    update.warning += std::string(update.warning.empty() ? "" : "; ") +
                      "every coarse level had fewer than min_coarse_pairs pairs and was passed over: only full "
                      "resolution registered (check the sensor model, or strides too coarse for its rows)";
  }
  // A suspect pose must not look as certain as a good one to whoever fuses
  // it (the odometry message's covariance).
  constexpr double kSuspectCovarianceScale = 100.0;
  if (update.suspect) update.covariance *= kSuspectCovarianceScale;
  // A step that fell back to the prior has an uncertain pose: the model waits
  // for a registered one, unless it has nothing deskewed yet.
  update.keyframe_distance_m = model_.keyframeDistance(*scan.model);
  if ((!update.degenerate || model_.provisional()) && model_.wantsKeyframe(pose_, *scan.model)) {
    addKeyframe(scan, deskewed);
    update.keyframe = true;
  }
  return finish();
}

std::string LidarOdometry::physicalLimitBroken(const Twist& twist, double dt_s) const {
  const auto text = [](double value, double limit, const char* unit, const char* name) {
    std::ostringstream out;
    out.precision(3);
    out << value << " " << unit << " (above " << name << " " << limit << " " << unit << ")";
    return out.str();
  };
  if (!twist.allFinite()) return "non-finite motion";
  const double speed = twist.tail<3>().norm(), rate = twist.head<3>().norm();
  if (options_.max_speed_mps > 0.0 && speed > options_.max_speed_mps)
    return "speed " + text(speed, options_.max_speed_mps, "m/s", "max_speed");
  if (options_.max_angular_rate_radps > 0.0 && rate > options_.max_angular_rate_radps)
    return "angular rate " + text(rate, options_.max_angular_rate_radps, "rad/s", "max_angular_rate");
  if (options_.max_acceleration_mps2 > 0.0 && velocity_known_) {
    const double acceleration = (twist.tail<3>() - trusted_twist_.tail<3>()).norm() / dt_s;
    if (acceleration > options_.max_acceleration_mps2)
      return "acceleration " + text(acceleration, options_.max_acceleration_mps2, "m/s^2", "max_acceleration");
  }
  return {};
}

// A keyframe that should have been deskewed with a measured velocity and
// could not be (the first scans after a restart) is replaced by the next one.
bool LidarOdometry::provisional(const RangeImage& scan) const {
  return options_.deskew && !velocity_known_ && scan.column_timestamp_ns.size() == std::size_t(scan.columns());
}

void LidarOdometry::restart(const RangeImage& scan, uint64_t stamp_ns) {
  twist_.setZero();
  velocity_known_ = false;
  if (!isFinite(pose_)) pose_.setIdentity();  // never restart from a non-finite pose
  computeVertexNormalMap(scan, 1, normalsFor(options_.registration, *scan.model), measured_);
  deskewed_ = measured_;
  moving_.assign(measured_.points.size(), 0);
  stale_.assign(measured_.points.size(), 0);
  model_disagreement_.clear();
  model_.clear();
  addKeyframe(scan, false);
  target_pose_ = pose_;
  last_stamp_ns_ = stamp_ns;
  trusted_pose_ = pose_;
  trusted_stamp_ns_ = stamp_ns;
  trusted_twist_.setZero();
  has_target_ = true;
}

// Objects that moved in the last scan are left out of this one's source:
// those that keep pace with the sensor (traffic alongside) stay in the same
// pixels, others move a few; the mask is grown by kMovingGrowth pixels. So are
// the last scan's stale pixels: where a vehicle pulls ahead they are on its
// rear, and paired with the model's older copy of it they hold the scan back.
const VertexNormalMap& LidarOdometry::sourceWithoutMoving() {
  constexpr int kMovingGrowth = 2;
  const std::size_t size = measured_.points.size();
  const auto marked = [&](std::size_t i) { return moving_[i] || stale_[i]; };
  if (moving_.size() != size || stale_.size() != size) return measured_;
  std::size_t first = 0;
  while (first < size && !marked(first)) ++first;
  if (first == size) return measured_;
  const int rows = measured_.rows, columns = measured_.columns;
  // The copy in parallel, then the few marked pixels' neighbourhoods cleared.
  source_.rows = rows;
  source_.columns = columns;
  source_.stride = measured_.stride;
  source_.points.resize(size);
  source_.normals.resize(size);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, size, 16384), [&](const tbb::blocked_range<std::size_t>& block) {
    std::copy(measured_.points.begin() + block.begin(), measured_.points.begin() + block.end(),
              source_.points.begin() + block.begin());
    std::copy(measured_.normals.begin() + block.begin(), measured_.normals.begin() + block.end(),
              source_.normals.begin() + block.begin());
  });
  for (int row = int(first / std::size_t(columns)); row < rows; ++row)
    for (int column = 0; column < columns; ++column) {
      if (!marked(std::size_t(row) * columns + column)) continue;
      for (int r = std::max(0, row - kMovingGrowth); r <= std::min(rows - 1, row + kMovingGrowth); ++r)
        for (int c = column - kMovingGrowth; c <= column + kMovingGrowth; ++c) {
          const std::size_t i = std::size_t(r) * columns + std::size_t((c + columns) % columns);
          source_.points[i].setConstant(std::numeric_limits<float>::quiet_NaN());
          source_.normals[i].setConstant(std::numeric_limits<float>::quiet_NaN());
        }
    }
  return source_;
}

std::size_t LidarOdometry::classifyMoving(const LidarModel& model, const Eigen::Isometry3d& target_from_current) {
  const VertexNormalMap& target = icp_.targetLevel(options_.registration.strides.size() - 1);
  if (!(options_.moving_margin_m > 0.0) || model_.provisional() || target.stride != 1) {
    model_disagreement_.clear();
    return 0;
  }
  const Eigen::Isometry3f transform = target_from_current.cast<float>();
  const float margin = float(options_.moving_margin_m);
  const float twice_margin = kInFrontTwiceMarginShare * margin;
  const std::vector<double>& altitude = model.intrinsics().altitude_rad;
  std::vector<float> row_gap_rad(altitude.size(), 0.0f);
  for (std::size_t row = 1; row < altitude.size(); ++row) {
    const float gap = kInFrontTwiceRowGaps * float(std::abs(altitude[row] - altitude[row - 1]));
    row_gap_rad[row] = std::max(row_gap_rad[row], gap);
    row_gap_rad[row - 1] = std::max(row_gap_rad[row - 1], gap);
  }
  // A stale pixel's surface faces the way the model's does: the same surface
  // moved away, not an edge that uncovers something behind it.
  constexpr float kStaleNormalCosine = 0.9f;
  constexpr uint8_t kInFrontOnce = 2;  // in moving_ until the two-scan rule below decides
  const std::size_t size = deskewed_.points.size();
  constexpr std::size_t kChunk = kClassifyChunk;
  // Pixels in a reused buffer: a ProjectedPixel array on the stack is
  // zeroed on every chunk.
  projected_.resize(size);
  const std::size_t moving = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, size, kChunk), std::size_t(0),
      [&](const tbb::blocked_range<std::size_t>& block, std::size_t count) {
        // Projected in chunks (projectMany): several times faster than one by one.
        alignas(32) float moved[3][kChunk], x[kChunk], y[kChunk], z[kChunk];
        std::size_t pixel_of[kChunk];
        uint8_t has_normal[kChunk], hits[kChunk], verdicts[kChunk];
        for (std::size_t first = block.begin(); first < block.end(); first += kChunk) {
          const std::size_t end = std::min(block.end(), first + kChunk);
          ProjectedPixel* pixels = &projected_[first];
          // Every pixel moved, then those with a normal kept.
          transformToArrays(deskewed_.points[first].data(), end - first, transform.matrix().data(), moved[0],
                            moved[1], moved[2]);
          finiteNormals(deskewed_.normals[first].data(), end - first, has_normal);
          std::size_t n = 0;
          for (std::size_t k = 0; k < end - first; ++k) {
            x[n] = moved[0][k];
            y[n] = moved[1][k];
            z[n] = moved[2][k];
            pixel_of[n] = first + k;
            n += has_normal[k];
          }
          model.projectMany(x, y, z, n, pixels, hits);
          judgePoints(x, y, z, pixels, hits, n, target.points.data()->data(), target.normals.data()->data(),
                      target.columns, row_gap_rad.data(), margin, twice_margin, verdicts);
          for (std::size_t k = 0; k < n; ++k) {
            if (verdicts[k] == kAgrees) continue;
            if (verdicts[k] == kInFrontByMargin) {
              moving_[pixel_of[k]] = 1;
              ++count;
            } else if (verdicts[k] == kInFrontByShare) {
              moving_[pixel_of[k]] = kInFrontOnce;  // moving if it was in the last scan too (below)
            } else if (target.normals[levelPixelIndex(target, pixels[k])].dot(transform.linear() *
                                                                               deskewed_.normals[pixel_of[k]]) >
                       kStaleNormalCosine) {
              stale_[pixel_of[k]] = 1;  // behind the model; stale if it was in the last scan too (below)
            }
          }
        }
        return count;
      },
      std::plus<>());
  // Stale only when behind the model in this scan and the last one at the
  // same pixel: a vehicle pulling ahead stays in its pixels, while the
  // uncovered edges of static objects move across the image with the sensor.
  // The same two-scan rule for pixels a little in front of the model.
  if (model_disagreement_.size() != size) model_disagreement_.assign(size, 0);
  const std::size_t moving_twice = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, size, 16384), std::size_t(0),
      [&](const tbb::blocked_range<std::size_t>& block, std::size_t count) {
        for (std::size_t i = block.begin(); i < block.end(); ++i) {
          const uint8_t now = (stale_[i] ? kBehindModel : 0) | (moving_[i] ? kInFrontOfModel : 0);
          stale_[i] = stale_[i] && (model_disagreement_[i] & kBehindModel);
          if (moving_[i] == kInFrontOnce) {
            moving_[i] = (model_disagreement_[i] & kInFrontOfModel) ? 1 : 0;
            count += moving_[i];
          }
          model_disagreement_[i] = now;
        }
        return count;
      },
      std::plus<>());
  return moving + moving_twice;
}

// The scan's pyramid, each level's normals at its own stride (the paper's
// coarse levels), deskewed as deskewed_ is, into the model at pose_.
void LidarOdometry::addKeyframe(const RangeImage& scan, bool deskewed) {
  const std::vector<int>& strides = options_.registration.strides;
  keyframe_levels_.resize(strides.size());
  const bool any_moving = std::find(moving_.begin(), moving_.end(), uint8_t(1)) != moving_.end();
  for (std::size_t level = 0; level < strides.size(); ++level) {
    VertexNormalMap& map = keyframe_levels_[level];
    if (strides[level] == 1) {
      map = deskewed_;
    } else {
      computeVertexNormalMap(scan, strides[level], normalsFor(options_.registration, *scan.model), map);
      if (deskewed) moveColumns(map, map);
    }
    if (!any_moving) continue;
    // A level pixel is the full-resolution pixel (s i, s j).
    const int s = map.stride;
    for (int row = 0; row < map.rows; ++row)
      for (int column = 0; column < map.columns; ++column)
        if (moving_[std::size_t(row * s) * deskewed_.columns + std::size_t(column * s)]) {
          map.points[std::size_t(row) * map.columns + column].setConstant(std::numeric_limits<float>::quiet_NaN());
          map.normals[std::size_t(row) * map.columns + column].setConstant(std::numeric_limits<float>::quiet_NaN());
        }
  }
  // Where the scan's normals are checked in line (a sparse sensor's), the
  // ground has its own and the model's planes, fitted across keyframes'
  // rings, would only bring back the tilt the check removes.
  model_.add(keyframe_levels_, pose_, provisional(scan),
             !(normalsFor(options_.registration, *scan.model).max_chord_offset_m > 0.0f));
}

// Each column's points and normals, measured at the column's time, moved into
// the lidar frame at the scan time: p0 = exp((t - t0) * twist) * p. Pixel
// (i, j) of a level of stride s is full-resolution column s * j.
void LidarOdometry::moveColumns(const VertexNormalMap& measured, VertexNormalMap& moved) const {
  if (&moved == &measured) {  // moveRow's output must not overlap its input
    const VertexNormalMap copy = measured;
    moveColumns(copy, moved);
    return;
  }
  moved.rows = measured.rows;
  moved.columns = measured.columns;
  moved.stride = measured.stride;
  moved.points.resize(measured.points.size());
  moved.normals.resize(measured.normals.size());
  // The level columns' motions as 12 arrays, one entry per column.
  const std::size_t columns = std::size_t(measured.columns);
  constexpr int kMotionFloats = ColumnMotion::SizeAtCompileTime;
  std::vector<float> motions(kMotionFloats * columns);
  for (std::size_t u = 0; u < columns; ++u)
    for (int j = 0; j < kMotionFloats; ++j) motions[j * columns + u] = column_motion_[u * measured.stride].data()[j];
  tbb::parallel_for(tbb::blocked_range<int>(0, measured.rows), [&](const tbb::blocked_range<int>& rows) {
    for (int v = rows.begin(); v < rows.end(); ++v) {
      const std::size_t first = std::size_t(v) * columns;
      moveRow(measured.points[first].data(), measured.normals[first].data(), motions.data(), columns,
              moved.points[first].data(), moved.normals[first].data());
    }
  });
}

}  // namespace range_image_mapping::registration
