// LidarMount (T_base_lidar from tf, or the identity after the timeout) and
// covarianceInFrame (a pose covariance carried through the mount), without a
// running nodelet: transforms go straight into a tf buffer.
#include "range_image_mapping/ros/lidar_mount.h"
#include "rostest_main.h"

#include <geometry_msgs/TransformStamped.h>
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/buffer.h>

#include <Eigen/Geometry>

namespace range_image_mapping {
namespace {

Eigen::Isometry3d offCentreMount() {
  Eigen::Isometry3d mount = Eigen::Isometry3d::Identity();
  mount.translate(Eigen::Vector3d(0.3, -0.1, 0.8));
  mount.rotate(Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX()));
  return mount;
}

TEST(LidarMount, FromTfOnceItIsThere) {
  tf2_ros::Buffer tf;
  LidarMount mount(tf, 60.0, "lidar_mount_test");
  EXPECT_EQ(mount.baseFromLidar("base_link", "os_lidar"), nullptr);  // not on tf yet: wait
  geometry_msgs::TransformStamped transform = tf2::eigenToTransform(offCentreMount());
  transform.header.frame_id = "base_link";
  transform.child_frame_id = "os_lidar";
  tf.setTransform(transform, "test", true);
  const Eigen::Isometry3d* base_from_lidar = mount.baseFromLidar("base_link", "os_lidar");
  ASSERT_NE(base_from_lidar, nullptr);
  EXPECT_TRUE(base_from_lidar->isApprox(offCentreMount(), 1e-12));
}

TEST(LidarMount, IdentityForTheSameFrameOrAfterTheTimeout) {
  tf2_ros::Buffer tf;
  LidarMount mount(tf, 0.05, "lidar_mount_test");
  const Eigen::Isometry3d* same = mount.baseFromLidar("os_lidar", "os_lidar");
  ASSERT_NE(same, nullptr);
  EXPECT_TRUE(same->isApprox(Eigen::Isometry3d::Identity()));
  EXPECT_EQ(mount.fallback(), "");  // the lidar is the base: nothing to warn about
  EXPECT_EQ(mount.baseFromLidar("base_link", "os_lidar"), nullptr);  // a new pair waits again
  EXPECT_EQ(mount.fallback(), "");
  ros::WallDuration(0.1).sleep();
  const Eigen::Isometry3d* fallback = mount.baseFromLidar("base_link", "os_lidar");
  ASSERT_NE(fallback, nullptr);
  EXPECT_TRUE(fallback->isApprox(Eigen::Isometry3d::Identity()));
  // Said, naming the transform and the fixes, until the frames change.
  EXPECT_NE(mount.fallback().find("base_link -> os_lidar"), std::string::npos) << mount.fallback();
  EXPECT_NE(mount.fallback().find("lidar_transform_timeout"), std::string::npos) << mount.fallback();
  ASSERT_NE(mount.baseFromLidar("os_lidar", "os_lidar"), nullptr);
  EXPECT_EQ(mount.fallback(), "");
}

// A twist drawn from covariance C in one frame is, in the other, the same
// twist through twistInFrame: a rank-one C = x x^T must become y y^T with
// y = twistInFrame(x), for every x (so also every sum of them).
TEST(LidarMount, CovarianceMovesLikeTheTwistsItDescribes) {
  const Eigen::Isometry3d mount = offCentreMount();
  Matrix6d covariance = Matrix6d::Zero(), expected = Matrix6d::Zero();
  for (int i = 0; i < 6; ++i) {
    const Twist x = Twist::Random();
    const Twist y = twistInFrame(mount, x);
    covariance += x * x.transpose();
    expected += y * y.transpose();
  }
  const Matrix6d moved = covarianceInFrame(mount, covariance);
  EXPECT_LT((moved - expected).cwiseAbs().maxCoeff(), 1e-12) << moved << "\n\n" << expected;
  // And back through the inverse mount.
  EXPECT_LT((covarianceInFrame(mount.inverse(), moved) - covariance).cwiseAbs().maxCoeff(), 1e-12);
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  return range_image_mapping::test::runRostestNode(argc, argv, "lidar_mount");
}
