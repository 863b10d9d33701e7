#include "range_image_mapping/simulation/trajectory.h"

#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pose_file.h"
#include "seeded_random.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <stdexcept>
#include <string>

namespace range_image_mapping::simulation {
namespace {

constexpr double kDegree = M_PI / 180.0;

[[noreturn]] void throwOutOfRange(double time_s, double start, double end) {
  std::ostringstream message;
  message.precision(12);
  message << "trajectory: time " << time_s << " s is outside [" << start << ", " << end << "] s";
  throw std::out_of_range(message.str());
}

// ------------------------------------------------------------ smooth route

// A closed uniform cubic B-spline through the resampled route, followed by arc
// length. Control points every ~spacing metres keep straight stretches on the
// route and round each corner within about a third of the spacing.
class SmoothRoute {
 public:
  SmoothRoute(const std::vector<Eigen::Vector3d>& route, double control_spacing_m) {
    const std::vector<Eigen::Vector3d> corners = distinctCorners(route);
    for (std::size_t i = 0; i < corners.size(); ++i) {
      const Eigen::Vector3d& from = corners[i];
      const Eigen::Vector3d& to = corners[(i + 1) % corners.size()];
      const int pieces = std::max(1, static_cast<int>(std::ceil((to - from).norm() / control_spacing_m)));
      for (int k = 0; k < pieces; ++k) control_.push_back(from + (to - from) * (double(k) / pieces));
    }
    buildArcLengthTable();
  }

  double length() const { return length_; }

  struct Point {
    Eigen::Vector3d position;
    Eigen::Vector3d tangent;  // unit
    double curvature = 0.0;
  };
  Point at(double arc_length) const {
    const double tau = parameterOf(arc_length);
    Eigen::Vector3d derivative, second;
    Point point;
    point.position = evaluate(tau, &derivative, &second);
    const double speed = derivative.norm();
    point.tangent = derivative / speed;
    point.curvature = derivative.cross(second).norm() / (speed * speed * speed);
    return point;
  }

 private:
  static constexpr int kStepsPerSpan = 16;

  // Drops repeated points (and a repeated first point at the end), then
  // rejects what cannot be smoothed into a drivable loop.
  static std::vector<Eigen::Vector3d> distinctCorners(const std::vector<Eigen::Vector3d>& route) {
    std::vector<Eigen::Vector3d> corners;
    for (std::size_t i = 0; i < route.size(); ++i) {
      if (!route[i].allFinite())
        throw std::invalid_argument("makeTrajectory: route point " + std::to_string(i) + " is not finite");
      if (corners.empty() || (route[i] - corners.back()).norm() > 1e-6) corners.push_back(route[i]);
    }
    while (corners.size() > 1 && (corners.back() - corners.front()).norm() <= 1e-6) corners.pop_back();
    if (corners.size() < 3)
      throw std::invalid_argument("makeTrajectory: the route needs at least 3 distinct points, got " +
                                  std::to_string(corners.size()));
    const std::size_t count = corners.size();
    for (std::size_t i = 0; i < count; ++i) {
      const Eigen::Vector3d in = corners[i] - corners[(i + count - 1) % count];
      const Eigen::Vector3d out = corners[(i + 1) % count] - corners[i];
      const double turn = std::atan2(in.cross(out).norm(), in.dot(out));
      // A U-turn would make the smoothed path stop and flip its heading.
      if (turn > 170.0 * kDegree)
        throw std::invalid_argument("makeTrajectory: the route turns by " +
                                    std::to_string(turn / kDegree) + " deg at point " +
                                    std::to_string(i) + "; turns must stay below 170 deg (no U-turns)");
    }
    return corners;
  }

  // B(tau) on the closed spline, tau in [0, M) for M control points.
  Eigen::Vector3d evaluate(double tau, Eigen::Vector3d* derivative = nullptr,
                           Eigen::Vector3d* second = nullptr) const {
    const int count = static_cast<int>(control_.size());
    const double span = std::floor(tau);
    const double x = tau - span;
    const int j = ((static_cast<int>(span) % count) + count) % count;
    const Eigen::Vector3d& p0 = control_[(j + count - 1) % count];
    const Eigen::Vector3d& p1 = control_[j];
    const Eigen::Vector3d& p2 = control_[(j + 1) % count];
    const Eigen::Vector3d& p3 = control_[(j + 2) % count];
    const double x2 = x * x, x3 = x2 * x, w = 1.0 - x;
    if (derivative)
      *derivative = -0.5 * w * w * p0 + (1.5 * x2 - 2.0 * x) * p1 + (-1.5 * x2 + x + 0.5) * p2 +
                    0.5 * x2 * p3;
    if (second) *second = w * p0 + (3.0 * x - 2.0) * p1 + (1.0 - 3.0 * x) * p2 + x * p3;
    return (w * w * w * p0 + (3.0 * x3 - 6.0 * x2 + 4.0) * p1 + (-3.0 * x3 + 3.0 * x2 + 3.0 * x + 1.0) * p2 +
            x3 * p3) / 6.0;
  }

  // Arc length from tau_from to tau_to by 4-point Gauss-Legendre (the pieces
  // are a sixteenth of a span: exact to rounding for these polynomials' norms).
  double arcLength(double tau_from, double tau_to) const {
    static constexpr std::array<double, 4> kNodes = {-0.8611363115940526, -0.3399810435848563,
                                                     0.3399810435848563, 0.8611363115940526};
    static constexpr std::array<double, 4> kWeights = {0.3478548451374538, 0.6521451548625461,
                                                       0.6521451548625461, 0.3478548451374538};
    const double half = 0.5 * (tau_to - tau_from), middle = 0.5 * (tau_to + tau_from);
    double sum = 0.0;
    for (int i = 0; i < 4; ++i) {
      Eigen::Vector3d derivative;
      evaluate(middle + half * kNodes[i], &derivative);
      sum += kWeights[i] * derivative.norm();
    }
    return sum * half;
  }

  void buildArcLengthTable() {
    const int steps = static_cast<int>(control_.size()) * kStepsPerSpan;
    cumulative_.assign(steps + 1, 0.0);
    for (int k = 0; k < steps; ++k)
      cumulative_[k + 1] =
          cumulative_[k] + arcLength(double(k) / kStepsPerSpan, double(k + 1) / kStepsPerSpan);
    length_ = cumulative_.back();
  }

  // The inverse of the arc length by Newton steps from the table, to rounding
  // (a coarse inverse would put kinks into the motion).
  double parameterOf(double arc_length) const {
    double s = std::fmod(arc_length, length_);
    if (s < 0.0) s += length_;
    const auto above = std::upper_bound(cumulative_.begin(), cumulative_.end(), s);
    const int k = std::clamp(static_cast<int>(above - cumulative_.begin()) - 1, 0,
                             static_cast<int>(cumulative_.size()) - 2);
    const double tau_start = double(k) / kStepsPerSpan;
    double tau = tau_start;
    for (int iteration = 0; iteration < 8; ++iteration) {
      Eigen::Vector3d derivative;
      evaluate(tau, &derivative);
      const double step = (s - cumulative_[k] - arcLength(tau_start, tau)) / derivative.norm();
      tau += step;
      if (std::abs(step) < 1e-14) break;
    }
    return tau;
  }

  std::vector<Eigen::Vector3d> control_;
  std::vector<double> cumulative_;  // arc length at tau = k / kStepsPerSpan
  double length_ = 0.0;
};

// ------------------------------------------------------------ speed profile

struct ProfileLimits {
  double control_spacing_m;     // of the smoothed route (sets the corner radius)
  double cruise_speed;          // m/s on straight stretches
  double lateral_acceleration;  // m/s^2 in turns
  double acceleration;          // m/s^2 speeding up
  double deceleration;          // m/s^2 braking
  double path_yaw_rate;         // rad/s from following the path's turns
  double grid_spacing_m;        // of the speed profile samples
  double smoothing_m;           // the speed profile is smoothed over about this length
};

ProfileLimits limitsOf(MotionProfile profile) {
  switch (profile) {
    case MotionProfile::kCar: return {12.0, 15.0, 2.5, 1.5, 2.5, 30.0 * kDegree, 0.5, 4.0};
    case MotionProfile::kCart: return {1.0, 1.0, 0.3, 0.3, 0.5, 30.0 * kDegree, 0.05, 0.3};
    case MotionProfile::kHandheld: return {1.0, 1.4, 0.5, 0.5, 0.8, 25.0 * kDegree, 0.05, 0.3};
  }
  throw std::invalid_argument("makeTrajectory: unknown motion profile");
}

// Speed along the loop as a function of arc length: limited by the turns,
// accelerating and braking within limits, smoothed, and interpolated C1 so the
// longitudinal acceleration is continuous.
class SpeedProfile {
 public:
  SpeedProfile(const SmoothRoute& route, const ProfileLimits& limits) : length_(route.length()) {
    const int count = std::max(16, static_cast<int>(std::ceil(length_ / limits.grid_spacing_m)));
    spacing_ = length_ / count;
    std::vector<double> speed(count);
    for (int k = 0; k < count; ++k) {
      const double curvature = std::max(route.at(k * spacing_).curvature, 1e-9);
      speed[k] = std::min({limits.cruise_speed, std::sqrt(limits.lateral_acceleration / curvature),
                           limits.path_yaw_rate / curvature});
    }
    const auto at = [&](int k) -> double& { return speed[((k % count) + count) % count]; };
    // Twice around the loop, so the limits carry over the seam.
    for (int k = 1; k <= 2 * count; ++k)
      at(k) = std::min(at(k), std::sqrt(at(k - 1) * at(k - 1) + 2.0 * limits.acceleration * spacing_));
    for (int k = 2 * count - 1; k >= 0; --k)
      at(k) = std::min(at(k), std::sqrt(at(k + 1) * at(k + 1) + 2.0 * limits.deceleration * spacing_));
    // Erode, then smooth with a kernel no wider: the result stays below every limit.
    const int passes = std::max(1, static_cast<int>(std::ceil(limits.smoothing_m / spacing_)));
    std::vector<double> eroded(count);
    for (int k = 0; k < count; ++k) {
      eroded[k] = at(k);
      for (int j = 1; j <= passes; ++j) eroded[k] = std::min({eroded[k], at(k - j), at(k + j)});
    }
    for (int pass = 0; pass < passes; ++pass) {
      std::vector<double> smoothed(count);
      for (int k = 0; k < count; ++k)
        smoothed[k] = 0.25 * eroded[(k + count - 1) % count] + 0.5 * eroded[k] +
                      0.25 * eroded[(k + 1) % count];
      eroded.swap(smoothed);
    }
    nodes_ = std::move(eroded);
  }

  // Speed and d(speed)/d(arc length), Catmull-Rom between the samples.
  void at(double arc_length, double& speed, double& slope) const {
    const int count = static_cast<int>(nodes_.size());
    double position = std::fmod(arc_length, length_) / spacing_;
    if (position < 0.0) position += count;
    const int k = std::min(static_cast<int>(position), count - 1);
    const double x = position - k;
    const double p0 = nodes_[(k + count - 1) % count], p1 = nodes_[k];
    const double p2 = nodes_[(k + 1) % count], p3 = nodes_[(k + 2) % count];
    const double m1 = 0.5 * (p2 - p0), m2 = 0.5 * (p3 - p1);
    const double x2 = x * x, x3 = x2 * x;
    speed = (2 * x3 - 3 * x2 + 1) * p1 + (x3 - 2 * x2 + x) * m1 + (-2 * x3 + 3 * x2) * p2 +
            (x3 - x2) * m2;
    slope = ((6 * x2 - 6 * x) * p1 + (3 * x2 - 4 * x + 1) * m1 + (-6 * x2 + 6 * x) * p2 +
             (3 * x2 - 2 * x) * m2) / spacing_;
  }

 private:
  double length_;
  double spacing_ = 1.0;
  std::vector<double> nodes_;
};

// Arc length travelled as a function of time: ds/dt = v(s) integrated by RK4
// on a fine grid, then quintic Hermite with s, v and a = v dv/ds at the nodes,
// so s(t) is C2 (continuous acceleration) between and across them.
class ArcLengthOfTime {
 public:
  ArcLengthOfTime(const SpeedProfile& profile, double duration_s) {
    const int steps = std::max(1, static_cast<int>(std::ceil(duration_s / kStep)));
    step_ = duration_s / steps;
    const auto speed = [&](double s) {
      double v, slope;
      profile.at(s, v, slope);
      return v;
    };
    double s = 0.0;
    for (int i = 0; i <= steps; ++i) {
      double v, slope;
      profile.at(s, v, slope);
      nodes_.push_back({s, v, v * slope});
      const double k1 = speed(s), k2 = speed(s + 0.5 * step_ * k1), k3 = speed(s + 0.5 * step_ * k2),
                   k4 = speed(s + step_ * k3);
      s += step_ / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4);
    }
  }

  double at(double time_s) const {
    const int last = static_cast<int>(nodes_.size()) - 1;
    const int i = std::clamp(static_cast<int>(time_s / step_), 0, last - 1);
    const double h = step_, x = time_s / step_ - i;
    const Node& a = nodes_[i];
    const Node& b = nodes_[i + 1];
    const double x2 = x * x, x3 = x2 * x, x4 = x3 * x, x5 = x4 * x;
    return (1 - 10 * x3 + 15 * x4 - 6 * x5) * a.s + (x - 6 * x3 + 8 * x4 - 3 * x5) * h * a.v +
           (0.5 * x2 - 1.5 * x3 + 1.5 * x4 - 0.5 * x5) * h * h * a.a +
           (0.5 * x3 - x4 + 0.5 * x5) * h * h * b.a + (-4 * x3 + 7 * x4 - 3 * x5) * h * b.v +
           (10 * x3 - 15 * x4 + 6 * x5) * b.s;
  }

 private:
  static constexpr double kStep = 0.01;
  struct Node {
    double s, v, a;
  };
  double step_ = kStep;
  std::vector<Node> nodes_;
};

// ------------------------------------------------------------ disturbances

// A sum of sines with seeded frequencies and phases: smooth, bounded, and its
// rate bounded by the sum of amplitude * angular frequency.
class Sway {
 public:
  // amplitude in the channel's unit (rad or m), frequency drawn from [low, high] Hz.
  void add(SeededRandom& random, double low_hz, double high_hz, double amplitude) {
    const double angular_frequency = 2.0 * M_PI * random.uniform(low_hz, high_hz);
    waves_.push_back({amplitude, angular_frequency, random.uniform(0.0, 2.0 * M_PI)});
  }
  // The amplitude follows from the largest rate the wave may reach.
  void addWithPeakRate(SeededRandom& random, double low_hz, double high_hz, double peak_rate) {
    const double angular_frequency = 2.0 * M_PI * random.uniform(low_hz, high_hz);
    waves_.push_back({peak_rate / angular_frequency, angular_frequency, random.uniform(0.0, 2.0 * M_PI)});
  }
  // A wave locked to a given frequency (the walking step), random phase.
  void addAt(SeededRandom& random, double frequency_hz, double amplitude) {
    add(random, frequency_hz, frequency_hz, amplitude);
  }
  double at(double time_s) const {
    double value = 0.0;
    for (const Wave& wave : waves_) value += wave.amplitude * std::sin(wave.angular_frequency * time_s + wave.phase);
    return value;
  }

 private:
  struct Wave {
    double amplitude, angular_frequency, phase;
  };
  std::vector<Wave> waves_;
};

struct BodyMotion {
  Sway yaw, pitch, roll;  // rad, applied in the path frame in this order
  Sway lateral, vertical;  // m, along the path's left and the world's up
};

BodyMotion makeBodyMotion(MotionProfile profile, uint32_t seed) {
  SeededRandom random({seed, static_cast<uint64_t>(profile), 0x5741ull});
  BodyMotion body;
  switch (profile) {
    case MotionProfile::kCar:  // suspension
      body.pitch.add(random, 1.0, 2.0, 0.2 * kDegree);
      body.roll.add(random, 1.0, 2.0, 0.2 * kDegree);
      body.vertical.add(random, 1.5, 3.0, 0.005);
      break;
    case MotionProfile::kCart:  // wheels on a floor
      body.pitch.add(random, 6.0, 10.0, 0.15 * kDegree);
      body.pitch.add(random, 10.0, 15.0, 0.1 * kDegree);
      body.roll.add(random, 6.0, 10.0, 0.15 * kDegree);
      body.roll.add(random, 10.0, 15.0, 0.1 * kDegree);
      body.yaw.add(random, 4.0, 8.0, 0.1 * kDegree);
      body.vertical.add(random, 8.0, 15.0, 0.001);
      break;
    case MotionProfile::kHandheld: {
      // Looking around: peak rates add up to 145 deg/s, plus at most 25 deg/s
      // from the path, staying below 180 deg/s.
      body.yaw.addWithPeakRate(random, 0.15, 0.35, 85.0 * kDegree);
      body.yaw.addWithPeakRate(random, 0.5, 0.9, 40.0 * kDegree);
      body.yaw.addWithPeakRate(random, 1.0, 1.6, 20.0 * kDegree);
      const double step_hz = random.uniform(1.7, 2.0);
      body.pitch.add(random, 0.2, 0.5, 6.0 * kDegree);
      body.pitch.add(random, 0.8, 1.3, 2.0 * kDegree);
      body.pitch.addAt(random, step_hz, 1.0 * kDegree);
      body.roll.add(random, 0.2, 0.5, 5.0 * kDegree);
      body.roll.add(random, 0.8, 1.3, 2.0 * kDegree);
      body.roll.addAt(random, 0.5 * step_hz, 1.5 * kDegree);
      body.vertical.addAt(random, step_hz, 0.025);   // walking bob
      body.lateral.addAt(random, 0.5 * step_hz, 0.03);  // weight shifting foot to foot
      break;
    }
  }
  return body;
}

class RouteTrajectory : public Trajectory {
 public:
  RouteTrajectory(const Scene& scene, const MotionOptions& options)
      : limits_(limitsOf(options.profile)),
        route_(scene.route, limits_.control_spacing_m),
        speed_(route_, limits_),
        arc_length_(speed_, options.duration_s),
        body_(makeBodyMotion(options.profile, options.seed)),
        duration_(options.duration_s),
        height_(options.sensor_height_m) {}

  Eigen::Isometry3d pose(double time_s) const override {
    if (!(time_s >= 0.0 && time_s <= duration_)) throwOutOfRange(time_s, 0.0, duration_);
    const SmoothRoute::Point point = route_.at(arc_length_.at(time_s));
    const Eigen::Vector3d up_hint = Eigen::Vector3d::UnitZ();
    Eigen::Vector3d left = up_hint.cross(point.tangent);
    left = left.norm() > 1e-9 ? left.normalized() : Eigen::Vector3d::UnitY();
    Eigen::Matrix3d path_frame;
    path_frame << point.tangent, left, point.tangent.cross(left);
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = path_frame *
                    (Eigen::AngleAxisd(body_.yaw.at(time_s), Eigen::Vector3d::UnitZ()) *
                     Eigen::AngleAxisd(body_.pitch.at(time_s), Eigen::Vector3d::UnitY()) *
                     Eigen::AngleAxisd(body_.roll.at(time_s), Eigen::Vector3d::UnitX()))
                        .toRotationMatrix();
    pose.translation() = point.position + (height_ + body_.vertical.at(time_s)) * up_hint +
                         body_.lateral.at(time_s) * left;
    return pose;
  }
  double startTime() const override { return 0.0; }
  double endTime() const override { return duration_; }

 private:
  ProfileLimits limits_;
  SmoothRoute route_;
  SpeedProfile speed_;
  ArcLengthOfTime arc_length_;
  BodyMotion body_;
  double duration_;
  double height_;
};

// ------------------------------------------------------------ pose files

std::unique_ptr<InterpolatedTrajectory> fromStampedPoses(const std::string& path,
                                                         const std::vector<io::StampedPose>& stamped) {
  std::vector<double> times;
  std::vector<Eigen::Isometry3d> poses;
  for (const io::StampedPose& pose : stamped) {
    times.push_back(pose.time_s);
    poses.push_back(pose.pose);
  }
  try {
    return std::make_unique<InterpolatedTrajectory>(std::move(times), std::move(poses));
  } catch (const std::invalid_argument& error) {
    throw std::runtime_error("loadTrajectory: " + path + ": " + error.what());
  }
}

}  // namespace

// ------------------------------------------------------------ public

InterpolatedTrajectory::InterpolatedTrajectory(std::vector<double> times_s,
                                               std::vector<Eigen::Isometry3d> poses)
    : times_(std::move(times_s)), poses_(std::move(poses)) {
  if (poses_.empty()) throw std::invalid_argument("InterpolatedTrajectory: no poses");
  if (times_.size() != poses_.size())
    throw std::invalid_argument("InterpolatedTrajectory: " + std::to_string(times_.size()) +
                                " times for " + std::to_string(poses_.size()) + " poses");
  for (std::size_t i = 0; i < times_.size(); ++i) {
    if (!std::isfinite(times_[i]))
      throw std::invalid_argument("InterpolatedTrajectory: time " + std::to_string(i) + " is not finite");
    if (i > 0 && !(times_[i] > times_[i - 1]))
      throw std::invalid_argument("InterpolatedTrajectory: times must increase strictly, time " +
                                  std::to_string(i) + " does not");
    if (!poses_[i].matrix().allFinite())
      throw std::invalid_argument("InterpolatedTrajectory: pose " + std::to_string(i) + " is not finite");
    rotations_.push_back(Eigen::Quaterniond(poses_[i].linear()).normalized());
  }
}

Eigen::Isometry3d InterpolatedTrajectory::pose(double time_s) const {
  if (!(time_s >= times_.front() && time_s <= times_.back()))
    throwOutOfRange(time_s, times_.front(), times_.back());
  const auto above = std::upper_bound(times_.begin(), times_.end(), time_s);
  if (above == times_.end()) return poses_.back();
  const std::size_t i = static_cast<std::size_t>(above - times_.begin()) - 1;
  const double fraction = (time_s - times_[i]) / (times_[i + 1] - times_[i]);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = rotations_[i].slerp(fraction, rotations_[i + 1]).toRotationMatrix();
  pose.translation() =
      (1.0 - fraction) * poses_[i].translation() + fraction * poses_[i + 1].translation();
  return pose;
}

std::unique_ptr<Trajectory> makeTrajectory(const Scene& scene, const MotionOptions& options) {
  if (!(std::isfinite(options.duration_s) && options.duration_s > 0.0 && options.duration_s <= 3600.0))
    throw std::invalid_argument("makeTrajectory: duration_s must be within (0, 3600], got " +
                                std::to_string(options.duration_s));
  if (!std::isfinite(options.sensor_height_m))
    throw std::invalid_argument("makeTrajectory: sensor_height_m is not finite");
  return std::make_unique<RouteTrajectory>(scene, options);
}

std::unique_ptr<InterpolatedTrajectory> loadTrajectory(const std::string& path) {
  if (std::filesystem::exists(io::kittiPoseFilePaths(path).times))
    return fromStampedPoses(path, io::readPoseFile(path));
  // No times file: KITTI poses at KITTI's Velodyne rate, or else TUM.
  std::string kitti_problem;
  try {
    constexpr double kAssumedRateHz = 10.0;
    std::vector<io::StampedPose> stamped;
    for (const Eigen::Isometry3d& pose : io::readKittiPoses(path))
      stamped.push_back({stamped.size() / kAssumedRateHz, pose});
    return fromStampedPoses(path, stamped);
  } catch (const io::KittiFormatError& error) {
    kitti_problem = error.what();
  }
  try {
    return fromStampedPoses(path, io::readTumPoses(path));
  } catch (const io::PoseFileError& error) {
    throw std::runtime_error("loadTrajectory: " + path + " is neither KITTI (" + kitti_problem +
                             ") nor TUM (" + error.what() + ")");
  }
}

}  // namespace range_image_mapping::simulation
