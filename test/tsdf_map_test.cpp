// TsdfMap: what it refuses (and that a refused scan leaves the map as it
// was), pose jumps, the memory radius and budget, the mesh, reset. Scans of
// analytic rooms from the simulator with the real OS0-128 tables where the
// shared data is present (a built-in approximation otherwise).
#include "range_image_mapping/io/mesh_file.h"
#include "range_image_mapping/mapping/tsdf_map.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/simulation/lidar_simulator.h"
#include "range_image_mapping/simulation/mesh_primitives.h"
#include "range_image_mapping/simulation/sensor_presets.h"
#include "error_text.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <iostream>
#include <cstdio>
#include <map>

namespace range_image_mapping::mapping {
namespace {

using test::contains;
using test::errorOf;

LidarModelConstPtr os0() {
  static const LidarModelConstPtr model = [] {
    const std::string path = test::dataFile("ouster-pcaps/OS-0-128-U1_v2.3.0_1024x10.json");
    const OusterMetadata metadata =
        path.empty() ? parseOusterMetadata(
                           simulation::ousterLikeMetadataJson("OS-0-128", UdpProfile::kRng19Rfl8Sig16Nir16))
                     : loadOusterMetadata(path);
    return std::make_shared<const LidarModel>(metadata.intrinsics);
  }();
  return model;
}

// A long hall, 90 m x 10 m x 4 m: far larger than the clip. Its faces are
// off the voxel lattice, so that no mesh vertex lies on them by construction.
const Eigen::Vector3f kHallLow(-10.03f, -5.04f, -1.47f), kHallHigh(80.02f, 4.97f, 2.53f);
const TriangleMesh& hall() {
  static const TriangleMesh mesh = simulation::makeBox(kHallLow, kHallHigh, true);
  return mesh;
}

// A still scan of the hall from (x, y, 0), exact ranges.
struct Scan {
  RangeImage image;
  ScanPose pose;
};
Scan scanAt(double x, double y = 0.0) {
  static const simulation::RayCaster caster(hall());
  simulation::SensorEffects effects;
  effects.min_range_m = 0.0;
  const simulation::LidarSimulator simulator(os0(), caster, effects, 5);
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(0.3 * x, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.translation() = Eigen::Vector3d(x, y, 0.0);
  Scan scan;
  scan.image = simulator.simulate(simulation::InterpolatedTrajectory({0.0, 1.0}, {pose, pose}), 0.1, 1).image;
  scan.pose.world_from_lidar = pose;
  return scan;
}

TsdfMapOptions mapOptions() {
  TsdfMapOptions options;
  options.grid.voxel_size_m = 0.1;
  options.integrator.max_range_m = 12.0;
  options.max_pose_jump_m = 20.0;
  options.max_refused_jumps = 3;
  return options;
}

using GridSnapshot = std::map<std::array<int, 3>, std::vector<float>>;
GridSnapshot snapshot(const VoxelBlockGrid& grid) {
  GridSnapshot result;
  for (const VoxelBlock* block : grid.blocks()) {
    std::vector<float> values = block->sdf;
    values.insert(values.end(), block->weight.begin(), block->weight.end());
    values.push_back(float(block->changed_generation));
    result[{block->key.x(), block->key.y(), block->key.z()}] = std::move(values);
  }
  return result;
}

TEST(TsdfMap, RefusesBadScansWithAWarningAndLeavesTheMapAsItWas) {
  TsdfMap map(mapOptions());
  const Scan scan = scanAt(0.0);
  const MapUpdate first = map.integrate(scan.image, scan.pose);
  ASSERT_TRUE(first.integrated) << first.warning;
  EXPECT_TRUE(first.warning.empty()) << first.warning;
  EXPECT_GT(first.integration.voxels_updated, 0u);
  const GridSnapshot before = snapshot(map.grid());

  const auto expectRefused = [&](const RangeImage& image, const ScanPose& pose, const std::string& why) {
    MapUpdate update;
    EXPECT_NO_THROW(update = map.integrate(image, pose));
    EXPECT_FALSE(update.integrated);
    EXPECT_TRUE(contains(update.warning, why)) << update.warning;
    EXPECT_EQ(update.integration.voxels_updated, 0u);
    EXPECT_TRUE(snapshot(map.grid()) == before) << why;
  };
  ScanPose nan_pose = scan.pose;
  nan_pose.world_from_lidar.linear()(2, 2) = std::nan("");
  expectRefused(scan.image, nan_pose, "pose is not finite");
  ScanPose nan_twist = scan.pose;
  nan_twist.twist[0] = std::nan("");
  expectRefused(scan.image, nan_twist, "twist is not finite");
  RangeImage no_model = scan.image;
  no_model.model.reset();
  expectRefused(no_model, scan.pose, "no sensor model");
  expectRefused(RangeImage(os0()), scan.pose, "no valid pixels");
  expectRefused(scan.image.destaggered(), scan.pose, "destaggered");

  const MapStatistics statistics = map.statistics();
  EXPECT_EQ(statistics.scans_integrated, 1u);
  EXPECT_EQ(statistics.scans_refused, 5u);
  EXPECT_EQ(statistics.blocks, before.size());
  // The refusals did not count as pose jumps or move the last pose.
  EXPECT_TRUE(map.integrate(scanAt(1.0).image, scanAt(1.0).pose).integrated);
}

TEST(TsdfMap, PoseJumpIsRefusedUntilItPersists) {
  TsdfMap map(mapOptions());
  const Scan start = scanAt(0.0), far = scanAt(25.0), farther = scanAt(26.0), farthest = scanAt(50.0);
  ASSERT_TRUE(map.integrate(start.image, start.pose).integrated);
  const GridSnapshot before = snapshot(map.grid());
  for (int refusal = 1; refusal <= 3; ++refusal) {
    const MapUpdate update = map.integrate(far.image, far.pose);
    EXPECT_FALSE(update.integrated);
    EXPECT_TRUE(contains(update.warning, "jumped 25 m")) << update.warning;
    EXPECT_TRUE(contains(update.warning, "refusal " + std::to_string(refusal) + " of 3")) << update.warning;
    EXPECT_TRUE(snapshot(map.grid()) == before);
  }
  const MapUpdate taken = map.integrate(far.image, far.pose);
  EXPECT_TRUE(taken.integrated);
  EXPECT_TRUE(contains(taken.warning, "taken after 3 refusals")) << taken.warning;
  // The new position is the reference now: a small step is fine, and the
  // count starts again for the next jump.
  const MapUpdate step = map.integrate(farther.image, farther.pose);
  EXPECT_TRUE(step.integrated);
  EXPECT_TRUE(step.warning.empty()) << step.warning;
  EXPECT_FALSE(map.integrate(farthest.image, farthest.pose).integrated);
  EXPECT_EQ(map.statistics().scans_integrated, 3u);
  EXPECT_EQ(map.statistics().scans_refused, 4u);

  TsdfMapOptions any_jump = mapOptions();
  any_jump.max_pose_jump_m = 0.0;
  TsdfMap accepting(any_jump);
  EXPECT_TRUE(accepting.integrate(start.image, start.pose).integrated);
  EXPECT_TRUE(accepting.integrate(farthest.image, farthest.pose).integrated);
}

TEST(TsdfMap, MemoryRadiusDropsBlocksFarFromTheSensor) {
  TsdfMapOptions options = mapOptions();
  options.memory_radius_m = 15.0;
  TsdfMap map(options);
  std::size_t dropped = 0;
  for (const double x : {0.0, 10.0, 20.0, 30.0}) {
    const Scan scan = scanAt(x);
    const MapUpdate update = map.integrate(scan.image, scan.pose);
    ASSERT_TRUE(update.integrated) << update.warning;
    dropped += update.blocks_dropped;
    const double block = map.grid().blockSize();
    for (const VoxelBlock* kept : map.grid().blocks()) {
      const Eigen::Vector3d centre = (kept->key.cast<double>() + Eigen::Vector3d::Constant(0.5)) * block;
      ASSERT_LE((centre - scan.pose.world_from_lidar.translation()).norm(), 15.0);
    }
  }
  // In voxels, whatever the block edge: 500 blocks of 8^3.
  EXPECT_GT(dropped * map.grid().voxelsPerBlock(), 500u * 512u);
  // The scans' own surroundings are all still there.
  TsdfMap unbounded(mapOptions());
  const Scan last = scanAt(30.0);
  unbounded.integrate(last.image, last.pose);
  for (const VoxelBlock* block : unbounded.grid().blocks()) EXPECT_NE(map.grid().find(block->key), nullptr);
}

TEST(TsdfMap, MemoryBudgetWarnsAndKeepsWhatIsMapped) {
  const Scan first = scanAt(0.0), second = scanAt(8.0, 1.0);
  TsdfMap unlimited(mapOptions());
  const MapUpdate first_update = unlimited.integrate(first.image, first.pose);
  const std::size_t first_blocks = unlimited.grid().blockCount();
  // Activation creates candidate blocks and removes again those no voxel of
  // the scan reaches, so the budget bounds the candidates: a trial with a
  // budget of the kept blocks tells how many more the scan asks for.
  (void)first_update;
  TsdfMapOptions trial_options = mapOptions();
  trial_options.grid.max_blocks = first_blocks;
  TsdfMap trial(trial_options);
  const std::size_t first_candidates = first_blocks + trial.integrate(first.image, first.pose).integration.blocks_refused;
  unlimited.integrate(second.image, second.pose);
  const std::size_t growth = unlimited.grid().blockCount() - first_blocks;
  // In voxels, whatever the block edge: 400 blocks of 8^3.
  ASSERT_GT(growth * unlimited.grid().voxelsPerBlock(), 400u * 512u);
  // Room for a third of what the second scan adds: the budget must bite.
  const std::size_t budget = first_candidates + growth / 3;

  TsdfMapOptions options = mapOptions();
  options.grid.max_blocks = budget;
  TsdfMap bounded(options);
  const MapUpdate fits = bounded.integrate(first.image, first.pose);
  EXPECT_TRUE(fits.warning.empty()) << fits.warning;
  const MapUpdate full = bounded.integrate(second.image, second.pose);
  EXPECT_TRUE(full.integrated);
  EXPECT_GT(full.integration.blocks_refused, 0u);
  EXPECT_TRUE(contains(full.warning, "memory budget (max_blocks " + std::to_string(budget) + ")")) << full.warning;
  EXPECT_LE(bounded.grid().blockCount(), budget);
  // Every block the budget allowed holds exactly what it holds without a budget.
  std::size_t compared = 0;
  for (const VoxelBlock* block : bounded.grid().blocks()) {
    const VoxelBlock* reference = unlimited.grid().find(block->key);
    ASSERT_NE(reference, nullptr);
    ASSERT_EQ(block->sdf, reference->sdf);
    ASSERT_EQ(block->weight, reference->weight);
    ++compared;
  }
  EXPECT_GE(compared, first_blocks);
}

TEST(TsdfMap, MeshFollowsTheMapAndIsSavedAsPly) {
  TsdfMap map(mapOptions());
  const Scan scan = scanAt(0.0);
  map.integrate(scan.image, scan.pose);
  const MeshUpdate first = map.updateMesh();
  EXPECT_FALSE(first.changed.empty());
  EXPECT_GT(map.statistics().triangles, 1000u);
  EXPECT_EQ(map.statistics().triangles, map.mesh().triangleCount());
  // Nothing changed: nothing to re-mesh.
  EXPECT_TRUE(map.updateMesh().changed.empty());
  const std::string path = ::testing::TempDir() + "tsdf_map_test_mesh.ply";
  io::saveMeshFile(path, map.fullMesh());
  const TriangleMesh saved = io::loadMeshFile(path);
  EXPECT_EQ(saved.triangles.size(), map.mesh().combined().triangles.size());
  // The mesh lies on the hall's faces. The nearest pixel's range differs from
  // the voxel's own direction's by up to r tan(incidence) times half a pixel
  // (0.35 deg on an OS0): the side walls right beside the sensor (incidence
  // below 18 deg) are within a voxel / 10, all faces within a voxel.
  const Eigen::Vector3f low = kHallLow, high = kHallHigh;
  double worst_wall = 0.0, worst = 0.0;
  std::size_t wall_vertices = 0;
  for (const Eigen::Vector3f& vertex : saved.vertices) {
    const double distance = std::min((vertex - low).cwiseAbs().minCoeff(), (vertex - high).cwiseAbs().minCoeff());
    worst = std::max(worst, distance);
    const double to_side_wall = std::min(std::abs(vertex.y() - low.y()), std::abs(vertex.y() - high.y()));
    if (to_side_wall < 0.2 && std::abs(vertex.x()) < 1.2 && std::abs(vertex.z()) < 1.0) {
      worst_wall = std::max(worst_wall, to_side_wall);
      ++wall_vertices;
    }
  }
  std::cout << "mesh: side walls within " << worst_wall * 1000 << " mm (" << wall_vertices
            << " vertices), everything within " << worst * 1000 << " mm\n";
  EXPECT_GT(wall_vertices, 300u);
  EXPECT_LT(worst_wall, 0.01);
  EXPECT_LT(worst, 0.1);
  std::remove(path.c_str());
}

// A budgeted Mapper meshes a few blocks per update and lets blocks that
// changed by less than the tolerance wait; the saved mesh must still be the
// whole map's, exactly as one full extraction gives it.
TEST(TsdfMap, FullMeshIsExactWhateverTheUpdateBudget) {
  TsdfMapOptions options = mapOptions();
  options.mesh.max_blocks_per_update = 5;
  TsdfMap map(options);
  for (double x : {0.0, 0.4, 0.8}) {
    const Scan scan = scanAt(x);
    ASSERT_TRUE(map.integrate(scan.image, scan.pose).integrated);
    map.updateMesh();
  }
  ASSERT_GT(map.mesh().pendingCount(), 0u) << "the budget should have left blocks to mesh";
  const TriangleMesh full = map.fullMesh();
  const TriangleMesh reference = extractMesh(map.grid(), options.mesh);
  EXPECT_EQ(map.mesh().pendingCount(), 0u);
  ASSERT_GT(reference.triangles.size(), 1000u);
  EXPECT_EQ(full.triangles.size(), reference.triangles.size());
  EXPECT_EQ(full.vertices.size(), reference.vertices.size());
}

TEST(TsdfMap, ResetForgetsTheMapAndTheLastPose) {
  TsdfMap map(mapOptions());
  const Scan start = scanAt(0.0), far = scanAt(50.0);
  map.integrate(start.image, start.pose);
  map.updateMesh();
  ASSERT_GT(map.statistics().triangles, 0u);
  map.reset();
  const MapStatistics statistics = map.statistics();
  EXPECT_EQ(statistics.blocks, 0u);
  EXPECT_EQ(statistics.triangles, 0u);
  EXPECT_EQ(statistics.scans_integrated, 0u);
  // No last pose any more: a scan anywhere starts the new map.
  EXPECT_TRUE(map.integrate(far.image, far.pose).integrated);
  map.updateMesh();
  EXPECT_GT(map.statistics().triangles, 1000u);
}

TEST(TsdfMap, BadOptionsNameTheField) {
  const auto message = [](const std::function<void(TsdfMapOptions&)>& change) {
    TsdfMapOptions options = mapOptions();
    change(options);
    return errorOf([&] { TsdfMap map(options); });
  };
  EXPECT_TRUE(contains(message([](TsdfMapOptions& o) { o.memory_radius_m = 10.0; }), "memory_radius_m must exceed"));
  EXPECT_TRUE(contains(message([](TsdfMapOptions& o) { o.memory_radius_m = -1.0; }), "memory_radius_m"));
  EXPECT_TRUE(contains(message([](TsdfMapOptions& o) { o.max_pose_jump_m = std::nan(""); }), "max_pose_jump_m"));
  EXPECT_TRUE(contains(message([](TsdfMapOptions& o) { o.max_refused_jumps = 0; }), "max_refused_jumps"));
  EXPECT_TRUE(contains(message([](TsdfMapOptions& o) { o.grid.voxel_size_m = 0.0; }), "voxel_size_m"));
  EXPECT_TRUE(contains(message([](TsdfMapOptions& o) { o.integrator.point_stride = 0; }), "point_stride"));
  EXPECT_TRUE(contains(message([](TsdfMapOptions& o) { o.mesh.min_weight = -1.0f; }), "min_weight"));
  EXPECT_TRUE(contains(message([](TsdfMapOptions& o) { o.mesh.min_weight = 1.0f; }), "must equal mesh.min_weight"));
  EXPECT_EQ(message([](TsdfMapOptions& o) { o.mesh.min_weight = o.integrator.mesh_min_weight = 1.0f; }),
            "no exception");
  EXPECT_EQ(message([](TsdfMapOptions& o) { o.memory_radius_m = 12.5; }), "no exception");
}

}  // namespace
}  // namespace range_image_mapping::mapping
