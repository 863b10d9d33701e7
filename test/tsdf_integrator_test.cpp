// Projective TSDF integration against exact geometry: simulated scans of
// analytic surfaces (a sphere around the sensor, a box room, a wall) with the
// real OS0-128 tables where the shared data is present (a built-in
// approximation otherwise), no noise unless stated.
#include "range_image_mapping/mapping/tsdf_integrator.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/simulation/lidar_simulator.h"
#include "range_image_mapping/simulation/mesh_primitives.h"
#include "range_image_mapping/simulation/sensor_presets.h"
#include "error_text.h"
#include "simulated_mapping_sequence.h"
#include "test_data.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cstdio>
#include <cmath>
#include <functional>
#include <iostream>
#include <limits>
#include <map>
#include <optional>

namespace range_image_mapping::mapping {
namespace {

using simulation::LidarSimulator;
using simulation::RayCaster;
using simulation::SensorEffects;
using simulation::SimulatedScan;
using test::contains;
using test::errorOf;

constexpr double kDegree = M_PI / 180.0;
constexpr double kVoxel = 0.1;

// The real sensor tables when the shared data is there, else the built-in
// approximation (same size, field of view and beam origin).
LidarModelConstPtr ousterModel(const std::string& product) {
  const std::string file = product == "OS-0-128" ? "ouster-pcaps/OS-0-128-U1_v2.3.0_1024x10.json"
                                                 : "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json";
  const std::string path = test::dataFile(file);
  const OusterMetadata metadata =
      path.empty() ? parseOusterMetadata(simulation::ousterLikeMetadataJson(product, UdpProfile::kRng19Rfl8Sig16Nir16))
                   : loadOusterMetadata(path);
  return std::make_shared<const LidarModel>(metadata.intrinsics);
}

const LidarModelConstPtr& os0() {
  static const LidarModelConstPtr model = ousterModel("OS-0-128");
  return model;
}

SensorEffects exactEffects() {
  SensorEffects effects;
  effects.min_range_m = 0.0;
  return effects;
}

// T(t) = start * exp(t twist), sampled finely enough (1 ms) that the
// interpolated trajectory is the constant-velocity motion to well below a
// millimetre.
simulation::InterpolatedTrajectory constantTwist(const Eigen::Isometry3d& start, const Twist& twist,
                                                double duration_s) {
  std::vector<double> times;
  std::vector<Eigen::Isometry3d> poses;
  for (int n = 0; n <= int(duration_s * 1000); ++n) {
    times.push_back(n * 1e-3);
    poses.push_back(start * twistExponential(n * 1e-3 * twist));
  }
  return simulation::InterpolatedTrajectory(times, poses);
}

struct Simulated {
  RangeImage image;
  ScanPose pose;  // the true pose at scan time, zero twist
};

// One scan of `mesh` seen along `trajectory` from t = 0.1 s; the pose is the
// trajectory's at the scan time.
Simulated simulate(const TriangleMesh& mesh, const simulation::Trajectory& trajectory,
                   SensorEffects effects = exactEffects(), const LidarModelConstPtr& model = os0()) {
  const RayCaster caster(mesh);
  const LidarSimulator simulator(model, caster, effects, 3);
  Simulated result;
  result.image = simulator.simulate(trajectory, 0.1, 1).image;
  result.pose.scan_time_ns = scanTime(result.image, ScanTimeSource::kFirstValidColumn);
  result.pose.world_from_lidar = trajectory.pose(result.pose.scan_time_ns * 1e-9);
  return result;
}

Simulated simulateStill(const TriangleMesh& mesh, const Eigen::Isometry3d& pose,
                        SensorEffects effects = exactEffects()) {
  return simulate(mesh, simulation::InterpolatedTrajectory({0.0, 1.0}, {pose, pose}), effects);
}

Eigen::Isometry3d tiltedPose(const Eigen::Vector3d& position) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = (Eigen::AngleAxisd(35 * kDegree, Eigen::Vector3d::UnitZ()) *
                   Eigen::AngleAxisd(8 * kDegree, Eigen::Vector3d(1, 1, 0).normalized()))
                      .toRotationMatrix();
  pose.translation() = position;
  return pose;
}

VoxelBlockGridOptions gridOptions(bool intensity = false) {
  VoxelBlockGridOptions options;
  options.voxel_size_m = kVoxel;
  options.block_edge = 8;
  options.store_intensity = intensity;
  return options;
}

// Paper eq. 9 as it stands: distances along the ray, every sample weighing 1.
TsdfIntegratorOptions alongRayOptions() {
  TsdfIntegratorOptions options;
  options.signed_distance = SignedDistance::kAlongRay;
  options.incidence_weighting = false;
  options.free_space_weight = 1.0f;
  return options;
}

// ---------------------------------------------------------------- reading the grid

struct Voxel {
  float sdf = 0.0f, weight = 0.0f;
};

int floorDivide(int value, int divisor) { return value / divisor - (value % divisor < 0); }

// The voxel at a global lattice index (unobserved where there is no block).
Voxel voxelAt(const VoxelBlockGrid& grid, const Eigen::Vector3i& lattice) {
  const int edge = grid.blockEdge();
  const BlockKey key(floorDivide(lattice.x(), edge), floorDivide(lattice.y(), edge), floorDivide(lattice.z(), edge));
  const VoxelBlock* block = grid.find(key);
  if (block == nullptr) return {};
  const Eigen::Vector3i local = lattice - key * edge;
  const int i = local.x() + edge * (local.y() + edge * local.z());
  return {block->sdf[i], block->weight[i]};
}

// Calls visit(lattice, world position, voxel) for every voxel of every block.
void forEachVoxel(const VoxelBlockGrid& grid,
                  const std::function<void(const Eigen::Vector3i&, const Eigen::Vector3d&, const Voxel&)>& visit) {
  const int edge = grid.blockEdge();
  for (const VoxelBlock* block : grid.blocks())
    for (int k = 0; k < edge; ++k)
      for (int j = 0; j < edge; ++j)
        for (int i = 0; i < edge; ++i) {
          const int n = i + edge * (j + edge * k);
          visit(block->key * edge + Eigen::Vector3i(i, j, k), grid.voxelPosition(block->key, i, j, k),
                {block->sdf[n], block->weight[n]});
        }
}

struct CrossingErrors {
  std::size_t count = 0;
  double max = 0.0, mean = 0.0;
};

// Zero crossings of the TSDF along the grid lines (observed neighbours of
// opposite sign, linearly interpolated), measured with the true distance
// to the surface.
CrossingErrors zeroCrossingErrors(const VoxelBlockGrid& grid, const std::function<double(const Eigen::Vector3d&)>& distance,
                                  float truncation) {
  CrossingErrors errors;
  forEachVoxel(grid, [&](const Eigen::Vector3i& lattice, const Eigen::Vector3d& position, const Voxel& voxel) {
    if (voxel.weight <= 0.0f) return;
    for (int axis = 0; axis < 3; ++axis) {
      const Voxel next = voxelAt(grid, lattice + Eigen::Vector3i::Unit(axis));
      if (next.weight <= 0.0f || (voxel.sdf > 0.0f) == (next.sdf > 0.0f)) continue;
      // A jump between truncated values is an occlusion border, not a surface.
      if (std::abs(voxel.sdf - next.sdf) >= truncation) continue;
      const double t = voxel.sdf / (voxel.sdf - next.sdf);
      const Eigen::Vector3d crossing = position + t * kVoxel * Eigen::Vector3d::Unit(axis);
      const double error = std::abs(distance(crossing));
      ++errors.count;
      errors.max = std::max(errors.max, error);
      errors.mean += error;
    }
  });
  if (errors.count) errors.mean /= double(errors.count);
  return errors;
}

using GridSnapshot = std::map<std::array<int, 3>, std::vector<float>>;
GridSnapshot snapshot(const VoxelBlockGrid& grid) {
  GridSnapshot result;
  for (const VoxelBlock* block : grid.blocks()) {
    std::vector<float> values = block->sdf;
    values.insert(values.end(), block->weight.begin(), block->weight.end());
    values.insert(values.end(), block->intensity.begin(), block->intensity.end());
    values.push_back(float(block->changed_generation));
    result[{block->key.x(), block->key.y(), block->key.z()}] = std::move(values);
  }
  return result;
}

// ---------------------------------------------------------------- geometry

constexpr double kSphereRadius = 6.0;
const Eigen::Vector3d kSensorInSphere(0.3, -0.2, 0.1);

const Simulated& sphereScan() {
  static const Simulated scan =
      simulateStill(simulation::makeSphere(Eigen::Vector3f::Zero(), float(kSphereRadius), 6), tiltedPose(kSensorInSphere));
  return scan;
}

// Positive inside the sphere (the free space the sensor sees).
double sphereDistance(const Eigen::Vector3d& point) { return kSphereRadius - point.norm(); }

TEST(TsdfIntegrator, SphereZeroCrossingLiesWithinATenthOfAVoxel) {
  const Simulated& scan = sphereScan();
  VoxelBlockGrid grid(gridOptions());
  TsdfIntegrator integrator;
  const IntegrationStatistics statistics = integrator.integrate(grid, scan.image, scan.pose);
  EXPECT_EQ(statistics.points_used, scan.image.validCount());
  EXPECT_EQ(statistics.blocks_created, grid.blockCount());
  EXPECT_EQ(statistics.blocks_refused, 0u);
  EXPECT_GT(statistics.voxels_updated, 100000u);
  const float truncation = float(integrator.options().truncationFor(grid.options()));
  const CrossingErrors errors = zeroCrossingErrors(grid, sphereDistance, truncation);
  std::cout << "sphere: " << grid.blockCount() << " blocks, " << errors.count << " zero crossings, mean error "
            << errors.mean * 1000 << " mm, max " << errors.max * 1000 << " mm\n";
  EXPECT_GT(errors.count, 40000u);
  EXPECT_LT(errors.max, kVoxel / 10);
  EXPECT_LT(errors.mean, kVoxel / 50);
}

// ---------------------------------------------------------------- grazing incidence

// Flat ground under an OS1-128 1.8 m up (as on a car), one scan, 10 cm voxels,
// 30 m clip: beyond ~10 m the beam rings are further apart than the
// truncation. Per ring of ground distance, the share of lattice columns
// (x, y) with a zero crossing along z between two observed voxels, and the
// crossings' height errors.
struct GroundCoverage {
  std::vector<double> covered, mean_error, max_error;  // per 5 m ring of ground distance
};

constexpr double kSensorHeight = 1.8;
constexpr double kGroundRing = 5.0;

GroundCoverage groundCoverage(const VoxelBlockGrid& grid, double tilt_rad) {
  // Ground z = tan(tilt) * x: a gentle slope so that the plane is not a lattice plane.
  const double slope = std::tan(tilt_rad);
  const int rings = 6;
  std::vector<double> columns(rings, 0.0), covered(rings, 0.0), error_sum(rings, 0.0), error_max(rings, 0.0);
  const int reach = int(30.0 / kVoxel);
  for (int ix = -reach; ix <= reach; ++ix)
    for (int iy = -reach; iy <= reach; ++iy) {
      const double x = ix * kVoxel, y = iy * kVoxel, ground_distance = std::hypot(x, y);
      const int ring = int(ground_distance / kGroundRing);
      if (ring >= rings || ground_distance < 3.0) continue;
      columns[ring] += 1.0;
      const double ground_z = slope * x;
      // The lattice points straddling the ground, and their neighbours above and below.
      const int below = int(std::floor(ground_z / kVoxel));
      double best = std::numeric_limits<double>::infinity();
      for (int iz = below - 1; iz <= below + 1; ++iz) {
        const Voxel low = voxelAt(grid, {ix, iy, iz}), high = voxelAt(grid, {ix, iy, iz + 1});
        if (low.weight <= 0.0f || high.weight <= 0.0f || (low.sdf < 0.0f) == (high.sdf < 0.0f)) continue;
        const double z = (iz + low.sdf / (low.sdf - high.sdf)) * kVoxel;
        // Height error, perpendicular to the (nearly flat) ground.
        best = std::min(best, std::abs(z - ground_z) * std::cos(tilt_rad));
      }
      if (!std::isfinite(best)) continue;
      covered[ring] += 1.0;
      error_sum[ring] += best;
      error_max[ring] = std::max(error_max[ring], best);
    }
  GroundCoverage result;
  for (int ring = 0; ring < rings; ++ring) {
    result.covered.push_back(columns[ring] > 0 ? covered[ring] / columns[ring] : 0.0);
    result.mean_error.push_back(covered[ring] > 0 ? error_sum[ring] / covered[ring] : 0.0);
    result.max_error.push_back(error_max[ring]);
  }
  return result;
}

GroundCoverage integrateGround(SignedDistance signed_distance, double noise_m, double tilt_rad,
                               double plane_fill_m = 0.0) {
  const TriangleMesh ground = simulation::makeQuad(Eigen::Vector3f(-60, -60, 0), Eigen::Vector3f(120, 0, 0),
                                                   Eigen::Vector3f(0, 120, 0));
  TriangleMesh sloped = ground;
  for (Eigen::Vector3f& vertex : sloped.vertices) vertex.z() = float(std::tan(tilt_rad) * vertex.x());
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(0.03, -0.02, kSensorHeight);
  SensorEffects effects = exactEffects();
  effects.range_noise_sigma_m = noise_m;
  const RayCaster caster(sloped);
  const LidarSimulator simulator(ousterModel("OS-1-128"), caster, effects, 3);
  RangeImage image =
      simulator.simulate(simulation::InterpolatedTrajectory({0.0, 1.0}, {pose, pose}), 0.1, 1).image;
  ScanPose scan_pose;
  scan_pose.world_from_lidar = pose;
  VoxelBlockGrid grid(gridOptions());
  TsdfIntegratorOptions options;
  options.signed_distance = signed_distance;
  options.plane_fill_m = plane_fill_m;
  TsdfIntegrator integrator(options);
  integrator.integrate(grid, image, scan_pose);
  return groundCoverage(grid, tilt_rad);
}

void printGround(const char* what, const GroundCoverage& ground) {
  std::printf("%-26s", what);
  for (std::size_t ring = 0; ring < ground.covered.size(); ++ring)
    std::printf(" | %4.1f%% %4.1f/%4.1f", 100.0 * ground.covered[ring], 1000.0 * ground.mean_error[ring],
                1000.0 * ground.max_error[ring]);
  std::printf("\n");
}

// Point-to-plane distances with the plane filling the gaps between beam
// rings mesh the whole ground to 25 m, within millimetres; eq. 9 along the
// ray leaves rings with gaps beyond 5 m. With the default plane fill (the
// truncation) the plane covers the ground within the truncation of a
// return: whole where the rings are close, rings with narrower gaps than
// eq. 9's where they are far apart.
TEST(TsdfIntegrator, GroundAtGrazingIncidenceIsCoveredByPointToPlaneDistances) {
  const double tilt = 1.0 * kDegree, fill_gaps = 100.0;
  std::printf("ground distance            |   0-5 m covered, mean/max error mm | 5-10 | 10-15 | 15-20 | 20-25 | 25-30\n");
  const GroundCoverage filled = integrateGround(SignedDistance::kPointToPlane, 0.0, tilt, fill_gaps);
  const GroundCoverage noisy_filled = integrateGround(SignedDistance::kPointToPlane, 0.01, tilt, fill_gaps);
  const GroundCoverage plane = integrateGround(SignedDistance::kPointToPlane, 0.0, tilt);
  const GroundCoverage along_ray = integrateGround(SignedDistance::kAlongRay, 0.0, tilt);
  printGround("point-to-plane, gaps filled", filled);
  printGround("  the same, 1 cm noise", noisy_filled);
  printGround("point-to-plane (default)", plane);
  printGround("along the ray (eq. 9)", along_ray);
  // 5-25 m (beyond, the rings are more than 10 % of the range apart and the
  // normal map gives the ground no normal: eq. 9 there).
  for (std::size_t ring = 1; ring < 5; ++ring) {
    EXPECT_GT(filled.covered[ring], 0.97) << "ring " << ring;
    EXPECT_LT(filled.mean_error[ring], kVoxel / 100) << "ring " << ring;
    EXPECT_GT(noisy_filled.covered[ring], 0.97) << "ring " << ring;
    EXPECT_LT(noisy_filled.mean_error[ring], kVoxel / 20) << "ring " << ring;
    // (Free space activated in front of each band lets eq. 9 reach a little more of the ground.)
    EXPECT_LT(along_ray.covered[ring], 0.75) << "ring " << ring;
    EXPECT_GT(plane.covered[ring], along_ray.covered[ring] + 0.1) << "ring " << ring;
    EXPECT_LT(plane.mean_error[ring], kVoxel / 100) << "ring " << ring;
  }
  // Rings at most 0.34 m apart within 10 m: less than twice the truncation (0.6 m), whole.
  EXPECT_GT(plane.covered[1], 0.97);
  // Rings about 1 m apart and more beyond 15 m: gaps the plane does not fill.
  EXPECT_LT(plane.covered[3], filled.covered[3] - 0.2);
  EXPECT_LT(plane.covered[4], filled.covered[4] - 0.2);
}

TEST(TsdfIntegrator, FreeSpaceIsPositiveBehindIsNegativeAndFarBehindUntouched) {
  const Simulated& scan = sphereScan();
  VoxelBlockGrid grid(gridOptions());
  TsdfIntegrator integrator(alongRayOptions());
  integrator.integrate(grid, scan.image, scan.pose);
  const double truncation = integrator.options().truncationFor(grid.options());
  std::size_t in_front = 0, behind = 0, far_behind = 0, observed = 0;
  double worst = 0.0;
  forEachVoxel(grid, [&](const Eigen::Vector3i&, const Eigen::Vector3d& position, const Voxel& voxel) {
    const double distance = sphereDistance(position);
    if (distance < -truncation - 0.01) {
      ++far_behind;
      EXPECT_EQ(voxel.weight, 0.0f) << "voxel " << -distance << " m behind the surface was written";
      return;
    }
    if (voxel.weight == 0.0f) return;  // outside the vertical field of view
    ++observed;
    EXPECT_EQ(voxel.weight, 1.0f);
    // Along the ray, the projective distance is the radial one here (the
    // sensor is near the centre) up to a few millimetres.
    const double expected = std::clamp(distance, -truncation, truncation);
    worst = std::max(worst, std::abs(voxel.sdf - expected));
    if (distance > 0.01) {
      ++in_front;
      EXPECT_GT(voxel.sdf, 0.0f);
    } else if (distance < -0.01) {
      ++behind;
      EXPECT_LT(voxel.sdf, 0.0f);
    }
  });
  EXPECT_GT(in_front, 100000u);
  EXPECT_GT(behind, 50000u);
  EXPECT_GT(far_behind, 10000u);
  EXPECT_LT(worst, 0.01) << "largest difference from the true truncated distance";
  EXPECT_GT(observed, in_front + behind);
}

// Every voxel of every block against Pi, Omega and eq. 9-10 computed here one
// voxel at a time: a room with a pillar (occlusion edges), one scan. Voxels
// outside the activated cells stay unwritten: those must lie outside the
// truncation band of their pixel (far free space in a block near a surface).
TEST(TsdfIntegrator, EveryVoxelHoldsItsProjectiveDistance) {
  TriangleMesh scene = simulation::makeBox(Eigen::Vector3f(-6, -4, -1.5), Eigen::Vector3f(7, 5, 2.5), true);
  scene.append(simulation::makeCylinder(Eigen::Vector3f(2.0f, 1.0f, -1.5f), 0.4f, 4.0f, 32));
  const Simulated scan = simulateStill(scene, tiltedPose(Eigen::Vector3d(0.2, -0.3, 0.1)));
  VoxelBlockGrid grid(gridOptions());
  TsdfIntegratorOptions options = alongRayOptions();
  options.max_range_m = 8.0;
  TsdfIntegrator integrator(options);
  integrator.integrate(grid, scan.image, scan.pose);
  const float truncation = float(integrator.options().truncationFor(grid.options()));
  const Eigen::Isometry3d lidar_from_world = scan.pose.world_from_lidar.inverse();
  const LidarModel& model = *scan.image.model;
  std::size_t updated = 0, occluded = 0, free_space_left = 0, band_left = 0, on_pixel_edge = 0;
  // What the voxel at `point_lidar` should hold if its centre falls in the pixel project() gives.
  const auto expected = [&](const Eigen::Vector3f& point_lidar, bool count) {
    std::pair<float, float> weight_sdf(0.0f, 0.0f);
    const std::optional<ProjectedPixel> pixel = model.project(point_lidar);
    if (!pixel) return weight_sdf;
    const float measured = scan.image.at(pixel->row, pixel->column);
    const float distance = measured - pixel->range;
    if (measured >= 0.3f && measured <= 8.0f && distance >= -truncation) weight_sdf = {1.0f, std::min(distance, truncation)};
    if (count) occluded += measured >= 0.3f && measured <= 8.0f && distance < -truncation;
    return weight_sdf;
  };
  forEachVoxel(grid, [&](const Eigen::Vector3i&, const Eigen::Vector3d& position, const Voxel& voxel) {
    const Eigen::Vector3f point_lidar = (lidar_from_world * position).cast<float>();
    const auto [expected_weight, expected_sdf] = expected(point_lidar, true);
    if (voxel.weight == 0.0f && expected_weight > 0.0f) {  // outside the activated cells
      free_space_left += expected_sdf >= truncation;
      band_left += expected_sdf < truncation;
      return;
    }
    if (voxel.weight != expected_weight || std::abs(voxel.sdf - expected_sdf) > 1e-4f) {
      // The integrator moves the voxel with float arithmetic of its own: a centre within rounding (a few
      // micrometres) of a pixel's edge may land in the neighbour. It must then hold the neighbour's value.
      bool neighbour_matches = false;
      for (int axis = 0; axis < 3 && !neighbour_matches; ++axis)
        for (const float step : {-5e-6f, 5e-6f}) {
          const auto [weight, sdf] = expected(point_lidar + step * Eigen::Vector3f::Unit(axis), false);
          neighbour_matches |= voxel.weight == weight && std::abs(voxel.sdf - sdf) <= 1e-4f;
        }
      ASSERT_TRUE(neighbour_matches) << "voxel at " << position.transpose() << " holds weight " << voxel.weight
                                     << ", sdf " << voxel.sdf << "; its pixel gives " << expected_weight << ", "
                                     << expected_sdf << " and no pixel within 5 um of it gives that";
      ++on_pixel_edge;
    }
    updated += voxel.weight > 0.0f;
  });
  std::printf("%zu voxels on a pixel's edge took the neighbour's value\n", on_pixel_edge);
  EXPECT_LE(on_pixel_edge, 10u) << "more voxels than rounding explains hold another pixel's value";
  std::printf("%zu voxels written, %zu left as far free space, %zu in the band left\n", updated, free_space_left,
              band_left);
  EXPECT_GT(updated, 200000u);
  EXPECT_GT(occluded, 100000u);
  EXPECT_LT(band_left, updated / 1000) << "voxels in the truncation band outside the activated cells";
  EXPECT_GT(free_space_left, 0u);  // the cells leave some of the blocks out
}

// A room larger than the clip: nothing is written from returns outside
// [min_range, max_range].
TEST(TsdfIntegrator, RangeClipBoundsWhatIsWritten) {
  const Eigen::Vector3d sensor(1.0, 2.0, 0.0);
  const Simulated scan = simulateStill(
      simulation::makeBox(Eigen::Vector3f(-25, -4, -1.5), Eigen::Vector3f(30, 9, 3), true), tiltedPose(sensor));
  VoxelBlockGrid grid(gridOptions());
  TsdfIntegratorOptions options;
  options.min_range_m = 5.0;
  options.max_range_m = 12.0;
  TsdfIntegrator integrator(options);
  const IntegrationStatistics statistics = integrator.integrate(grid, scan.image, scan.pose);
  std::size_t in_clip = 0;
  for (const float range : scan.image.range) in_clip += range >= 5.0f && range <= 12.0f;
  EXPECT_EQ(statistics.points_used, in_clip);
  ASSERT_GT(grid.blockCount(), 100u);
  const double truncation = integrator.options().truncationFor(grid.options());
  // The beam starts a few centimetres from the lidar origin.
  const double beam_origin = std::hypot(os0()->intrinsics().beam_origin_radius_m, os0()->intrinsics().beam_origin_z_m);
  double nearest_block = 1e9, farthest_block = 0.0, nearest_voxel = 1e9, farthest_voxel = 0.0;
  for (const VoxelBlock* block : grid.blocks()) {
    const Eigen::Vector3d low = block->key.cast<double>() * grid.blockSize();
    const Eigen::AlignedBox3d box(low, low + Eigen::Vector3d::Constant(grid.blockSize()));
    const double near = std::sqrt(box.squaredExteriorDistance(sensor));
    nearest_block = std::min(nearest_block, near);
    farthest_block = std::max(farthest_block, near);
  }
  forEachVoxel(grid, [&](const Eigen::Vector3i&, const Eigen::Vector3d& position, const Voxel& voxel) {
    if (voxel.weight == 0.0f) return;
    nearest_voxel = std::min(nearest_voxel, (position - sensor).norm());
    farthest_voxel = std::max(farthest_voxel, (position - sensor).norm());
  });
  EXPECT_LE(farthest_block, 12.0 + truncation + beam_origin);
  // Cells are activated 4 voxels in front of the band too (kFreeSpaceActivationVoxels).
  EXPECT_GE(nearest_block, 5.0 - truncation - 4.0 * grid.voxelSize() - beam_origin - grid.blockSize() * std::sqrt(3.0));
  EXPECT_LE(farthest_voxel, 12.0 + truncation + beam_origin);
  EXPECT_GT(farthest_voxel, 11.0);
  EXPECT_LT(nearest_voxel, 6.0);
}

TEST(TsdfIntegrator, ImageWithoutReturnsWritesNothing) {
  const Simulated& scan = sphereScan();
  RangeImage empty(scan.image.model);  // every pixel NaN
  VoxelBlockGrid grid(gridOptions());
  TsdfIntegrator integrator;
  IntegrationStatistics statistics = integrator.integrate(grid, empty, scan.pose);
  EXPECT_EQ(grid.blockCount(), 0u);
  EXPECT_EQ(statistics.points_used, 0u);
  integrator.integrate(grid, scan.image, scan.pose);
  const GridSnapshot before = snapshot(grid);
  statistics = integrator.integrate(grid, empty, scan.pose);
  EXPECT_EQ(statistics.voxels_updated, 0u);
  GridSnapshot after = snapshot(grid);
  EXPECT_EQ(after, before);
}

TEST(TsdfIntegrator, BadInputThrowsAndLeavesTheGridBitIdentical) {
  const Simulated& scan = sphereScan();
  VoxelBlockGrid grid(gridOptions());
  TsdfIntegrator integrator;
  integrator.integrate(grid, scan.image, scan.pose);
  const GridSnapshot before = snapshot(grid);
  const uint64_t generation = grid.generation();

  const auto expectRefused = [&](const RangeImage& image, const ScanPose& pose, const std::string& part,
                                 TsdfIntegrator& with) {
    const std::string message = errorOf([&] { with.integrate(grid, image, pose); });
    EXPECT_TRUE(contains(message, part)) << message;
    EXPECT_THROW(with.deintegrate(grid, image, pose), MappingError);
    EXPECT_EQ(grid.generation(), generation);
    EXPECT_TRUE(snapshot(grid) == before) << part;
  };
  ScanPose nan_pose = scan.pose;
  nan_pose.world_from_lidar.translation().x() = std::nan("");
  expectRefused(scan.image, nan_pose, "pose is not finite", integrator);
  ScanPose infinite_twist = scan.pose;
  infinite_twist.twist[4] = std::numeric_limits<double>::infinity();
  expectRefused(scan.image, infinite_twist, "twist is not finite", integrator);
  ScanPose sheared = scan.pose;
  sheared.world_from_lidar.linear()(0, 1) += 0.1;
  expectRefused(scan.image, sheared, "not a rotation", integrator);
  ScanPose far_away = scan.pose;
  far_away.world_from_lidar.translation().x() = 1e12;
  expectRefused(scan.image, far_away, "beyond what the voxel grid can index", integrator);

  expectRefused(scan.image.destaggered(), scan.pose, "destaggered", integrator);
  RangeImage no_model = scan.image;
  no_model.model.reset();
  expectRefused(no_model, scan.pose, "no sensor model", integrator);
  RangeImage short_ranges = scan.image;
  short_ranges.range.pop_back();
  expectRefused(short_ranges, scan.pose, "ranges", integrator);
  RangeImage bad_intensity = scan.image;
  bad_intensity.intensity.assign(7, 1.0f);
  expectRefused(bad_intensity, scan.pose, "intensities", integrator);

  const auto withOptions = [&](const std::function<void(TsdfIntegratorOptions&)>& change,
                               const std::string& field) {
    TsdfIntegratorOptions options;
    change(options);
    TsdfIntegrator bad(options);
    expectRefused(scan.image, scan.pose, field, bad);
  };
  withOptions([](TsdfIntegratorOptions& o) { o.truncation_m = 0.05; }, "truncation_m");
  withOptions([](TsdfIntegratorOptions& o) { o.truncation_m = 11.0; }, "truncation_m");
  withOptions([](TsdfIntegratorOptions& o) { o.truncation_m = std::nan(""); }, "truncation_m");
  withOptions([](TsdfIntegratorOptions& o) { o.min_range_m = -1.0; }, "min_range_m");
  withOptions([](TsdfIntegratorOptions& o) { o.max_range_m = 0.2; }, "max_range_m");
  withOptions([](TsdfIntegratorOptions& o) { o.max_range_m = std::nan(""); }, "max_range_m");
  withOptions([](TsdfIntegratorOptions& o) { o.point_stride = 0; }, "point_stride");
  withOptions([](TsdfIntegratorOptions& o) { o.max_weight = 0.0f; }, "max_weight");
  withOptions([](TsdfIntegratorOptions& o) { o.mesh_tolerance_voxels = -0.1; }, "mesh_tolerance_voxels");
  withOptions([](TsdfIntegratorOptions& o) { o.mesh_min_weight = std::nanf(""); }, "mesh_min_weight");
  withOptions([](TsdfIntegratorOptions& o) { o.free_space_weight = 0.0f; }, "free_space_weight");
  withOptions([](TsdfIntegratorOptions& o) { o.free_space_weight = std::nanf(""); }, "free_space_weight");
  withOptions([](TsdfIntegratorOptions& o) { o.plane_fill_m = -0.1; }, "plane_fill_m");
  withOptions([](TsdfIntegratorOptions& o) { o.plane_fill_m = std::numeric_limits<double>::infinity(); }, "plane_fill_m");
  withOptions([](TsdfIntegratorOptions& o) { o.signed_distance = SignedDistance(7); }, "signed_distance");
  withOptions(
      [](TsdfIntegratorOptions& o) {
        o.range_weighting = true;
        o.range_weighting_start_m = -2.0;
      },
      "range_weighting_start_m");
}

// changed_generation against what each block held when it was last marked:
// a block a scan leaves unmarked has the same observed voxels and signs, and
// none of its voxels drifted by more than the tolerance since. A sphere
// growing 3 mm per scan (below the 1 cm tolerance each time), 10 scans.
TEST(TsdfIntegrator, BlocksAreMarkedWhenTheirChangeMattersToTheMesh) {
  TsdfIntegrator integrator;  // mesh_tolerance_voxels 0.1: 1 cm
  const float tolerance = float(integrator.options().mesh_tolerance_voxels * kVoxel);
  VoxelBlockGrid grid(gridOptions());
  std::map<std::array<int, 3>, std::pair<std::vector<float>, std::vector<float>>> at_mark;  // sdf, weight
  std::size_t marked = 0, unmarked = 0;
  double largest_unmarked_drift = 0.0;
  Simulated scan;
  for (int n = 0; n < 10; ++n) {
    scan = simulateStill(simulation::makeSphere(Eigen::Vector3f::Zero(), float(kSphereRadius + 0.003 * n), 6),
                         tiltedPose(kSensorInSphere));
    const IntegrationStatistics statistics = integrator.integrate(grid, scan.image, scan.pose);
    std::size_t marked_now = 0;
    for (const VoxelBlock* block : grid.blocks()) {
      auto& [sdf, weight] = at_mark[{block->key.x(), block->key.y(), block->key.z()}];
      if (block->changed_generation == grid.generation()) {
        sdf = block->sdf;
        weight = block->weight;
        ++marked_now;
        continue;
      }
      ASSERT_EQ(sdf.size(), block->sdf.size()) << "a block was never marked";
      ++unmarked;
      for (std::size_t i = 0; i < sdf.size(); ++i) {
        ASSERT_EQ(weight[i] > 0.0f, block->weight[i] > 0.0f) << "scan " << n;
        ASSERT_EQ(sdf[i] < 0.0f, block->sdf[i] < 0.0f) << "scan " << n;
        largest_unmarked_drift = std::max(largest_unmarked_drift, double(std::abs(block->sdf[i] - sdf[i])));
      }
    }
    EXPECT_EQ(statistics.blocks_marked, marked_now);
    marked += marked_now;
  }
  std::printf("growing sphere: %zu blocks marked, %zu left unmarked over 10 scans; largest drift of an unmarked "
              "voxel since its block was marked %.2f mm\n",
              marked, unmarked, 1000.0 * largest_unmarked_drift);
  EXPECT_LE(largest_unmarked_drift, tolerance + 1e-6);
  EXPECT_GT(largest_unmarked_drift, 0.5 * tolerance);  // the test can fail
  EXPECT_GT(unmarked, marked / 4);

  // A scan integrated twice: the second time changes no value (only
  // weights), nothing to re-mesh.
  VoxelBlockGrid fresh(gridOptions());
  integrator.integrate(fresh, scan.image, scan.pose);
  EXPECT_EQ(integrator.integrate(fresh, scan.image, scan.pose).blocks_marked, 0u);
  // With tolerance 0 every block whose values changed is marked.
  TsdfIntegratorOptions exact;
  exact.mesh_tolerance_voxels = 0.0;
  TsdfIntegrator every_change(exact);
  const GridSnapshot before = snapshot(grid);
  const IntegrationStatistics statistics = every_change.integrate(grid, sphereScan().image, sphereScan().pose);
  std::size_t changed = 0, changed_and_marked = 0;
  for (const VoxelBlock* block : grid.blocks()) {
    const auto old = before.find({block->key.x(), block->key.y(), block->key.z()});
    ASSERT_NE(old, before.end());
    const bool values_changed = !std::equal(block->sdf.begin(), block->sdf.end(), old->second.begin()) ||
                                !std::equal(block->weight.begin(), block->weight.end(), old->second.begin() + block->sdf.size());
    changed += values_changed;
    changed_and_marked += values_changed && block->changed_generation == grid.generation();
  }
  EXPECT_GT(changed, 1000u);
  EXPECT_EQ(changed_and_marked, changed);
  EXPECT_EQ(statistics.blocks_marked, changed);
}

TEST(TsdfIntegrator, RepeatedScansConvergeWithTheWeightCapped) {
  const Simulated& scan = sphereScan();
  VoxelBlockGrid once(gridOptions()), repeated(gridOptions());
  TsdfIntegratorOptions options = alongRayOptions();
  options.max_weight = 5.0f;
  options.mesh_tolerance_voxels = 0.0;  // every scan marks what it wrote
  TsdfIntegrator integrator(options);
  integrator.integrate(once, scan.image, scan.pose);
  for (int n = 0; n < 8; ++n) integrator.integrate(repeated, scan.image, scan.pose);
  ASSERT_EQ(once.blockCount(), repeated.blockCount());
  EXPECT_EQ(repeated.generation(), 8u);
  std::size_t compared = 0;
  for (const VoxelBlock* block : once.blocks()) {
    const VoxelBlock* other = repeated.find(block->key);
    ASSERT_NE(other, nullptr);
    EXPECT_EQ(other->changed_generation, 8u);
    for (std::size_t i = 0; i < block->sdf.size(); ++i) {
      if (block->weight[i] == 0.0f) {
        ASSERT_EQ(other->weight[i], 0.0f);
        continue;
      }
      ASSERT_EQ(other->weight[i], 5.0f);
      ASSERT_NEAR(other->sdf[i], block->sdf[i], 1e-6f);
      ++compared;
    }
  }
  EXPECT_GT(compared, 100000u);
}

// Samples beyond the truncation in front of the surface weigh
// free_space_weight: a single one cannot erase a surface, and an object
// that went away still fades, over about 1 / free_space_weight scans.
TEST(TsdfIntegrator, FreeSpaceSamplesWeighLessYetAGhostFades) {
  const Simulated& sphere = sphereScan();
  TsdfIntegratorOptions options = alongRayOptions();
  options.free_space_weight = 0.1f;
  {
    VoxelBlockGrid grid(gridOptions());
    TsdfIntegrator integrator(options);
    integrator.integrate(grid, sphere.image, sphere.pose);
    const double truncation = integrator.options().truncationFor(grid.options());
    std::size_t free_space = 0, near_surface = 0;
    forEachVoxel(grid, [&](const Eigen::Vector3i&, const Eigen::Vector3d& position, const Voxel& voxel) {
      if (voxel.weight == 0.0f) return;
      const double distance = sphereDistance(position);  // positive inside: the free space seen
      if (distance > truncation + 0.01) {
        ++free_space;
        ASSERT_FLOAT_EQ(voxel.weight, 0.1f) << -distance << " m in front";
        ASSERT_FLOAT_EQ(voxel.sdf, float(truncation));
      } else if (distance < truncation - 0.01) {
        ++near_surface;
        ASSERT_FLOAT_EQ(voxel.weight, 1.0f) << distance << " m in front";
      }
    });
    EXPECT_GT(free_space, 10000u);
    EXPECT_GT(near_surface, 50000u);
  }
  // A box seen once against a room's wall, then the room without it from the
  // same place. (Free space is written only in blocks a scan activates, near
  // its returns: here the wall's.)
  const TriangleMesh room = simulation::makeBox(Eigen::Vector3f(-7, -5, -1.5), Eigen::Vector3f(9, 6, 2.5), true);
  TriangleMesh with_box = room;
  const Eigen::Vector3f box_low(8.3f, -0.4f, -0.6f), box_high(9.0f, 0.4f, 0.2f);
  with_box.append(simulation::makeBox(box_low, box_high));
  const Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  const Simulated box_scan = simulateStill(with_box, pose);
  const Simulated empty_scan = simulateStill(room, pose);
  // Voxels with a negative value (at or behind a surface) behind the box's
  // front face, short of the wall's own band.
  const auto ghostVoxels = [&](const VoxelBlockGrid& grid) {
    std::size_t negative = 0;
    forEachVoxel(grid, [&](const Eigen::Vector3i&, const Eigen::Vector3d& position, const Voxel& voxel) {
      const Eigen::Vector3f p = position.cast<float>();
      const bool at_box = p.x() > box_low.x() - 0.15f && p.x() < 8.65f && std::abs(p.y()) < 0.35f &&
                          p.z() > box_low.z() + 0.05f && p.z() < box_high.z() - 0.05f;
      negative += at_box && voxel.weight > 0.0f && voxel.sdf < 0.0f;
    });
    return negative;
  };
  const auto ghostAfter = [&](float free_space_weight, int empty_scans) {
    TsdfIntegratorOptions ghost_options = alongRayOptions();
    ghost_options.free_space_weight = free_space_weight;
    VoxelBlockGrid grid(gridOptions());
    TsdfIntegrator integrator(ghost_options);
    integrator.integrate(grid, box_scan.image, box_scan.pose);
    const std::size_t seen = ghostVoxels(grid);
    EXPECT_GT(seen, 50u);
    for (int n = 0; n < empty_scans; ++n) integrator.integrate(grid, empty_scan.image, empty_scan.pose);
    return ghostVoxels(grid);
  };
  EXPECT_GT(ghostAfter(0.1f, 3), 50u) << "three free-space samples at 0.1 erased the box";
  EXPECT_EQ(ghostAfter(0.1f, 20), 0u) << "the box did not fade in 20 scans";
  EXPECT_EQ(ghostAfter(1.0f, 2), 0u) << "at full weight the box should be gone after 2 scans";
}

TEST(TsdfIntegrator, DeintegrateUndoesIntegrate) {
  const TriangleMesh room = simulation::makeBox(Eigen::Vector3f(-7, -5, -1.5), Eigen::Vector3f(9, 6, 2.5), true);
  const Simulated first = simulateStill(room, tiltedPose(Eigen::Vector3d(0, 0, 0)));
  const Simulated second = simulateStill(room, tiltedPose(Eigen::Vector3d(1.5, 0.5, 0.2)));
  VoxelBlockGrid only_first(gridOptions()), both(gridOptions());
  TsdfIntegrator integrator;
  integrator.integrate(only_first, first.image, first.pose);
  integrator.integrate(both, first.image, first.pose);
  const IntegrationStatistics added = integrator.integrate(both, second.image, second.pose);
  ASSERT_GT(added.blocks_created, 0u);
  const IntegrationStatistics removed = integrator.deintegrate(both, second.image, second.pose);
  EXPECT_EQ(removed.blocks_created, 0u);
  EXPECT_EQ(removed.blocks_removed, added.blocks_created);
  ASSERT_EQ(both.blockCount(), only_first.blockCount());
  for (const VoxelBlock* block : only_first.blocks()) {
    const VoxelBlock* other = both.find(block->key);
    ASSERT_NE(other, nullptr);
    for (std::size_t i = 0; i < block->sdf.size(); ++i) {
      ASSERT_NEAR(other->weight[i], block->weight[i], 1e-5f);
      ASSERT_NEAR(other->sdf[i], block->sdf[i], 1e-5f);
    }
  }
  integrator.deintegrate(both, first.image, first.pose);
  EXPECT_EQ(both.blockCount(), 0u);
}

// A sensor turning at 90 deg/s while moving at 1.5 m/s inside a sphere: the
// true twist puts the surface back where it is, a zero twist smears it.
TEST(TsdfIntegrator, TwistCompensatesMotionWithinTheSweep) {
  Twist twist;
  twist << 0.1, -0.05, 90 * kDegree, 1.5, 0.3, 0.0;
  const auto trajectory = constantTwist(tiltedPose(Eigen::Vector3d(-0.4, 0.2, 0.0)), twist, 0.3);
  Simulated scan = simulate(simulation::makeSphere(Eigen::Vector3f::Zero(), 8.0f, 6), trajectory);
  TsdfIntegrator integrator;
  const float truncation = float(integrator.options().truncationFor(gridOptions()));
  VoxelBlockGrid compensated(gridOptions()), still(gridOptions());
  scan.pose.twist = twist;
  integrator.integrate(compensated, scan.image, scan.pose);
  scan.pose.twist.setZero();
  integrator.integrate(still, scan.image, scan.pose);
  const auto distance = [](const Eigen::Vector3d& p) { return 8.0 - p.norm(); };
  const CrossingErrors with_twist = zeroCrossingErrors(compensated, distance, truncation);
  const CrossingErrors without = zeroCrossingErrors(still, distance, truncation);
  std::cout << "moving sensor: mean zero-crossing error " << with_twist.mean * 1000 << " mm (max "
            << with_twist.max * 1000 << ") with the twist, " << without.mean * 1000 << " mm (max "
            << without.max * 1000 << ") without\n";
  EXPECT_GT(with_twist.count, 40000u);
  EXPECT_LT(with_twist.max, kVoxel / 10);
  EXPECT_GT(without.mean, 5.0 * with_twist.mean);
  EXPECT_GT(without.max, kVoxel / 2);
}

TEST(TsdfIntegrator, OneThreadAndTwoThreadsGiveTheSameGrid) {
  Twist twist;
  twist << 0.0, 0.0, 60 * kDegree, 1.0, 0.0, 0.0;
  const auto trajectory = constantTwist(tiltedPose(Eigen::Vector3d(0, 0, 0)), twist, 0.3);
  Simulated scan = simulate(simulation::makeBox(Eigen::Vector3f(-7, -5, -1.5), Eigen::Vector3f(9, 6, 2.5), true),
                            trajectory);
  scan.pose.twist = twist;
  TsdfIntegratorOptions options;
  options.incidence_weighting = true;
  options.range_weighting = true;
  options.range_weighting_start_m = 4.0;
  GridSnapshot results[2];
  for (const int threads : {1, 2}) {
    const tbb::global_control limit(tbb::global_control::max_allowed_parallelism, threads);
    VoxelBlockGrid grid(gridOptions());
    TsdfIntegrator integrator(options);
    integrator.integrate(grid, scan.image, scan.pose);
    results[threads - 1] = snapshot(grid);
  }
  EXPECT_GT(results[0].size(), 500u);
  EXPECT_TRUE(results[0] == results[1]);
}

// Activation by cells: on moving OS1-128 and HDL-64E sweeps of the simulated
// drives only part of each touched block is projected (the cells a return's
// band crossed, not the space under the ground or behind walls), and the
// incremental mesh, updated after every scan with every change marked, is
// the full extraction after every scan.
TEST(TsdfIntegrator, CellActivationProjectsPartOfEachBlockAndMeshesIncrementally) {
  for (const test::MappingPreset& preset : {test::outdoorCarPreset(), test::kittiLikePreset()}) {
    const test::SimulatedMappingSequence sequence = test::simulateMappingSequence(preset, 5, 4);
    VoxelBlockGridOptions grid_options = gridOptions();
    grid_options.voxel_size_m = preset.voxel_m;
    TsdfIntegratorOptions options;
    options.max_range_m = preset.max_range_m;
    options.mesh_tolerance_voxels = 0.0;  // every change re-meshed: the incremental mesh must be exact
    VoxelBlockGrid grid(grid_options);
    TsdfIntegrator integrator(options);
    MeshExtractor extractor;
    std::size_t block_voxels = 0, selected = 0, updated = 0;
    for (std::size_t k = 0; k < sequence.scans.size(); ++k) {
      ASSERT_FALSE(sequence.poses[k].twist.isZero());
      const IntegrationStatistics statistics = integrator.integrate(grid, sequence.scans[k], sequence.poses[k]);
      block_voxels += statistics.blocks_touched * std::size_t(grid.voxelsPerBlock());
      selected += statistics.voxels_selected;
      updated += statistics.voxels_updated;
      EXPECT_LE(statistics.voxels_updated, statistics.voxels_selected) << preset.name << " scan " << k;
      extractor.update(grid);
      if (k + 1 == sequence.scans.size()) continue;  // compared below
      const TriangleMesh incremental = extractor.combined(), full = extractMesh(grid);
      ASSERT_EQ(incremental.vertices, full.vertices) << preset.name << " scan " << k;
      ASSERT_EQ(incremental.normals, full.normals) << preset.name << " scan " << k;
      ASSERT_EQ(incremental.triangles, full.triangles) << preset.name << " scan " << k;
    }
    std::printf("%s: %zu voxels in the touched blocks, %zu of them selected, %zu written, over %zu sweeps\n",
                preset.name.c_str(), block_voxels, selected, updated, sequence.scans.size());
    EXPECT_LT(selected, block_voxels * 3 / 4) << preset.name;  // the cells leave much of the blocks out
    EXPECT_GT(updated, selected / 3) << preset.name;           // and much of what they select is written
    const TriangleMesh incremental = extractor.combined(), full = extractMesh(grid);
    EXPECT_GT(full.triangles.size(), 10000u) << preset.name;
    EXPECT_EQ(incremental.vertices, full.vertices) << preset.name;
    EXPECT_EQ(incremental.normals, full.normals) << preset.name;
    EXPECT_EQ(incremental.triangles, full.triangles) << preset.name;
  }
}

// A wall at x = 6 seen from the origin: one sample weighs cos(incidence)
// with incidence weighting, (start / r)^2 past the start with range weighting.
TEST(TsdfIntegrator, OptionalWeightsFollowIncidenceAndRange) {
  const TriangleMesh wall = simulation::makeQuad(Eigen::Vector3f(6, 20, -20), Eigen::Vector3f(0, -40, 0),
                                                 Eigen::Vector3f(0, 0, 40));
  const Simulated scan = simulateStill(wall, Eigen::Isometry3d::Identity());
  for (const bool incidence : {true, false}) {
    TsdfIntegratorOptions options;
    options.incidence_weighting = incidence;
    options.range_weighting = !incidence;
    options.range_weighting_start_m = 7.0;
    options.max_range_m = 20.0;
    VoxelBlockGrid grid(gridOptions());
    TsdfIntegrator integrator(options);
    integrator.integrate(grid, scan.image, scan.pose);
    std::size_t checked = 0;
    double worst = 0.0;
    forEachVoxel(grid, [&](const Eigen::Vector3i&, const Eigen::Vector3d& position, const Voxel& voxel) {
      // Voxels on the wall, away from the sensor's axis where beams bunch up.
      if (voxel.weight == 0.0f || std::abs(position.x() - 6.0) > 0.05 || std::abs(position.z()) > 4.0) return;
      const double range = position.norm();
      const double expected = incidence ? 6.0 / range : (range > 7.0 ? std::pow(7.0 / range, 2) : 1.0);
      worst = std::max(worst, std::abs(voxel.weight - expected));
      ++checked;
    });
    EXPECT_GT(checked, 2000u);
    EXPECT_LT(worst, 0.03) << (incidence ? "incidence" : "range") << " weighting";
  }
}

TEST(TsdfIntegrator, IntensityIsAveragedWhenTheGridStoresIt) {
  Simulated scan = sphereScan();
  scan.image.intensity.assign(scan.image.range.size(), 0.0f);
  for (int v = 0; v < scan.image.rows(); ++v)
    for (int u = 0; u < scan.image.columns(); ++u) scan.image.intensity[scan.image.index(v, u)] = float(v % 2 ? 30 : 10);
  VoxelBlockGrid grid(gridOptions(true));
  TsdfIntegrator integrator(alongRayOptions());
  integrator.integrate(grid, scan.image, scan.pose);
  for (float& value : scan.image.intensity) value += 40.0f;
  integrator.integrate(grid, scan.image, scan.pose);
  std::size_t checked = 0;
  for (const VoxelBlock* block : grid.blocks())
    for (std::size_t i = 0; i < block->weight.size(); ++i) {
      if (block->weight[i] == 0.0f) continue;
      ASSERT_EQ(block->weight[i], 2.0f);
      // Both rows' values plus the 40 / 2 of the second scan.
      ASSERT_TRUE(std::abs(block->intensity[i] - 30.0f) < 1e-4f || std::abs(block->intensity[i] - 50.0f) < 1e-4f)
          << block->intensity[i];
      ++checked;
    }
  EXPECT_GT(checked, 100000u);
}

TEST(TsdfIntegrator, BlockBudgetRefusesNewBlocksOnly) {
  const Simulated& scan = sphereScan();
  VoxelBlockGridOptions options = gridOptions();
  options.max_blocks = 300;
  VoxelBlockGrid grid(options);
  TsdfIntegrator integrator;
  const IntegrationStatistics statistics = integrator.integrate(grid, scan.image, scan.pose);
  EXPECT_GT(statistics.blocks_refused, 500u);
  EXPECT_LE(grid.blockCount(), 300u);
  EXPECT_GT(grid.blockCount(), 200u);
  // Blocks created for nothing (no voxel projected onto a return) are dropped.
  EXPECT_EQ(statistics.blocks_created, grid.blockCount());
  EXPECT_EQ(statistics.blocks_touched, 300u);
  // The blocks that were made are the ones nearest the sensor, integrated as
  // without a budget.
  VoxelBlockGrid unlimited(gridOptions());
  integrator.integrate(unlimited, scan.image, scan.pose);
  const auto distance = [&](const VoxelBlock* block) {
    return ((block->key.cast<double>() + Eigen::Vector3d::Constant(0.5)) * grid.blockSize() - kSensorInSphere).norm();
  };
  double farthest_kept = 0.0;
  for (const VoxelBlock* block : grid.blocks()) farthest_kept = std::max(farthest_kept, distance(block));
  std::size_t nearer_missing = 0;
  for (const VoxelBlock* block : unlimited.blocks())
    nearer_missing += distance(block) < farthest_kept - 1e-9 && grid.find(block->key) == nullptr;
  EXPECT_EQ(nearer_missing, 0u);
  for (const VoxelBlock* block : grid.blocks()) {
    const VoxelBlock* reference = unlimited.find(block->key);
    ASSERT_NE(reference, nullptr);
    EXPECT_EQ(block->sdf, reference->sdf);
    EXPECT_EQ(block->weight, reference->weight);
  }
}

TEST(TsdfIntegrator, PointStrideActivatesFromFewerPixels) {
  const Simulated& scan = sphereScan();
  TsdfIntegratorOptions options;
  options.point_stride = 4;
  VoxelBlockGrid strided(gridOptions()), full(gridOptions());
  TsdfIntegrator integrator(options), reference;
  const IntegrationStatistics statistics = integrator.integrate(strided, scan.image, scan.pose);
  reference.integrate(full, scan.image, scan.pose);
  EXPECT_EQ(statistics.points_used, (128 / 4) * (1024 / 4));
  // 0.8 m blocks at 6 m: every fourth beam still crosses every block near the surface.
  EXPECT_GT(strided.blockCount(), 0.95 * full.blockCount());
  EXPECT_LE(strided.blockCount(), full.blockCount());
}

}  // namespace
}  // namespace range_image_mapping::mapping
