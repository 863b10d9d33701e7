// readOdometryParameters: defaults, values read into the core's options, and
// bad values rejected with an error naming the parameter; and an Odometry
// nodelet with a bad parameter fails to load instead of running without an
// odometry. Needs a master only for the parameter server.
#include "error_text.h"
#include "nodelet_loading.h"
#include "range_image_mapping/ros/parameters.h"

#include <gtest/gtest.h>
#include <ros/ros.h>

#include <cmath>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using test::errorOf;

TEST(OdometryParameters, DefaultsWhenNothingIsSet) {
  const OdometryParameters parameters = readOdometryParameters(ros::NodeHandle("~empty"));
  const registration::OdometryOptions core;
  EXPECT_EQ(parameters.odom_frame, "odom");
  EXPECT_EQ(parameters.base_frame, "base_link");
  EXPECT_TRUE(parameters.publish_tf);
  EXPECT_FALSE(parameters.invert_tf);
  EXPECT_FALSE(parameters.publish_deskewed_cloud);
  // The core's own defaults, untouched.
  EXPECT_EQ(parameters.odometry.registration.strides, core.registration.strides);
  EXPECT_EQ(parameters.odometry.registration.iterations, core.registration.iterations);
  EXPECT_EQ(parameters.odometry.registration.kernel.scale_m, core.registration.kernel.scale_m);
  EXPECT_EQ(parameters.odometry.deskew, core.deskew);
  EXPECT_EQ(parameters.odometry.min_inliers, core.min_inliers);
  EXPECT_EQ(parameters.odometry.max_time_gap_s, core.max_time_gap_s);
  EXPECT_NEAR(parameters.odometry.model.keyframe_angle_rad, core.model.keyframe_angle_rad, 1e-12);
  EXPECT_EQ(parameters.odometry.model.keyframe_distance_m, core.model.keyframe_distance_m);
  EXPECT_EQ(parameters.odometry.model.keyframes, core.model.keyframes);
  EXPECT_EQ(parameters.odometry.model.keyframe_range_share, core.model.keyframe_range_share);
  EXPECT_EQ(parameters.odometry.model.max_keyframe_distance_m, core.model.max_keyframe_distance_m);
  EXPECT_EQ(parameters.odometry.deskew_passes, core.deskew_passes);
  EXPECT_EQ(parameters.odometry.max_speed_mps, core.max_speed_mps);
  EXPECT_NEAR(parameters.odometry.max_angular_rate_radps, core.max_angular_rate_radps, 1e-12);
  EXPECT_EQ(parameters.odometry.max_acceleration_mps2, core.max_acceleration_mps2);
  EXPECT_EQ(parameters.odometry.velocity_decay_time_s, core.velocity_decay_time_s);
  EXPECT_EQ(parameters.odometry.registration.gate_grows_with_stride, core.registration.gate_grows_with_stride);
  EXPECT_EQ(parameters.odometry.registration.min_coarse_pairs, core.registration.min_coarse_pairs);
}

TEST(OdometryParameters, ValuesReachTheCoreOptions) {
  ros::NodeHandle node("~set");
  node.setParam("odom_frame", "wheel_odom");
  node.setParam("base_frame", "robot");
  node.setParam("invert_tf", true);
  node.setParam("path_length", 0);
  node.setParam("strides", std::vector<int>{8, 4, 2, 1});
  node.setParam("iterations", std::vector<int>{10, 10, 10, 5});
  node.setParam("kernel", "barron");
  node.setParam("kernel_scale", 0.2);
  node.setParam("kernel_alpha", 0);  // an integer where a double is expected is fine
  node.setParam("normal_method", "covariance");
  node.setParam("deskew", false);
  node.setParam("keyframe_angle_deg", 90.0);
  node.setParam("keyframe_range_share", 0.0);  // off
  node.setParam("max_keyframe_distance", 3.0);
  node.setParam("min_inliers", 50);
  node.setParam("gate_grows_with_stride", false);
  node.setParam("min_coarse_pairs", 40);
  node.setParam("deskew_passes", 3);
  node.setParam("max_speed", 5.0);
  node.setParam("max_angular_rate_deg", 90.0);
  node.setParam("max_acceleration", 0);  // 0: off
  node.setParam("velocity_decay_time", 2.5);
  const OdometryParameters parameters = readOdometryParameters(node);
  EXPECT_EQ(parameters.odometry.max_speed_mps, 5.0);
  EXPECT_NEAR(parameters.odometry.max_angular_rate_radps, M_PI / 2, 1e-12);
  EXPECT_EQ(parameters.odometry.max_acceleration_mps2, 0.0);
  EXPECT_EQ(parameters.odometry.velocity_decay_time_s, 2.5);
  EXPECT_FALSE(parameters.odometry.registration.gate_grows_with_stride);
  EXPECT_EQ(parameters.odometry.registration.min_coarse_pairs, 40);
  EXPECT_EQ(parameters.odometry.deskew_passes, 3);
  EXPECT_EQ(parameters.odom_frame, "wheel_odom");
  EXPECT_EQ(parameters.base_frame, "robot");
  EXPECT_TRUE(parameters.invert_tf);
  EXPECT_EQ(parameters.path_length, 0);
  const registration::RegistrationOptions& registration = parameters.odometry.registration;
  EXPECT_EQ(registration.strides, (std::vector<int>{8, 4, 2, 1}));
  EXPECT_EQ(registration.iterations, (std::vector<int>{10, 10, 10, 5}));
  EXPECT_EQ(registration.kernel.type, registration::RobustKernel::Type::kBarron);
  EXPECT_EQ(registration.kernel.scale_m, 0.2);
  EXPECT_EQ(registration.kernel.alpha, 0.0);
  EXPECT_EQ(registration.normals.method, NormalMethod::kCovariance);
  EXPECT_FALSE(parameters.odometry.deskew);
  EXPECT_NEAR(parameters.odometry.model.keyframe_angle_rad, M_PI / 2, 1e-12);
  EXPECT_EQ(parameters.odometry.model.keyframe_range_share, 0.0);
  EXPECT_EQ(parameters.odometry.model.max_keyframe_distance_m, 3.0);
  EXPECT_EQ(parameters.odometry.min_inliers, 50u);
}

TEST(OdometryParameters, BadValuesAreErrorsNamingTheParameter) {
  const auto error_for = [](const std::string& name, const auto& value) {
    ros::NodeHandle node("~bad_" + name);
    node.setParam(name, value);
    return errorOf([&] { readOdometryParameters(node); });
  };
  const std::string scale = error_for("kernel_scale", -0.5);
  EXPECT_NE(scale.find("/bad_kernel_scale/kernel_scale is -0.5, expected within ["), std::string::npos) << scale;
  const std::string kernel = error_for("kernel", std::string("huber"));
  EXPECT_NE(kernel.find("kernel is 'huber', expected one of: pseudo_huber, barron"), std::string::npos) << kernel;
  const std::string strides = error_for("strides", std::string("4 2 1"));
  EXPECT_NE(strides.find("strides must be a list of integers, got a string"), std::string::npos) << strides;
  const std::string zero_stride = error_for("strides", std::vector<int>{4, 0, 1});
  EXPECT_NE(zero_stride.find("strides entry 1 is 0, expected within [1, 64]"), std::string::npos) << zero_stride;
  const std::string levels = error_for("iterations", std::vector<int>{20, 20});
  EXPECT_NE(levels.find("iterations has 2 entries"), std::string::npos) << levels;
  const std::string frame = error_for("base_frame", std::string(""));
  EXPECT_NE(frame.find("base_frame is empty"), std::string::npos) << frame;
  const std::string same = error_for("base_frame", std::string("odom"));
  EXPECT_NE(same.find("are both 'odom'"), std::string::npos) << same;
  const std::string flag = error_for("publish_tf", 1);
  EXPECT_NE(flag.find("publish_tf must be true or false, got a int"), std::string::npos) << flag;
  const std::string gap = error_for("max_time_gap", 0.0);
  EXPECT_NE(gap.find("max_time_gap is 0"), std::string::npos) << gap;
  const std::string speed = error_for("max_speed", -1.0);
  EXPECT_NE(speed.find("max_speed is -1"), std::string::npos) << speed;
}

// The nodelet refuses to start, saying which parameter.
TEST(OdometryParameters, NodeletWithABadParameterFailsToLoad) {
  const std::string odometry = "range_image_mapping/Odometry";
  nodelet::Loader loader(false);
  test::expectRefused(loader, odometry, "/bad_odometry", "kernel_scale", -0.5,
                      "Odometry not started: parameter /bad_odometry/kernel_scale is -0.5");
  test::expectRefused(loader, odometry, "/same_frames_odometry", "base_frame", std::string("odom"),
                      "/same_frames_odometry/base_frame");
  test::expectLoaded(loader, odometry, "/good_odometry");  // the defaults
  loader.clear();
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "odometry_parameters");
  ros::NodeHandle keep_node_alive;
  return RUN_ALL_TESTS();
}
