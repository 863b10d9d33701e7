// The mapping stack against exact ground truth (issue 5): simulated
// indoor_cart and outdoor_car sequences through TsdfMap, scored with the
// paper's F-score at 3 x voxel against the scene's seen surface, and against
// OctoMap on the same scans; analytic scenes through the whole pipeline (a
// box room that meshes to a closed surface, a sphere meshed on its radius).
#include "octomap_baseline.h"
#include "simulated_mapping_sequence.h"

#include "range_image_mapping/evaluation/surface_metrics.h"
#include "range_image_mapping/mapping/tsdf_map.h"
#include "range_image_mapping/simulation/mesh_primitives.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

namespace range_image_mapping::mapping {
namespace {

TsdfMapOptions mapOptionsFor(const test::MappingPreset& preset) {
  TsdfMapOptions options;
  options.grid.voxel_size_m = preset.voxel_m;
  options.integrator.min_range_m = preset.min_range_m;
  options.integrator.max_range_m = preset.max_range_m;
  return options;
}

void printMetrics(const char* what, const evaluation::SurfaceMetrics& metrics) {
  std::printf("  %-26s at %.3f m: P %.4f  R %.4f  F %.4f  (%zu points, accuracy median %.4f m)\n", what,
              metrics.threshold_m, metrics.precision, metrics.recall, metrics.f_score, metrics.estimate_points,
              metrics.accuracy_median_m);
}

// The sequence integrated into a TsdfMap (every scan must be accepted), its
// incremental mesh sampled for compareSurfaces.
std::vector<Eigen::Vector3f> tsdfSurface(const test::MappingPreset& preset,
                                         const test::SimulatedMappingSequence& sequence) {
  TsdfMap map(mapOptionsFor(preset));
  for (std::size_t k = 0; k < sequence.scans.size(); ++k) {
    const MapUpdate update = map.integrate(sequence.scans[k], sequence.poses[k]);
    EXPECT_TRUE(update.integrated) << "scan " << k << ": " << update.warning;
  }
  map.updateMesh();
  return test::meshSamples(map.mesh().combined(), preset.sampleSpacingM());
}

std::vector<Eigen::Vector3f> octomapSurface(const test::MappingPreset& preset,
                                            const test::SimulatedMappingSequence& sequence) {
  test::OctomapBaselineOptions options;
  options.resolution_m = preset.voxel_m;
  options.min_range_m = preset.min_range_m;
  options.max_range_m = preset.max_range_m;
  test::OctomapBaseline octomap(options);
  for (std::size_t k = 0; k < sequence.scans.size(); ++k)
    octomap.insert(sequence.scans[k], sequence.poses[k].world_from_lidar, sequence.poses[k].twist);
  return octomap.occupiedCentres();
}

// The issue's targets: F at 3 x voxel over 20 scans, every 5th frame of a
// 10 s route (the cart covers ~10 m of corridors and rooms, the car ~100 m
// of streets).
evaluation::SurfaceMetrics issueTargetRun(const test::MappingPreset& preset) {
  const test::SimulatedMappingSequence sequence = test::simulateMappingSequence(preset, 20, 5);
  const evaluation::SurfaceMetrics metrics =
      evaluation::compareSurfaces(tsdfSurface(preset, sequence), sequence.surface, preset.thresholdM());
  std::printf("%s, %zu scans, voxel %.2f m, clip %.0f m, %zu ground-truth samples:\n", preset.name.c_str(),
              sequence.scans.size(), preset.voxel_m, preset.max_range_m, sequence.surface.size());
  printMetrics("TSDF mesh", metrics);
  return metrics;
}

TEST(MappingAccuracy, IndoorCartMeshReachesTheIssueTarget) {
  EXPECT_GE(issueTargetRun(test::indoorCartPreset()).f_score, 0.99);
}

// (0.954 with eq. 9 along the ray: recall 0.91, the far ground between beam
// rings missing; point-to-plane distances: 0.975, recall 0.99, precision
// 0.96 with the plane filling the gaps between far rings; 0.996 with the
// plane within plane_fill of a return.)
TEST(MappingAccuracy, OutdoorCarMeshReachesTheIssueTarget) {
  EXPECT_GE(issueTargetRun(test::outdoorCarPreset()).f_score, 0.99);
}

// OctoMap on the same scans (30 consecutive scans, as mapping_benchmark:
// OctoMap needs 1-2 s of one core per scan), same clip, same resolution, its
// default sensor model (insertPointCloud, hit 0.7 / miss 0.4); its surface
// is the centres of its occupied leaves. Against the issue's truth (the
// scene within a voxel of a hit) OctoMap's precision is 1 by construction:
// its occupied leaves are where the hits fell, and so is the truth; its
// recall falls as rays through leaves at grazing incidence clear them (on
// fewer than ~10 scans it is still near 1, and higher than ours). Finer
// thresholds show what each map knows of where the surface is: a zero
// crossing within the voxel, a leaf centre within half a voxel. Asserted:
// the paper's claim, a higher F at 3 x voxel, and at half a voxel F and
// the median accuracy; precision against every surface near the route.
void compareWithOctomap(const test::MappingPreset& preset) {
  const test::SimulatedMappingSequence sequence = test::simulateMappingSequence(preset, 30, 1);
  const std::vector<Eigen::Vector3f> scene = test::sceneSurfaceNearRoute(preset, sequence);
  const std::vector<Eigen::Vector3f> ours = tsdfSurface(preset, sequence);
  const std::vector<Eigen::Vector3f> octomap = octomapSurface(preset, sequence);
  std::printf("%s, %zu scans, voxel %.2f m, clip %.0f m, %zu ground-truth samples (%zu on the scene near the "
              "route):\n",
              preset.name.c_str(), sequence.scans.size(), preset.voxel_m, preset.max_range_m, sequence.surface.size(),
              scene.size());
  const std::vector<float> ours_to_scene = evaluation::nearestDistances(ours, scene);
  const std::vector<float> octomap_to_scene = evaluation::nearestDistances(octomap, scene);
  for (const double voxels : {3.0, 1.0, 0.5}) {
    const double threshold = voxels * preset.voxel_m;
    const evaluation::SurfaceMetrics ours_metrics = evaluation::compareSurfaces(ours, sequence.surface, threshold);
    const evaluation::SurfaceMetrics octomap_metrics =
        evaluation::compareSurfaces(octomap, sequence.surface, threshold);
    const double ours_on_scene = evaluation::shareBelow(ours_to_scene, threshold);
    const double octomap_on_scene = evaluation::shareBelow(octomap_to_scene, threshold);
    printMetrics("TSDF mesh", ours_metrics);
    std::printf("  %-26s           P against the whole scene %.4f\n", "", ours_on_scene);
    printMetrics("OctoMap occupied centres", octomap_metrics);
    std::printf("  %-26s           P against the whole scene %.4f\n", "", octomap_on_scene);
    if (voxels == 3.0) {
      EXPECT_GT(ours_metrics.f_score, octomap_metrics.f_score);
      EXPECT_GT(ours_on_scene, 0.999);
    }
    if (voxels == 0.5) {
      EXPECT_GT(ours_metrics.f_score, octomap_metrics.f_score);
      EXPECT_LT(ours_metrics.accuracy_median_m, octomap_metrics.accuracy_median_m);
    }
  }
}

TEST(MappingAccuracy, IndoorCartMeshAgainstOctomap) { compareWithOctomap(test::indoorCartPreset()); }

TEST(MappingAccuracy, OutdoorCarMeshAgainstOctomap) { compareWithOctomap(test::outdoorCarPreset()); }

// ---------------------------------------------------------------- analytic scenes

// The sensor driven around a vertical circle at a constant body twist
// (forward speed and yaw rate), x along the tangent: exact motion distortion
// with a twist the integrator can undo exactly.
class CircleTrajectory : public simulation::Trajectory {
 public:
  CircleTrajectory(const Eigen::Vector3d& centre, double radius_m, double yaw_rate)
      : centre_(centre), radius_(radius_m), yaw_rate_(yaw_rate) {}
  Eigen::Isometry3d pose(double time_s) const override {
    const double angle = yaw_rate_ * time_s;
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() = centre_ + radius_ * Eigen::Vector3d(std::cos(angle), std::sin(angle), 0.0);
    pose.linear() = Eigen::AngleAxisd(angle + M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    return pose;
  }
  double startTime() const override { return 0.0; }
  double endTime() const override { return 1e3; }

 private:
  Eigen::Vector3d centre_;
  double radius_, yaw_rate_;
};

LidarModelConstPtr os0Model() {
  static const LidarModelConstPtr model = test::ousterLikeModel("OS-0-128");
  return model;
}

// scans_per_circle scans spread over one lap of each circle, with the presets'
// 1 cm noise and the true sweep twist, integrated into a 4 cm, 10 m map.
TsdfMap mapAnalyticScene(const TriangleMesh& scene, const std::vector<CircleTrajectory>& circles, int scans_per_circle,
                         double yaw_rate) {
  const simulation::RayCaster caster(scene);
  simulation::SensorEffects effects;
  effects.range_noise_sigma_m = 0.01;
  const simulation::LidarSimulator simulator(os0Model(), caster, effects, 1);
  TsdfMapOptions options;
  options.grid.voxel_size_m = 0.04;
  options.integrator.max_range_m = 10.0;
  TsdfMap map(options);
  const double lap_s = 2.0 * M_PI / yaw_rate;
  uint32_t frame = 0;
  for (const CircleTrajectory& circle : circles)
    for (int k = 0; k < scans_per_circle; ++k) {
      const double start = 0.5 + lap_s * k / scans_per_circle;
      const simulation::SimulatedScan scan = simulator.simulate(circle, start, frame++);
      ScanPose pose;
      pose.world_from_lidar = scan.column_poses.front();
      pose.twist = twistBetween(scan.column_poses.front(), scan.column_poses.back(),
                                simulator.columnTime(start, os0Model()->columns() - 1) - start);
      pose.scan_time_ns = scanTime(scan.image, ScanTimeSource::kFirstValidColumn);
      const MapUpdate update = map.integrate(scan.image, pose);
      EXPECT_TRUE(update.integrated) << update.warning;
    }
  map.updateMesh();
  return map;
}

// A 6 x 5 x 3 m room seen from two laps (1.5 m radius, at 1.0 and 2.0 m
// height): every wall, the floor and the ceiling are observed (the OS0's
// +-45 deg field of view sees the floor under one side of the lap from the
// other), so the zero crossing closes on itself.
TEST(MappingAccuracy, BoxRoomMeshesToAClosedSurface) {
  const Eigen::Vector3f low(-3.0f, -2.5f, 0.0f), high(3.0f, 2.5f, 3.0f);
  const double yaw_rate = 0.5;
  const std::vector<CircleTrajectory> laps{{{0.2, 0.1, 1.0}, 1.5, yaw_rate}, {{-0.1, 0.2, 2.0}, 1.5, yaw_rate}};
  const TsdfMap map = mapAnalyticScene(simulation::makeBox(low, high, true), laps, 12, yaw_rate);
  const TriangleMesh mesh = extractMesh(map.grid());
  ASSERT_GT(mesh.triangles.size(), 1000u);
  EXPECT_EQ(countBoundaryEdges(mesh.triangles), 0u);
  // Every vertex on a wall (noise averaged over 24 scans: well within a voxel).
  double worst = 0.0;
  Eigen::Vector3f worst_vertex = Eigen::Vector3f::Zero();
  for (const Eigen::Vector3f& vertex : mesh.vertices) {
    const double off_wall = std::min((vertex - low).cwiseAbs().minCoeff(), (vertex - high).cwiseAbs().minCoeff());
    if (off_wall > worst) worst = off_wall, worst_vertex = vertex;
  }
  std::printf("box room: %zu triangles, %zu boundary edges, worst vertex %.4f m off the walls\n",
              mesh.triangles.size(), countBoundaryEdges(mesh.triangles), worst);
  EXPECT_LT(worst, 0.04) << "at " << worst_vertex.transpose();
  // The incremental mesh is the same surface.
  EXPECT_EQ(map.mesh().triangleCount(), mesh.triangles.size());
  EXPECT_EQ(countBoundaryEdges(map.mesh().combined().triangles), 0u);
}

// A sphere of radius 0.8 m in a room, seen from laps below and above it
// (24 scans per lap, 15 deg apart): its mesh vertices lie on the true radius
// within a quarter voxel (1 cm), for the median and the 95th percentile of
// |distance to centre - radius|. (The error is the nearest-pixel association
// at grazing incidence, not the noise: with 12 scans per lap the 95th
// percentile is 1.04 cm, noise-free as with 1 cm noise.)
TEST(MappingAccuracy, SphereMeshLiesOnTheTrueRadius) {
  const Eigen::Vector3f centre(0.0f, 0.0f, 1.6f);
  const float radius = 0.8f;
  TriangleMesh scene = simulation::makeBox({-4.0f, -4.0f, 0.0f}, {4.0f, 4.0f, 3.5f}, true);
  scene.append(simulation::makeSphere(centre, radius, 6));
  const double yaw_rate = 0.5;
  const std::vector<CircleTrajectory> laps{{{0, 0, 0.6}, 2.2, yaw_rate}, {{0, 0, 2.8}, 2.2, yaw_rate}};
  const TsdfMap map = mapAnalyticScene(scene, laps, 24, yaw_rate);
  const TriangleMesh mesh = extractMesh(map.grid());
  std::vector<double> errors;
  for (const Eigen::Vector3f& vertex : mesh.vertices) {
    const double distance = (vertex - centre).norm();
    if (distance < radius + 0.3) errors.push_back(std::abs(distance - radius));
  }
  // At least 0.8 vertices per voxel face of the sphere's area (marching cubes
  // makes ~1.5): the whole sphere, not a few patches.
  const double expected_vertices = 4.0 * M_PI * radius * radius / (0.04 * 0.04);
  ASSERT_GT(double(errors.size()), 0.8 * expected_vertices);
  std::sort(errors.begin(), errors.end());
  const double median = errors[errors.size() / 2], p95 = errors[errors.size() * 95 / 100];
  std::printf("sphere r %.2f m: %zu vertices, |distance - radius| median %.4f m, 95th percentile %.4f m, max %.4f m\n",
              radius, errors.size(), median, p95, errors.back());
  EXPECT_LT(median, 0.01);
  EXPECT_LT(p95, 0.01);
}

}  // namespace
}  // namespace range_image_mapping::mapping
