// LocalModel: the scan-to-model reference. A keyframe rendered at its own pose
// gives back its own pixels; of several keyframes, the nearest surface is
// kept and, on it, the newest keyframe's point; occluded points lose. On real
// KITTI raw scans (no ground truth) the odometry with the model gets the path
// length an independent ICP chain and KISS-ICP get, where frame-to-frame
// registration is more than 1 % long.
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/recording.h"
#include "range_image_mapping/registration/lidar_odometry.h"
#include "range_image_mapping/registration/local_model.h"
#include "range_image_mapping/sensor_catalog.h"

#include "test_data.h"

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <cmath>

namespace range_image_mapping::registration {
namespace {

constexpr double kDegree = M_PI / 180.0;

LidarModelConstPtr sensor() {
  static const LidarModelConstPtr model =
      std::make_shared<const LidarModel>(LidarIntrinsics::synthetic(32, 256, 15.0 * kDegree, -25.0 * kDegree));
  return model;
}

// Every pixel sees a cylinder wall of this radius around the sensor (and the
// floor below it): a scan with a point and a normal everywhere.
RangeImage cylinderScan(float radius_m, const LidarModelConstPtr& model = sensor()) {
  RangeImage image(model);
  for (int v = 0; v < image.rows(); ++v)
    for (int u = 0; u < image.columns(); ++u) {
      const Eigen::Vector3f direction = model->direction(u, v);
      image.range[image.index(v, u)] = radius_m / direction.head<2>().norm();
    }
  return image;
}

std::vector<VertexNormalMap> pyramid(const RangeImage& scan, const std::vector<int>& strides) {
  std::vector<VertexNormalMap> levels(strides.size());
  for (std::size_t l = 0; l < strides.size(); ++l) computeVertexNormalMap(scan, strides[l], {}, levels[l]);
  return levels;
}

std::size_t validPixels(const VertexNormalMap& map) {
  std::size_t count = 0;
  for (const Eigen::Vector3f& point : map.points) count += point.allFinite();
  return count;
}

TEST(LocalModel, AKeyframeRenderedAtItsOwnPoseGivesBackItsPixels) {
  const std::vector<int> strides{4, 2, 1};
  const std::vector<VertexNormalMap> levels = pyramid(cylinderScan(10.0f), strides);
  LocalModelOptions own_normals;
  own_normals.normal_radius_m = 0.0;  // the keyframe's normals as given
  LocalModel model(own_normals);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translate(Eigen::Vector3d(3.0, -2.0, 0.5)).rotate(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()));
  model.add(levels, pose, false);
  std::vector<VertexNormalMap> rendered;
  model.render(*sensor(), pose, rendered);
  ASSERT_EQ(rendered.size(), strides.size());
  for (std::size_t l = 0; l < strides.size(); ++l) {
    ASSERT_EQ(rendered[l].stride, strides[l]);
    ASSERT_EQ(rendered[l].points.size(), levels[l].points.size());
    std::size_t compared = 0;
    for (std::size_t i = 0; i < levels[l].points.size(); ++i) {
      if (!levels[l].normals[i].allFinite()) continue;
      ASSERT_TRUE(rendered[l].points[i].allFinite()) << "level " << l << " pixel " << i;
      EXPECT_LT((rendered[l].points[i] - levels[l].points[i]).norm(), 1e-4f);
      EXPECT_LT((rendered[l].normals[i] - levels[l].normals[i]).norm(), 1e-4f);
      ++compared;
    }
    EXPECT_GT(compared, levels[l].points.size() / 2) << "level " << l;
  }
}

TEST(LocalModel, KeepsTheNearestSurfaceAndOnItTheNewestKeyframe) {
  const std::vector<int> strides{1};
  LocalModel model(LocalModelOptions{3, 0.0, 0.0});
  const Eigen::Isometry3d at_origin = Eigen::Isometry3d::Identity();
  model.add(pyramid(cylinderScan(8.0f), strides), at_origin, false);    // a wall behind...
  model.add(pyramid(cylinderScan(5.0f), strides), at_origin, false);    // ... the nearest surface
  model.add(pyramid(cylinderScan(5.03f), strides), at_origin, false);   // the same, 3 cm off: newest
  std::vector<VertexNormalMap> rendered;
  model.render(*sensor(), at_origin, rendered);
  ASSERT_EQ(rendered.size(), 1u);
  const std::size_t valid = validPixels(rendered[0]);
  ASSERT_GT(valid, rendered[0].points.size() / 2);
  for (const Eigen::Vector3f& point : rendered[0].points) {
    if (!point.allFinite()) continue;
    EXPECT_NEAR(point.head<2>().norm(), 5.03f, 1e-3f);  // not the 8 m wall, not the older 5 m samples
  }
  // Without the newest, the 5 m surface (the 8 m wall is hidden behind it).
  LocalModel two(LocalModelOptions{2, 0.0, 0.0});
  two.add(pyramid(cylinderScan(5.0f), strides), at_origin, false);
  two.add(pyramid(cylinderScan(8.0f), strides), at_origin, false);
  two.render(*sensor(), at_origin, rendered);
  for (const Eigen::Vector3f& point : rendered[0].points)
    if (point.allFinite()) EXPECT_NEAR(point.head<2>().norm(), 5.0f, 1e-3f);
}

TEST(LocalModel, DropsTheOldestKeyframeAndReplacesAProvisionalOne) {
  const std::vector<int> strides{1};
  LocalModelOptions options{2, 1.0, 0.0};
  options.keyframe_range_share = 0.0;  // not raised with the scene (see below)
  LocalModel model(options);
  // Rows 0.25 deg apart: the option's distance is the one in use.
  const LidarModel dense(LidarIntrinsics::synthetic(128, 256, 16.0 * kDegree, -16.0 * kDegree));
  ASSERT_DOUBLE_EQ(keyframeDistance(model.options(), dense), 1.0);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  EXPECT_TRUE(model.wantsKeyframe(pose, dense));
  model.add(pyramid(cylinderScan(5.0f), strides), pose, true);
  EXPECT_TRUE(model.provisional());
  EXPECT_TRUE(model.wantsKeyframe(pose, dense));  // a provisional keyframe is always replaced
  model.add(pyramid(cylinderScan(6.0f), strides), pose, false);
  EXPECT_EQ(model.size(), 1u);
  EXPECT_FALSE(model.wantsKeyframe(pose, dense));
  pose.translation().x() = 1.0;
  EXPECT_TRUE(model.wantsKeyframe(pose, dense));
  model.add(pyramid(cylinderScan(7.0f), strides), pose, false);
  pose.translation().x() = 2.0;
  model.add(pyramid(cylinderScan(8.0f), strides), pose, false);
  EXPECT_EQ(model.size(), 2u);
  EXPECT_TRUE(model.newestPose().isApprox(pose));
  EXPECT_THROW(LocalModel(LocalModelOptions{0, 1.0, 0.0}), std::invalid_argument);
  EXPECT_THROW(LocalModel(LocalModelOptions{2, -1.0, 0.0}), std::invalid_argument);
}

// On a sensor with rows a degree or more apart the keyframes are a metre per
// degree of its median beam spacing apart at least (a VLP-16's 2 deg: 2 m;
// an HDL-32E's 1.33 deg: 1.33 m); denser sensors keep the option's distance,
// and 0 (every scan a keyframe) stays 0.
TEST(LocalModel, KeyframeDistanceFollowsTheSensorsRowSpacing) {
  const LocalModelOptions options;  // 0.5 m
  const auto distanceFor = [&](const std::string& name) {
    const std::optional<LidarIntrinsics> intrinsics = catalogSensor(name);
    EXPECT_TRUE(intrinsics) << name;
    return intrinsics ? keyframeDistance(options, LidarModel(*intrinsics)) : -1.0;
  };
  EXPECT_NEAR(distanceFor("VLP-16"), 2.0, 0.01);
  EXPECT_NEAR(distanceFor("HDL-32E"), 1.33, 0.01);
  EXPECT_DOUBLE_EQ(distanceFor("VLP-32C"), 0.5);
  EXPECT_DOUBLE_EQ(distanceFor("Pandar64"), 0.5);
  EXPECT_DOUBLE_EQ(keyframeDistance(options, LidarModel(io::kittiHdl64Intrinsics())), 0.5);
  const LidarModel vlp16(*catalogSensor("VLP-16"));
  EXPECT_DOUBLE_EQ(keyframeDistance(LocalModelOptions{4, 0.0, 0.0}, vlp16), 0.0);
  EXPECT_DOUBLE_EQ(keyframeDistance(LocalModelOptions{4, 3.0, 0.0}, vlp16), 3.0);
  // The model asks for a keyframe at the sensor's distance, not the option's.
  LocalModel model(options);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  model.add(pyramid(cylinderScan(5.0f), {1}), pose, false);
  pose.translation().x() = 1.0;
  EXPECT_FALSE(model.wantsKeyframe(pose, vlp16));
  pose.translation().x() = 2.1;
  EXPECT_TRUE(model.wantsKeyframe(pose, vlp16));
}

// The distance follows the scene: keyframe_range_share (0.2) of the newest
// keyframe's median range, between keyframe_distance_m (0.5 m) and
// max_keyframe_distance_m (1.5 m), which does not lower a sparse sensor's.
TEST(LocalModel, KeyframeDistanceFollowsTheScenesScale) {
  const LocalModelOptions options;
  ASSERT_DOUBLE_EQ(options.keyframe_distance_m, 0.5);
  ASSERT_DOUBLE_EQ(options.keyframe_range_share, 0.2);
  ASSERT_DOUBLE_EQ(options.max_keyframe_distance_m, 1.5);
  const LidarModelConstPtr dense =
      std::make_shared<const LidarModel>(LidarIntrinsics::synthetic(128, 256, 16.0 * kDegree, -16.0 * kDegree));
  const std::vector<int> strides{2, 1};
  LocalModel model(options);
  EXPECT_DOUBLE_EQ(model.keyframeDistance(*dense), 0.5);  // empty: no scene yet
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  const auto addCylinder = [&](float radius_m) {
    model.add(pyramid(cylinderScan(radius_m, dense), strides), pose, false);
    // The wall's median range: the radius over the median row's cosine.
    EXPECT_NEAR(model.newestMedianRange(), radius_m, 0.02 * radius_m);
  };
  addCylinder(2.0f);  // a room: 0.4 m, so the least distance
  EXPECT_DOUBLE_EQ(model.keyframeDistance(*dense), 0.5);
  addCylinder(5.0f);
  EXPECT_NEAR(model.keyframeDistance(*dense), 1.0, 0.02);
  EXPECT_DOUBLE_EQ(model.keyframeDistance(*dense), 0.2 * model.newestMedianRange());
  pose.translation().x() = 0.9;
  EXPECT_FALSE(model.wantsKeyframe(pose, *dense));
  pose.translation().x() = 1.1;
  EXPECT_TRUE(model.wantsKeyframe(pose, *dense));
  addCylinder(20.0f);  // a street: capped
  EXPECT_DOUBLE_EQ(model.keyframeDistance(*dense), 1.5);
  pose.translation().x() += 1.4;
  EXPECT_FALSE(model.wantsKeyframe(pose, *dense));
  pose.translation().x() += 0.2;
  EXPECT_TRUE(model.wantsKeyframe(pose, *dense));
  // The cap does not lower a sparse sensor's 2 m.
  EXPECT_NEAR(model.keyframeDistance(LidarModel(*catalogSensor("VLP-16"))), 2.0, 0.01);
  // Share 0: the least distance; distance 0: every scan, whatever the scene.
  LocalModelOptions off = options;
  off.keyframe_range_share = 0.0;
  LocalModel fixed(off);
  fixed.add(pyramid(cylinderScan(20.0f, dense), strides), Eigen::Isometry3d::Identity(), false);
  EXPECT_DOUBLE_EQ(fixed.keyframeDistance(*dense), 0.5);
  LocalModel every(LocalModelOptions{4, 0.0, 0.0});
  every.add(pyramid(cylinderScan(20.0f, dense), strides), Eigen::Isometry3d::Identity(), false);
  EXPECT_DOUBLE_EQ(every.keyframeDistance(*dense), 0.0);
  EXPECT_TRUE(every.wantsKeyframe(Eigen::Isometry3d::Identity(), *dense));
  EXPECT_THROW(LocalModel(LocalModelOptions{4, 0.5, 0.0, 1.0, -0.2}), std::invalid_argument);
}

// A sparse sensor (8 rows 4 deg apart) over a flat floor 1.5 m below it:
// a ring's range changes by far more than the depth-jump test allows from
// one row to the next, so each scan's own normal map has no floor normals.
// Keyframes 0.4 m apart put their rings between each other's, and the
// model's normals from the model's points find the floor.
LidarModelConstPtr sparseSensor() {
  static const LidarModelConstPtr model =
      std::make_shared<const LidarModel>(LidarIntrinsics::synthetic(8, 512, 2.0 * kDegree, -26.0 * kDegree));
  return model;
}

// The floor rises by tan(tilt) per metre along x (0: flat).
RangeImage floorScan(float tilt_rad = 0.0f) {
  RangeImage image(sparseSensor());
  for (int v = 0; v < image.rows(); ++v)
    for (int u = 0; u < image.columns(); ++u) {
      const Eigen::Vector3f direction = sparseSensor()->direction(u, v);
      const float descent = direction.z() - std::tan(tilt_rad) * direction.x();
      if (descent < -0.01f) image.range[image.index(v, u)] = 1.5f / -descent;
    }
  return image;
}

std::size_t pixelsWithNormals(const VertexNormalMap& map) {
  std::size_t count = 0;
  for (const Eigen::Vector3f& normal : map.normals) count += normal.allFinite();
  return count;
}

TEST(LocalModel, NormalsFromTheModelFindTheFloorBetweenASparseSensorsRings) {
  const std::vector<int> strides{2, 1};
  const std::vector<VertexNormalMap> levels = pyramid(floorScan(), strides);
  ASSERT_EQ(pixelsWithNormals(levels[1]), 0u) << "the scan's own normal map should not find the floor";
  LocalModelOptions own_normals{4, 0.0, 0.0, 0.0};
  LocalModelOptions model_normals = own_normals;
  model_normals.normal_radius_m = 1.0;
  LocalModel own(own_normals), merged(model_normals);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  for (int k = 0; k < 4; ++k) {
    pose.translation().x() = 0.4 * k;
    own.add(levels, pose, false);
    merged.add(levels, pose, false);
  }
  std::vector<VertexNormalMap> rendered;
  own.render(*sparseSensor(), pose, rendered);
  EXPECT_EQ(pixelsWithNormals(rendered[1]), 0u);
  merged.render(*sparseSensor(), pose, rendered);
  ASSERT_EQ(rendered.size(), strides.size());
  for (std::size_t l = 0; l < strides.size(); ++l) {
    // Ahead of and behind the sensor the rings fill in; to the side they
    // slide along themselves and stay one line each (no plane).
    EXPECT_GT(pixelsWithNormals(rendered[l]), validPixels(levels[l]) / 5) << "stride " << strides[l];
    for (const Eigen::Vector3f& normal : rendered[l].normals)
      if (normal.allFinite()) EXPECT_GT(normal.z(), std::cos(0.5 * kDegree)) << normal.transpose();
  }
}

// A keyframe that leaves the model (dropped, or a provisional one replaced)
// must take its points out of the later keyframes' normals: keyframes of a
// tilted floor come and go before flat ones, and the model that saw them
// must give the normals of one that never did, to the bit (nothing of a
// keyframe that left may remain, not even a rounding).
TEST(LocalModel, NormalsDependOnlyOnTheKeyframesHeld) {
  const std::vector<int> strides{2, 1};
  const std::vector<VertexNormalMap> flat = pyramid(floorScan(), strides);
  const std::vector<VertexNormalMap> tilted = pyramid(floorScan(float(15.0 * kDegree)), strides);
  LocalModelOptions options{2, 0.0, 0.0, 1.0};
  LocalModel rolling(options), fresh(options);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  const auto at = [&](double x) {
    pose.translation().x() = x;
    return pose;
  };
  rolling.add(tilted, at(0.0), true);  // provisional: replaced by the next
  rolling.add(flat, at(0.0), false);
  rolling.add(tilted, at(0.4), false);
  for (int k = 2; k < 5; ++k) rolling.add(flat, at(0.4 * k), false);
  for (int k = 2; k < 5; ++k) fresh.add(flat, at(0.4 * k), false);
  ASSERT_EQ(rolling.size(), 2u);
  std::vector<VertexNormalMap> kept, built;
  rolling.render(*sparseSensor(), pose, kept);
  fresh.render(*sparseSensor(), pose, built);
  ASSERT_EQ(kept.size(), strides.size());
  for (std::size_t l = 0; l < strides.size(); ++l) {
    EXPECT_GT(pixelsWithNormals(built[l]), validPixels(flat[l]) / 5) << "stride " << strides[l];
    EXPECT_EQ(pixelsWithNormals(kept[l]), pixelsWithNormals(built[l])) << "stride " << strides[l];
    for (std::size_t p = 0; p < kept[l].normals.size(); ++p)
      if (kept[l].normals[p].allFinite() && built[l].normals[p].allFinite())
        ASSERT_TRUE(kept[l].normals[p] == built[l].normals[p])
            << "stride " << strides[l] << " pixel " << p << ": " << kept[l].normals[p].transpose() << " against "
            << built[l].normals[p].transpose();
  }
}

// The model's normals are summed on several threads, and the render
// z-buffers in lanes whose number follows the threads: the same keyframes
// must give bit-identical rendered points and normals on one thread and on four.
TEST(LocalModel, ModelNormalsAndRenderDoNotDependOnTheThreads) {
  const std::vector<int> strides{2, 1};
  const std::vector<VertexNormalMap> flat = pyramid(floorScan(), strides);
  const std::vector<VertexNormalMap> tilted = pyramid(floorScan(float(3.0 * kDegree)), strides);
  const auto renderWith = [&](int threads) {
    std::vector<VertexNormalMap> rendered;
    tbb::task_arena(threads).execute([&] {
      LocalModel model(LocalModelOptions{4, 0.0, 0.0, 1.0});
      Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
      for (int k = 0; k < 4; ++k) {
        pose.translation() = Eigen::Vector3d(0.37 * k, 0.11 * k, 0.0);
        model.add(k % 2 ? tilted : flat, pose, false);
      }
      model.render(*sparseSensor(), pose, rendered);
    });
    return rendered;
  };
  const std::vector<VertexNormalMap> one = renderWith(1), four = renderWith(4);
  ASSERT_EQ(one.size(), strides.size());
  ASSERT_EQ(four.size(), strides.size());
  for (std::size_t l = 0; l < strides.size(); ++l) {
    EXPECT_GT(pixelsWithNormals(one[l]), validPixels(flat[l]) / 5) << "stride " << strides[l];
    ASSERT_EQ(one[l].normals.size(), four[l].normals.size());
    ASSERT_EQ(one[l].points.size(), four[l].points.size());
    for (std::size_t p = 0; p < one[l].normals.size(); ++p)
      for (int axis = 0; axis < 3; ++axis) {
        const float a = one[l].normals[p][axis], b = four[l].normals[p][axis];
        ASSERT_TRUE(a == b || (std::isnan(a) && std::isnan(b)))
            << "stride " << strides[l] << " pixel " << p << ": " << one[l].normals[p].transpose() << " against "
            << four[l].normals[p].transpose();
        const float x = one[l].points[p][axis], y = four[l].points[p][axis];
        ASSERT_TRUE(x == y || (std::isnan(x) && std::isnan(y)))
            << "stride " << strides[l] << " pixel " << p << ": point " << one[l].points[p].transpose()
            << " against " << four[l].points[p].transpose();
      }
  }
}

// The path over io::forEachScan of a KITTI folder.
double pathLength(const std::string& folder, const OdometryOptions& options) {
  io::RecordingOptions recording_options;
  recording_options.input = folder;
  recording_options.kitti = true;
  const io::Recording recording = io::openRecording(recording_options);
  LidarOdometry odometry(options);
  double length = 0.0;
  Eigen::Vector3d previous = Eigen::Vector3d::Zero();
  io::forEachScan(recording, [&](const RangeImage& scan) {
    const OdometryUpdate update = odometry.process(scan);
    EXPECT_FALSE(update.degenerate) << update.warning;
    length += (update.pose.translation() - previous).norm();
    previous = update.pose.translation();
    return true;
  });
  return length;
}

// kitti-raw-22: an independent point-to-plane ICP chain and KISS-ICP both put
// the path at 16.84-16.90 m (the data's SOURCE.md).
TEST(LocalModel, RealKittiRawPathMatchesTheReferenceWhereFrameToFrameIsLong) {
  RIM_REQUIRE_DATA(folder, "kitti-raw-22/velodyne");
  const double with_model = pathLength(folder, OdometryOptions{});
  OdometryOptions frame_to_frame;
  frame_to_frame.model = LocalModelOptions{1, 0.0, 0.0};
  const double previous_scan = pathLength(folder, frame_to_frame);
  std::cout << "kitti-raw-22 path: " << with_model << " m with the local model, " << previous_scan
            << " m frame to frame (reference 16.84-16.90 m)\n";
  EXPECT_NEAR(with_model, 16.87, 0.17);  // 1 %
  EXPECT_GT(previous_scan, with_model);
}

}  // namespace
}  // namespace range_image_mapping::registration
