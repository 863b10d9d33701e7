// Generated motion (smoothness and limits measured by finite differences) and
// pose files (KITTI with and without times, TUM), interpolated.
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/simulation/trajectory.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>

namespace range_image_mapping::simulation {
namespace {

constexpr double kDegree = M_PI / 180.0;

// A rectangle loop on flat ground: what the scene generator's routes look like.
Scene rectangleScene(double length, double width) {
  Scene scene;
  scene.route = {{0, 0, 0}, {length, 0, 0}, {length, width, 0}, {0, width, 0}};
  return scene;
}

double distanceToRoute(const Scene& scene, const Eigen::Vector3d& point) {
  double best = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < scene.route.size(); ++i) {
    const Eigen::Vector2d a = scene.route[i].head<2>();
    const Eigen::Vector2d b = scene.route[(i + 1) % scene.route.size()].head<2>();
    const double length_squared = (b - a).squaredNorm();
    const double t = length_squared > 0 ? std::clamp((point.head<2>() - a).dot(b - a) / length_squared, 0.0, 1.0) : 0.0;
    best = std::min(best, (point.head<2>() - (a + t * (b - a))).norm());
  }
  return best;
}

double heading(const Eigen::Isometry3d& pose) { return std::atan2(pose.linear()(1, 0), pose.linear()(0, 0)); }

// Finite-difference statistics over poses sampled every millisecond.
struct MotionStatistics {
  double max_horizontal_speed = 0, max_horizontal_acceleration = 0, max_acceleration_step = 0;
  double max_yaw_rate = 0, max_angular_velocity_step = 0, max_route_distance = 0;
  double max_height_error = 0, max_heading_to_velocity = 0, max_step = 0;
  std::vector<double> speeds;
};

MotionStatistics measure(const Trajectory& trajectory, const Scene& scene, double height) {
  constexpr double dt = 1e-3;
  const int count = static_cast<int>(std::floor((trajectory.endTime() - trajectory.startTime()) / dt));
  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i <= count; ++i) poses.push_back(trajectory.pose(trajectory.startTime() + i * dt));
  MotionStatistics statistics;
  Eigen::Vector3d previous_acceleration = Eigen::Vector3d::Zero();
  Eigen::Vector3d previous_angular_velocity = Eigen::Vector3d::Zero();
  for (int i = 1; i + 1 <= count; ++i) {
    const Eigen::Vector3d p0 = poses[i - 1].translation(), p1 = poses[i].translation(),
                          p2 = poses[i + 1].translation();
    const Eigen::Vector3d velocity = (p2 - p0) / (2 * dt);
    const Eigen::Vector3d acceleration = (p2 - 2 * p1 + p0) / (dt * dt);
    const double speed = velocity.head<2>().norm();
    statistics.speeds.push_back(speed);
    statistics.max_step = std::max(statistics.max_step, (p2 - p1).norm());
    statistics.max_horizontal_speed = std::max(statistics.max_horizontal_speed, speed);
    statistics.max_horizontal_acceleration =
        std::max(statistics.max_horizontal_acceleration, acceleration.head<2>().norm());
    if (i > 1)
      statistics.max_acceleration_step =
          std::max(statistics.max_acceleration_step, (acceleration - previous_acceleration).norm());
    previous_acceleration = acceleration;
    const double yaw_rate = std::remainder(heading(poses[i + 1]) - heading(poses[i - 1]), 2 * M_PI) / (2 * dt);
    statistics.max_yaw_rate = std::max(statistics.max_yaw_rate, std::abs(yaw_rate));
    const Eigen::AngleAxisd turn(poses[i - 1].linear().transpose() * poses[i + 1].linear());
    const Eigen::Vector3d angular_velocity = turn.axis() * turn.angle() / (2 * dt);
    if (i > 1)
      statistics.max_angular_velocity_step = std::max(
          statistics.max_angular_velocity_step, (angular_velocity - previous_angular_velocity).norm());
    previous_angular_velocity = angular_velocity;
    statistics.max_route_distance = std::max(statistics.max_route_distance, distanceToRoute(scene, p1));
    statistics.max_height_error = std::max(statistics.max_height_error, std::abs(p1.z() - height));
    if (speed > 1.0) {
      const Eigen::Vector3d forward = poses[i].linear().col(0);
      statistics.max_heading_to_velocity = std::max(
          statistics.max_heading_to_velocity,
          std::acos(std::clamp(forward.head<2>().normalized().dot(velocity.head<2>().normalized()), -1.0, 1.0)));
    }
  }
  return statistics;
}

TEST(Trajectory, CarDrivesUpTo15MetresPerSecondSlowingIntoTurnsSmoothly) {
  const Scene scene = rectangleScene(300, 150);
  MotionOptions options;
  options.profile = MotionProfile::kCar;
  options.duration_s = 60.0;
  const auto trajectory = makeTrajectory(scene, options);
  const MotionStatistics s = measure(*trajectory, scene, options.sensor_height_m);
  EXPECT_LE(s.max_horizontal_speed, 15.0 + 1e-6);
  EXPECT_GE(s.max_horizontal_speed, 14.5);  // reaches cruising speed on the straights
  EXPECT_LE(s.max_horizontal_acceleration, 4.0);
  // Continuous acceleration: no step above what a bounded jerk gives in 1 ms.
  EXPECT_LE(s.max_acceleration_step, 0.2);
  EXPECT_LE(s.max_yaw_rate, 31.0 * kDegree);  // the profile's 30 deg/s, sampled every 0.5 m
  EXPECT_GE(s.max_yaw_rate, 20.0 * kDegree);  // it does turn
  EXPECT_LE(s.max_angular_velocity_step, 0.01);
  EXPECT_LE(s.max_route_distance, 3.5);  // corners rounded, never far off the street
  EXPECT_LE(s.max_height_error, 0.006);  // sensor height plus suspension
  EXPECT_LE(s.max_heading_to_velocity, 0.1 * kDegree);  // heading follows the tangent
  // Slows into the turns: the slowest moment is a corner, well below cruising speed.
  EXPECT_LT(*std::min_element(s.speeds.begin(), s.speeds.end()), 6.0);
  // Starts at route[0], already moving along the first leg.
  EXPECT_LT((trajectory->pose(0).translation() - Eigen::Vector3d(0, 0, 1.8)).norm(), 3.0);
}

TEST(Trajectory, CartRollsAtWalkingPaceWithSmallVibration) {
  const Scene scene = rectangleScene(20, 8);
  MotionOptions options;
  options.profile = MotionProfile::kCart;
  options.sensor_height_m = 1.0;
  options.duration_s = 60.0;
  const auto trajectory = makeTrajectory(scene, options);
  const MotionStatistics s = measure(*trajectory, scene, options.sensor_height_m);
  EXPECT_LE(s.max_horizontal_speed, 1.0 + 1e-6);
  EXPECT_GE(s.max_horizontal_speed, 0.95);
  EXPECT_LE(s.max_yaw_rate, 36.0 * kDegree);  // path turns plus vibration
  EXPECT_LE(s.max_route_distance, 0.35);
  EXPECT_LE(s.max_height_error, 0.0011);
  EXPECT_LE(s.max_step, 1.0e-3 * 1.1);
  // Vibration tilts the cart by a fraction of a degree, not more.
  double max_tilt = 0;
  for (double t = 0; t < 10; t += 0.01)
    max_tilt = std::max(max_tilt, std::acos(trajectory->pose(t).linear()(2, 2)));
  EXPECT_GT(max_tilt, 0.05 * kDegree);
  EXPECT_LT(max_tilt, 0.5 * kDegree);
}

TEST(Trajectory, HandheldTurnsFastBelow180DegreesPerSecondWithoutJumps) {
  const Scene scene = rectangleScene(20, 8);
  MotionOptions options;
  options.profile = MotionProfile::kHandheld;
  options.sensor_height_m = 1.5;
  options.duration_s = 60.0;
  for (uint32_t seed : {1u, 2u, 3u}) {
    options.seed = seed;
    const auto trajectory = makeTrajectory(scene, options);
    const MotionStatistics s = measure(*trajectory, scene, options.sensor_height_m);
    EXPECT_LE(s.max_yaw_rate, 180.0 * kDegree) << "seed " << seed;
    EXPECT_GE(s.max_yaw_rate, 100.0 * kDegree) << "seed " << seed;
    // Sway reaches ~11 rad/s^2 (0.011 rad/s per ms); a jump would stand out.
    EXPECT_LE(s.max_angular_velocity_step, 0.02) << "seed " << seed;
    EXPECT_LE(s.max_horizontal_speed, 1.4 + 0.2) << "seed " << seed;  // walking plus sway
    EXPECT_GE(s.max_horizontal_speed, 1.3) << "seed " << seed;
    EXPECT_LE(s.max_acceleration_step, 0.1) << "seed " << seed;  // bob and sway: ~0.05
    EXPECT_LE(s.max_route_distance, 0.4) << "seed " << seed;
    EXPECT_LE(s.max_height_error, 0.03) << "seed " << seed;  // walking bob
    EXPECT_GE(s.max_height_error, 0.015) << "seed " << seed;
  }
}

// The procedural scenes keep their clutter a placement margin away from the
// route (0.3 m outdoors, 0.15 m indoors, scene generator): the smoothed motion
// must stay within it, or the sensor could pass through parked cars or doors.
TEST(Trajectory, StaysOnTheRoutesOfGeneratedScenes) {
  struct Case {
    SceneKind kind;
    MotionProfile profile;
    double margin;
  };
  for (const Case& c : {Case{SceneKind::kOutdoor, MotionProfile::kCar, 0.3},
                        Case{SceneKind::kIndoor, MotionProfile::kCart, 0.15},
                        Case{SceneKind::kIndoor, MotionProfile::kHandheld, 0.15}}) {
    SceneOptions scene_options;
    scene_options.kind = c.kind;
    scene_options.extent_m = c.kind == SceneKind::kOutdoor ? 150.0 : 30.0;
    const Scene scene = generateScene(scene_options);
    MotionOptions options;
    options.profile = c.profile;
    options.duration_s = 60.0;
    const auto trajectory = makeTrajectory(scene, options);
    double worst = 0.0;
    for (double t = 0.0; t <= options.duration_s; t += 0.01)
      worst = std::max(worst, distanceToRoute(scene, trajectory->pose(t).translation()));
    EXPECT_LT(worst, c.margin) << "profile " << static_cast<int>(c.profile);
  }
}

TEST(Trajectory, SameSeedSamePosesOtherSeedOtherSway) {
  const Scene scene = rectangleScene(20, 8);
  MotionOptions options;
  options.profile = MotionProfile::kHandheld;
  options.duration_s = 5.0;
  const auto first = makeTrajectory(scene, options);
  const auto again = makeTrajectory(scene, options);
  options.seed = 2;
  const auto other = makeTrajectory(scene, options);
  double largest_difference = 0;
  for (double t = 0; t <= 5.0; t += 0.05) {
    ASSERT_TRUE(first->pose(t).matrix() == again->pose(t).matrix()) << "t = " << t;
    largest_difference = std::max(largest_difference, (first->pose(t).matrix() - other->pose(t).matrix()).norm());
  }
  EXPECT_GT(largest_difference, 0.1);
}

TEST(Trajectory, FollowsSlopesAndRejectsBadInput) {
  Scene scene = rectangleScene(100, 40);
  for (Eigen::Vector3d& point : scene.route) point.z() = 0.05 * point.x();  // a 5 % slope
  MotionOptions options;
  options.duration_s = 10.0;
  const auto trajectory = makeTrajectory(scene, options);
  const Eigen::Isometry3d pose = trajectory->pose(3.0);  // on the first leg, climbing
  EXPECT_NEAR(pose.translation().z(), 0.05 * pose.translation().x() + 1.8, 0.01);
  EXPECT_NEAR(pose.linear()(2, 0), std::sin(std::atan(0.05)), 2e-3);  // x axis tilts up the slope
  EXPECT_THROW(trajectory->pose(-0.01), std::out_of_range);
  EXPECT_THROW(trajectory->pose(10.01), std::out_of_range);
  EXPECT_NO_THROW(trajectory->pose(10.0));

  Scene bad;
  bad.route = {{0, 0, 0}, {10, 0, 0}, {10, 0, 0}, {0, 0, 0}};
  EXPECT_THROW(makeTrajectory(bad, options), std::invalid_argument);  // 2 distinct points
  bad.route = {{0, 0, 0}, {10, 0, 0}, {10, 10, 0}, {10.1, 0.1, 0}};
  try {
    makeTrajectory(bad, options);
    FAIL() << "expected an error for a U-turn";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("U-turn"), std::string::npos) << error.what();
  }
  bad.route = {{0, 0, 0}, {10, 0, 0}, {10, NAN, 0}};
  EXPECT_THROW(makeTrajectory(bad, options), std::invalid_argument);
  options.duration_s = 0.0;
  EXPECT_THROW(makeTrajectory(scene, options), std::invalid_argument);
}

class PoseFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    directory_ = std::filesystem::temp_directory_path() /
                 ("rim_trajectory_test_" + std::to_string(::getpid()));
    std::filesystem::create_directories(directory_);
  }
  void TearDown() override { std::filesystem::remove_all(directory_); }
  std::string path(const std::string& name) const { return (directory_ / name).string(); }
  void write(const std::string& name, const std::string& text) const { std::ofstream(path(name)) << text; }

  std::vector<Eigen::Isometry3d> twoPoses() const {
    Eigen::Isometry3d first = Eigen::Isometry3d::Identity(), second = Eigen::Isometry3d::Identity();
    first.translation() = Eigen::Vector3d(1, 2, 3);
    second.translation() = Eigen::Vector3d(3, 2, 1);
    second.linear() = Eigen::AngleAxisd(90 * kDegree, Eigen::Vector3d(0, 1, 1).normalized()).toRotationMatrix();
    return {first, second};
  }
  void expectHalfway(const Trajectory& trajectory, double time) const {
    const Eigen::Isometry3d halfway = trajectory.pose(time);
    EXPECT_TRUE(halfway.translation().isApprox(Eigen::Vector3d(2, 2, 2), 1e-9));
    const Eigen::AngleAxisd rotation(halfway.linear());
    EXPECT_NEAR(rotation.angle(), 45 * kDegree, 1e-7);  // slerp: half the angle, same axis
    EXPECT_TRUE(rotation.axis().isApprox(Eigen::Vector3d(0, 1, 1).normalized(), 1e-7));
  }

  std::filesystem::path directory_;
};

TEST_F(PoseFileTest, KittiWithoutTimesIsTenHertz) {
  io::writeKittiPoses(path("poses.txt"), twoPoses());
  const auto trajectory = loadTrajectory(path("poses.txt"));
  EXPECT_EQ(trajectory->startTime(), 0.0);
  EXPECT_DOUBLE_EQ(trajectory->endTime(), 0.1);
  EXPECT_TRUE(trajectory->pose(0.1).isApprox(twoPoses()[1], 1e-8));
  expectHalfway(*trajectory, 0.05);
}

TEST_F(PoseFileTest, KittiTakesTimesFromTheFileNextToIt) {
  io::writeKittiPoses(path("gt.txt"), twoPoses());
  write("gt_times.txt", "12.5\n14.5\n");
  const auto trajectory = loadTrajectory(path("gt.txt"));
  EXPECT_EQ(trajectory->startTime(), 12.5);
  EXPECT_EQ(trajectory->endTime(), 14.5);
  expectHalfway(*trajectory, 13.5);
  write("gt_times.txt", "12.5\n");
  EXPECT_THROW(loadTrajectory(path("gt.txt")), std::runtime_error);
  write("gt_times.txt", "12.5\n12.5\n");
  EXPECT_THROW(loadTrajectory(path("gt.txt")), std::runtime_error);
}

TEST_F(PoseFileTest, TumIsReadWithCommentsAndInterpolated) {
  const auto poses = twoPoses();
  const Eigen::Quaterniond q(poses[1].linear());
  std::ostringstream text;
  text.precision(17);
  text << "# timestamp tx ty tz qx qy qz qw\n100 1 2 3 0 0 0 1\n\n"
       << "102 3 2 1 " << q.x() << ' ' << q.y() << ' ' << q.z() << ' ' << q.w() << '\n';
  write("poses.tum", text.str());
  const auto trajectory = loadTrajectory(path("poses.tum"));
  EXPECT_EQ(trajectory->times().size(), 2u);
  expectHalfway(*trajectory, 101);
  EXPECT_THROW(trajectory->pose(99.9), std::out_of_range);
}

TEST_F(PoseFileTest, MalformedFilesNameTheProblem) {
  const auto message = [&](const std::string& text) -> std::string {
    write("bad.txt", text);
    try {
      loadTrajectory(path("bad.txt"));
    } catch (const std::runtime_error& error) {
      return error.what();
    }
    return "no error";
  };
  EXPECT_NE(message("1 2 3 4 5\n").find("is neither KITTI"), std::string::npos);
  EXPECT_NE(message("0 0 0 0 0 0 0 1\n1 0 0 0 0 0 x 1\n").find("line 2"), std::string::npos);
  EXPECT_NE(message("0 0 0 0 0 0 0 1\n1 0 0 0 0 0 0\n").find("line 2 has 7 numbers"), std::string::npos);
  EXPECT_NE(message("0 0 0 0 0 0 0 2\n").find("quaternion of norm"), std::string::npos);
  EXPECT_NE(message("1 0 0 0 0 0 0 1\n0 0 0 0 0 0 0 1\n").find("increase strictly"), std::string::npos);
  EXPECT_NE(message("").find("no poses"), std::string::npos);
  EXPECT_THROW(loadTrajectory(path("missing.txt")), std::runtime_error);
}

TEST(InterpolatedTrajectory, RejectsInconsistentInput) {
  EXPECT_THROW(InterpolatedTrajectory({}, {}), std::invalid_argument);
  EXPECT_THROW(InterpolatedTrajectory({0.0, 1.0}, {Eigen::Isometry3d::Identity()}), std::invalid_argument);
  EXPECT_THROW(InterpolatedTrajectory({1.0, 0.0}, {Eigen::Isometry3d::Identity(), Eigen::Isometry3d::Identity()}),
               std::invalid_argument);
  const InterpolatedTrajectory single({2.0}, {Eigen::Isometry3d::Identity()});
  EXPECT_TRUE(single.pose(2.0).isApprox(Eigen::Isometry3d::Identity()));
  EXPECT_THROW(single.pose(2.1), std::out_of_range);
}

}  // namespace
}  // namespace range_image_mapping::simulation
