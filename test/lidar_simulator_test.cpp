// The simulated scan against analytic answers computed here in double from the
// model's Pi^-1 tables: exact ranges, surfaces hit by unprojection, noise
// statistics, motion distortion, determinism. Real Ouster OS0-128 tables (when
// the shared data is present) and the synthetic KITTI HDL-64.
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/simulation/lidar_simulator.h"
#include "range_image_mapping/simulation/mesh_primitives.h"
#include "mesh_reference.h"
#include "test_data.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <cstdio>
#include <limits>
#include <random>

namespace range_image_mapping::simulation {
namespace {

constexpr double kDegree = M_PI / 180.0;
constexpr double kHalfMillimetre = 0.0005;

double floatTolerance(double range, const Eigen::Vector3d& origin) {
  return 8.0 * std::numeric_limits<float>::epsilon() * (range + origin.norm() + 1.0);
}

LidarModelConstPtr hdl64Model() { return std::make_shared<const LidarModel>(io::kittiHdl64Intrinsics()); }

LidarModelConstPtr ousterModel(const std::string& json_path) {
  return std::make_shared<const LidarModel>(loadOusterMetadata(json_path).intrinsics);
}
#define REQUIRE_OUSTER_TABLES() RIM_REQUIRE_DATA(ouster_json_path, "ouster-pcaps/OS-0-128-U1_v2.3.0_1024x10.json")

InterpolatedTrajectory standingStill(const Eigen::Isometry3d& pose) {
  return InterpolatedTrajectory({0.0, 100.0}, {pose, pose});
}

Eigen::Isometry3d tiltedPose() {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = (Eigen::AngleAxisd(35 * kDegree, Eigen::Vector3d::UnitZ()) *
                   Eigen::AngleAxisd(8 * kDegree, Eigen::Vector3d(1, 1, 0).normalized()))
                      .toRotationMatrix();
  pose.translation() = Eigen::Vector3d(0.7, -0.3, 0.2);
  return pose;
}

// The beam of pixel (u, v) in the world, in double from the model's tables:
// it starts where Pi^-1 gives range n.
struct Beam {
  Eigen::Vector3d origin, direction;
  double n;
};
Beam beamOf(const LidarModel& model, const Eigen::Isometry3d& pose, int u, int v) {
  const LidarIntrinsics& in = model.intrinsics();
  const double n = std::hypot(in.beam_origin_radius_m, in.beam_origin_z_m);
  const Eigen::Vector3d d = model.direction(u, v).cast<double>();
  return {pose * (model.offset(u, v).cast<double>() + n * d), pose.linear() * d, n};
}

// Distance from inside an axis-aligned box to its walls along a ray.
double distanceToBoxWall(const Eigen::Vector3d& minimum, const Eigen::Vector3d& maximum, const Beam& beam,
                         Eigen::Vector3d* normal = nullptr) {
  double best = std::numeric_limits<double>::infinity();
  for (int axis = 0; axis < 3; ++axis) {
    const double d = beam.direction[axis];
    const double wall = d > 0 ? maximum[axis] : minimum[axis];
    if (d == 0) continue;
    const double t = (wall - beam.origin[axis]) / d;
    if (t < best) {
      best = t;
      if (normal) *normal = -Eigen::Vector3d::Unit(axis) * (d > 0 ? 1.0 : -1.0);
    }
  }
  return best;
}

std::string scientific(double value) {
  char text[32];
  std::snprintf(text, sizeof(text), "%.3e", value);
  return text;
}

SensorEffects exactEffects() {
  SensorEffects effects;
  effects.min_range_m = 0.0;
  return effects;
}

// Every pixel of a closed room: the exact range, the millimetre reading, and
// the unprojected point on a wall.
void expectExactBoxRoom(const LidarModelConstPtr& model) {
  const Eigen::Vector3d minimum(-6, -4, -2.5), maximum(9, 5, 3.5);
  const RayCaster caster(makeBox(minimum.cast<float>(), maximum.cast<float>(), true));
  const LidarSimulator simulator(model, caster, exactEffects(), 1);
  const Eigen::Isometry3d pose = tiltedPose();
  const SimulatedScan scan = simulator.simulate(standingStill(pose), 1.0, 7);
  ASSERT_EQ(scan.image.validCount(), static_cast<std::size_t>(model->rows()) * model->columns());
  double worst_exact = 0, worst_reading = 0, worst_surface = 0;
  for (int v = 0; v < model->rows(); ++v)
    for (int u = 0; u < model->columns(); ++u) {
      const Beam beam = beamOf(*model, pose, u, v);
      Eigen::Vector3d normal;
      const double expected = beam.n + distanceToBoxWall(minimum, maximum, beam, &normal);
      const std::size_t i = scan.image.index(v, u);
      const double tolerance = floatTolerance(expected, beam.origin);
      ASSERT_NEAR(scan.true_range[i], expected, tolerance) << "row " << v << " column " << u;
      ASSERT_NEAR(scan.raw.range[i] * 0.001, expected, kHalfMillimetre + tolerance);
      ASSERT_NEAR(scan.image.range[i], expected, kHalfMillimetre + tolerance);
      worst_exact = std::max(worst_exact, std::abs(scan.true_range[i] - expected) / expected);
      worst_reading = std::max(worst_reading, std::abs(scan.image.range[i] - expected));
      // Pi^-1 of the reading lies on a wall.
      const Eigen::Vector3d point = pose * model->unproject(u, v, scan.image.range[i]).cast<double>();
      const double off_wall = std::min(((point - minimum).cwiseAbs()).minCoeff(), ((point - maximum).cwiseAbs()).minCoeff());
      worst_surface = std::max(worst_surface, off_wall);
      // A grey Lambertian world: reflectivity follows the incidence angle.
      EXPECT_NEAR(scan.raw.reflectivity[i], 50.0 * std::abs(normal.dot(beam.direction)), 0.51);
    }
  EXPECT_LT(worst_surface, 1e-3);
  ::testing::Test::RecordProperty("worst_relative_range_error", scientific(worst_exact));
  ::testing::Test::RecordProperty("worst_reading_error_m", scientific(worst_reading));
  ::testing::Test::RecordProperty("worst_distance_to_wall_m", scientific(worst_surface));
}

TEST(LidarSimulator, BoxRoomRangesAreExactWithOusterTables) {
  REQUIRE_OUSTER_TABLES();
  expectExactBoxRoom(ousterModel(ouster_json_path));
}

TEST(LidarSimulator, BoxRoomRangesAreExactWithHdl64) { expectExactBoxRoom(hdl64Model()); }

// The floor at a known height below the sensor: every downward beam that
// reaches it reads its analytic distance, and lands on it.
void expectExactFloor(const LidarModelConstPtr& model) {
  const double floor_height = -1.73;
  const RayCaster caster(makeQuad({-200, -200, float(floor_height)}, {400, 0, 0}, {0, 400, 0}));
  const LidarSimulator simulator(model, caster, exactEffects(), 1);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(3, -2, 0);
  const SimulatedScan scan = simulator.simulate(standingStill(pose), 0.0, 0);
  int floor_pixels = 0;
  for (int v = 0; v < model->rows(); ++v)
    for (int u = 0; u < model->columns(); ++u) {
      const Beam beam = beamOf(*model, pose, u, v);
      const std::size_t i = scan.image.index(v, u);
      const double distance = (floor_height - beam.origin.z()) / beam.direction.z();
      const Eigen::Vector3d hit = beam.origin + distance * beam.direction;
      const bool reaches = beam.direction.z() < 0 && beam.n + distance <= 120.0 &&
                           hit.head<2>().cwiseAbs().maxCoeff() < 199.0;
      if (!reaches) {
        if (beam.direction.z() >= 0) ASSERT_FALSE(scan.image.valid(v, u)) << "row " << v << " column " << u;
        continue;
      }
      ++floor_pixels;
      const double expected = beam.n + distance;
      ASSERT_NEAR(scan.true_range[i], expected, floatTolerance(expected, beam.origin)) << "row " << v;
      ASSERT_TRUE(scan.image.valid(v, u));
      ASSERT_NEAR(scan.image.range[i], expected, kHalfMillimetre + floatTolerance(expected, beam.origin));
      const Eigen::Vector3d point = pose * model->unproject(u, v, scan.image.range[i]).cast<double>();
      ASSERT_LT(std::abs(point.z() - floor_height), 1e-3) << "row " << v << " column " << u;
    }
  EXPECT_GT(floor_pixels, model->columns() * model->rows() / 4);
}

TEST(LidarSimulator, FloorAtKnownHeightIsExactWithOusterTables) {
  REQUIRE_OUSTER_TABLES();
  expectExactFloor(ousterModel(ouster_json_path));
}

TEST(LidarSimulator, FloorAtKnownHeightIsExactWithHdl64) { expectExactFloor(hdl64Model()); }

using test::bruteForceDistance;

// A sphere (an icosphere fine enough that its facets stay within 0.13 mm of
// the true sphere): ranges exact against the mesh, points on the sphere.
void expectSphere(const LidarModelConstPtr& model) {
  const Eigen::Vector3d centre(8, 2, 0.5);
  const double radius = 2.5;
  const TriangleMesh sphere = makeSphere(centre.cast<float>(), float(radius), 6);
  const RayCaster caster(sphere);
  const LidarSimulator simulator(model, caster, exactEffects(), 1);
  const Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  const SimulatedScan scan = simulator.simulate(standingStill(pose), 0.0, 0);
  int hits = 0, checked = 0;
  double worst_surface = 0;
  for (int v = 0; v < model->rows(); ++v)
    for (int u = 0; u < model->columns(); ++u) {
      if (!scan.image.valid(v, u)) continue;
      ++hits;
      const std::size_t i = scan.image.index(v, u);
      const Eigen::Vector3d point = pose * model->unproject(u, v, scan.image.range[i]).cast<double>();
      worst_surface = std::max(worst_surface, std::abs((point - centre).norm() - radius));
      if (hits % 7 != 0) continue;  // brute force on a sample
      ++checked;
      const Beam beam = beamOf(*model, pose, u, v);
      const double expected = beam.n + bruteForceDistance(sphere, beam.origin, beam.direction);
      ASSERT_NEAR(scan.true_range[i], expected, floatTolerance(expected, beam.origin)) << "row " << v << " column " << u;
    }
  EXPECT_GT(checked, 100);
  EXPECT_LT(worst_surface, 1e-3);
  ::testing::Test::RecordProperty("worst_distance_to_sphere_m", scientific(worst_surface));
}

TEST(LidarSimulator, SphereIsHitExactlyWithOusterTables) {
  REQUIRE_OUSTER_TABLES();
  expectSphere(ousterModel(ouster_json_path));
}

TEST(LidarSimulator, SphereIsHitExactlyWithHdl64) { expectSphere(hdl64Model()); }

TEST(LidarSimulator, RangeNoiseHasTheConfiguredSigma) {
  const LidarModelConstPtr model = hdl64Model();
  const RayCaster caster(makeBox({-20, -15, -3}, {25, 18, 6}, true));
  SensorEffects effects = exactEffects();
  effects.range_noise_sigma_m = 0.02;
  const LidarSimulator simulator(model, caster, effects, 42);
  const SimulatedScan scan = simulator.simulate(standingStill(tiltedPose()), 0.0, 3);
  double sum = 0, sum_squares = 0;
  int count = 0, within_sigma = 0;
  for (std::size_t i = 0; i < scan.image.range.size(); ++i) {
    if (!isValidRange(scan.image.range[i])) continue;
    const double residual = double(scan.image.range[i]) - scan.true_range[i];
    sum += residual;
    sum_squares += residual * residual;
    within_sigma += std::abs(residual) <= effects.range_noise_sigma_m;
    ++count;
  }
  ASSERT_GT(count, 100000);
  const double mean = sum / count;
  // Millimetre quantisation adds 1/12 mm^2 of variance: 0.01 % of sigma here.
  const double deviation = std::sqrt(sum_squares / count - mean * mean);
  EXPECT_NEAR(deviation, effects.range_noise_sigma_m, 0.03 * effects.range_noise_sigma_m);
  EXPECT_NEAR(mean, 0.0, 4.0 * effects.range_noise_sigma_m / std::sqrt(double(count)));
  EXPECT_NEAR(double(within_sigma) / count, 0.6827, 0.01);  // Gaussian, not uniform
  ::testing::Test::RecordProperty("sample_sigma_m", scientific(deviation));
}

TEST(LidarSimulator, DropoutLosesTheConfiguredShare) {
  const LidarModelConstPtr model = hdl64Model();
  const RayCaster caster(makeBox({-20, -15, -3}, {25, 18, 6}, true));
  SensorEffects effects = exactEffects();
  effects.dropout_probability = 0.2;
  const LidarSimulator simulator(model, caster, effects, 5);
  const SimulatedScan scan = simulator.simulate(standingStill(tiltedPose()), 0.0, 0);
  const double pixels = double(scan.image.range.size());
  const double lost = pixels - scan.image.validCount();
  const double expected = effects.dropout_probability * pixels;
  EXPECT_NEAR(lost, expected, 5.0 * std::sqrt(pixels * 0.2 * 0.8));
}

TEST(LidarSimulator, MinAndMaxRangeRemoveReturns) {
  const LidarModelConstPtr model = hdl64Model();
  const RayCaster caster(makeBox({-9, -1.5f, -1.8f}, {2.5f, 12, 4}, true));
  SensorEffects effects;
  effects.min_range_m = 2.0;
  effects.max_range_m = 6.0;
  const LidarSimulator simulator(model, caster, effects, 5);
  const SimulatedScan scan = simulator.simulate(standingStill(Eigen::Isometry3d::Identity()), 0.0, 0);
  int short_ones = 0, long_ones = 0, kept = 0;
  for (std::size_t i = 0; i < scan.image.range.size(); ++i) {
    const float truth = scan.true_range[i];
    const float range = scan.image.range[i];
    if (isValidRange(range)) {
      ++kept;
      EXPECT_GE(range, 2.0f);
      EXPECT_LE(range, 6.0f);
    } else if (std::isnan(truth)) {
      ++long_ones;  // in a closed room: a wall beyond the rays' reach of max range
    } else {
      EXPECT_TRUE(truth < 2.001f || truth > 5.999f) << "lost a return at " << truth << " m";
      short_ones += truth < 2.0f;
    }
  }
  EXPECT_GT(kept, 1000);
  EXPECT_GT(short_ones, 1000);
  EXPECT_GT(long_ones, 1000);
}

TEST(LidarSimulator, BeamDivergenceReturnsTheNearestSurfaceInTheFootprint) {
  const LidarModelConstPtr model = hdl64Model();
  TriangleMesh scene = makeBox({-30, -30, -5}, {30, 30, 10}, true);
  for (int i = 0; i < 8; ++i)  // thin poles in front of the walls
    scene.append(makeCylinder({float(5 * std::cos(i * 0.8)), float(5 * std::sin(i * 0.8)), -5.0f}, 0.05f, 15.0f, 16));
  const RayCaster caster(scene);
  const auto mixed_pixels = [&](double divergence) {
    SensorEffects effects = exactEffects();
    effects.beam_divergence_rad = divergence;
    const LidarSimulator simulator(model, caster, effects, 1);
    const SimulatedScan scan = simulator.simulate(standingStill(Eigen::Isometry3d::Identity()), 0.0, 0);
    int mixed = 0;
    for (std::size_t i = 0; i < scan.image.range.size(); ++i) {
      EXPECT_LE(scan.image.range[i], scan.true_range[i] + kHalfMillimetre + 1e-5);
      mixed += scan.image.range[i] < scan.true_range[i] - 1.0f;  // a pole beside the centre ray
    }
    return mixed;
  };
  EXPECT_EQ(mixed_pixels(0.0), 0);
  const int wide = mixed_pixels(0.01);  // 5 cm footprint at 5 m: poles look wider
  EXPECT_GT(wide, 100);
}

TEST(LidarSimulator, MotionDistortionFollowsEachColumnsTime) {
  const LidarModelConstPtr model = hdl64Model();
  const double wall = 40.0, speed = 10.0;
  const RayCaster caster(makeQuad({float(wall), 1000, -1000}, {0, -2000, 0}, {0, 0, 2000}));
  Eigen::Isometry3d start = Eigen::Isometry3d::Identity(), end = Eigen::Isometry3d::Identity();
  end.translation().x() = speed * 2.0;
  const InterpolatedTrajectory trajectory({0.0, 2.0}, {start, end});  // 10 m/s along x
  for (bool distortion : {true, false}) {
    SensorEffects effects = exactEffects();
    effects.motion_distortion = distortion;
    const LidarSimulator simulator(model, caster, effects, 1);
    const double start_time = 0.5;
    const SimulatedScan scan = simulator.simulate(trajectory, start_time, 0);
    int checked = 0;
    double first_column_range = 0, last_column_range = 0;
    for (int u = 0; u < model->columns(); ++u) {
      const double time = distortion ? start_time + u / (model->columns() * 10.0) : start_time;
      EXPECT_NEAR(scan.column_poses[u].translation().x(), speed * time, 1e-9);
      Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
      pose.translation().x() = speed * time;
      for (int v = 0; v < model->rows(); ++v) {
        const Beam beam = beamOf(*model, pose, u, v);
        if (beam.direction.x() <= 0.5) continue;  // within 80 m
        const double expected = beam.n + (wall - beam.origin.x()) / beam.direction.x();
        ASSERT_NEAR(scan.true_range[scan.image.index(v, u)], expected, floatTolerance(expected, beam.origin))
            << "row " << v << " column " << u << (distortion ? " with" : " without") << " distortion";
        ++checked;
      }
      const int v = 40;
      if (u == 1) first_column_range = scan.true_range[scan.image.index(v, u)];
      if (u == model->columns() - 1) last_column_range = scan.true_range[scan.image.index(v, u)];
    }
    EXPECT_GT(checked, 10000);
    // Columns 1 and W-1 look the same way mirrored about x, almost a
    // revolution (1 m) apart along the wall's normal.
    const double travelled = distortion ? speed * (model->columns() - 2) / (model->columns() * 10.0) : 0.0;
    EXPECT_NEAR(first_column_range - last_column_range, travelled / model->direction(1, 40).x(), 1e-4);
  }
}

TEST(LidarSimulator, FillsTimestampsIdsStatusAndTheColumnWindow) {
  REQUIRE_OUSTER_TABLES();
  LidarIntrinsics intrinsics = loadOusterMetadata(ouster_json_path).intrinsics;
  intrinsics.column_window = {100, 899};
  const auto model = std::make_shared<const LidarModel>(intrinsics);
  const RayCaster caster(makeBox({-10, -10, -3}, {10, 10, 4}, true));
  const LidarSimulator simulator(model, caster, exactEffects(), 1, 10.0);
  const double start_time = 12.3;
  const SimulatedScan scan = simulator.simulate(standingStill(Eigen::Isometry3d::Identity()), start_time, 77);
  EXPECT_EQ(scan.raw.frame_id, 77u);
  EXPECT_EQ(scan.image.frame_id, 77u);
  EXPECT_EQ(scan.start_time_s, start_time);
  for (int u = 0; u < model->columns(); ++u) {
    const double time = start_time + u / (1024 * 10.0);
    EXPECT_EQ(scan.raw.timestamp_ns[u], static_cast<uint64_t>(std::llround(time * 1e9)));
    EXPECT_EQ(scan.raw.measurement_id[u], u);
    const bool inside = u >= 100 && u <= 899;
    EXPECT_EQ(scan.raw.status[u] != 0, inside) << "column " << u;
    EXPECT_EQ(scan.image.column_timestamp_ns[u], inside ? scan.raw.timestamp_ns[u] : 0u);
    for (int v = 0; v < model->rows(); v += 9) {
      EXPECT_EQ(scan.image.valid(v, u), inside);
      EXPECT_EQ(std::isnan(scan.true_range[scan.image.index(v, u)]), !inside);
      if (inside) EXPECT_GE(scan.raw.signal[scan.image.index(v, u)], 1);
    }
  }
  EXPECT_EQ(scan.image.stamp_ns, scan.raw.timestamp_ns[100]);
  EXPECT_EQ(scan.image.intensity_field, "reflectivity");
}

TEST(LidarSimulator, SameSeedSameScanWhateverTheThreads) {
  const LidarModelConstPtr model = hdl64Model();
  TriangleMesh scene = makeBox({-30, -30, -5}, {30, 30, 10}, true);
  scene.append(makeSphere({4, 3, 0}, 1.5f, 3));
  const RayCaster caster(scene);
  SensorEffects effects;
  effects.range_noise_sigma_m = 0.03;
  effects.dropout_probability = 0.1;
  effects.beam_divergence_rad = 0.003;
  Scene route_scene;
  route_scene.route = {{-10, -10, 0}, {10, -10, 0}, {10, 10, 0}, {-10, 10, 0}};
  MotionOptions motion;
  motion.profile = MotionProfile::kHandheld;
  motion.duration_s = 2.0;
  const auto trajectory = makeTrajectory(route_scene, motion);
  const LidarSimulator simulator(model, caster, effects, 9);
  const SimulatedScan first = simulator.simulate(*trajectory, 0.5, 4);
  SimulatedScan single_thread;
  {
    tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
    simulator.simulate(*trajectory, 0.5, 4, single_thread);
  }
  EXPECT_TRUE(first.raw.range == single_thread.raw.range);
  EXPECT_TRUE(first.raw.reflectivity == single_thread.raw.reflectivity);
  EXPECT_TRUE(first.raw.timestamp_ns == single_thread.raw.timestamp_ns);
  SimulatedScan reused = single_thread;  // buffers reused, same result
  simulator.simulate(*trajectory, 0.5, 4, reused);
  EXPECT_TRUE(first.raw.range == reused.raw.range);
  const LidarSimulator other_seed(model, caster, effects, 10);
  EXPECT_FALSE(first.raw.range == other_seed.simulate(*trajectory, 0.5, 4).raw.range);
  EXPECT_FALSE(first.raw.range == simulator.simulate(*trajectory, 0.5, 5).raw.range);  // other frame
}

TEST(LidarSimulator, RejectsBadSettingsNamingThem) {
  const LidarModelConstPtr model = hdl64Model();
  const RayCaster caster(makeBox({-10, -10, -3}, {10, 10, 4}, true));
  const auto message = [&](SensorEffects effects, double frequency = 10.0) -> std::string {
    try {
      LidarSimulator simulator(model, caster, effects, 1, frequency);
    } catch (const std::invalid_argument& error) {
      return error.what();
    }
    return "no error";
  };
  SensorEffects effects;
  effects.range_noise_sigma_m = -0.1;
  EXPECT_NE(message(effects).find("range_noise_sigma_m"), std::string::npos);
  effects = SensorEffects();
  effects.dropout_probability = 1.5;
  EXPECT_NE(message(effects).find("dropout_probability"), std::string::npos);
  effects = SensorEffects();
  effects.min_range_m = 10;
  effects.max_range_m = 5;
  EXPECT_NE(message(effects).find("max_range_m must be above min_range_m"), std::string::npos);
  effects = SensorEffects();
  effects.max_range_m = 600;
  EXPECT_NE(message(effects).find("max_range_m"), std::string::npos);
  EXPECT_NE(message(SensorEffects(), 0.0).find("frequency_hz"), std::string::npos);
  EXPECT_THROW(LidarSimulator(nullptr, caster, SensorEffects(), 1), std::invalid_argument);

  const LidarSimulator simulator(model, caster, SensorEffects(), 1);
  const InterpolatedTrajectory short_one({0.0, 0.05}, {Eigen::Isometry3d::Identity(), Eigen::Isometry3d::Identity()});
  try {
    simulator.simulate(short_one, 0.0, 0);  // a revolution takes 0.1 s
    FAIL() << "expected an error";
  } catch (const std::out_of_range& error) {
    EXPECT_NE(std::string(error.what()).find("the trajectory covers [0, 0.05] s"), std::string::npos)
        << error.what();
  }
  EXPECT_THROW(simulator.simulate(standingStill(Eigen::Isometry3d::Identity()), -1.0, 0), std::invalid_argument);
}

}  // namespace
}  // namespace range_image_mapping::simulation
