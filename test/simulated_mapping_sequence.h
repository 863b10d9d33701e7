// The issue-5 mapping sequences simulated in memory, with exact ground truth:
// indoor_cart (OS0-128-like, 4 cm voxels, 10 m clip) and outdoor_car
// (OS1-128-like, 10 cm, 30 m clip), and kitti_like (KITTI's HDL-64E, 10 cm,
// 30 m clip), as `rim simulate --preset` builds them
// (same scene, motion, noise and start time), always with the built-in
// approximation of the beam tables so that results do not depend on the data
// folder. Shared by the mapping accuracy test and the mapping benchmarks.
#pragma once

#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/mapping/marching_cubes.h"
#include "range_image_mapping/mapping/tsdf_integrator.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/simulation/lidar_simulator.h"
#include "range_image_mapping/simulation/scene_generator.h"
#include "range_image_mapping/simulation/sensor_presets.h"
#include "range_image_mapping/simulation/surface_sampler.h"

#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace range_image_mapping::test {

struct MappingPreset {
  std::string name;
  simulation::SceneKind scene;
  std::string product;  // ousterLikeMetadataJson's product line, or "hdl64"
  simulation::MotionProfile motion;
  double sensor_height_m;
  double voxel_m;      // the paper's voxel size for the kind of scene
  double max_range_m;  // and its range clip
  double min_range_m = 0.3;
  double noise_sigma_m = 0.01;  // rim simulate's default
  // F-score threshold (paper: 3 x voxel) and the sample spacing of meshes and
  // ground truth (rim eval mesh: a quarter of the threshold).
  double thresholdM() const { return 3.0 * voxel_m; }
  double sampleSpacingM() const { return thresholdM() / 4.0; }
};

inline MappingPreset indoorCartPreset() {
  return {"indoor_cart", simulation::SceneKind::kIndoor, "OS-0-128", simulation::MotionProfile::kCart, 1.2, 0.04, 10.0};
}
inline MappingPreset outdoorCarPreset() {
  return {"outdoor_car", simulation::SceneKind::kOutdoor, "OS-1-128", simulation::MotionProfile::kCar, 1.8, 0.10, 30.0};
}
// rim simulate's kitti_like sensor and route, mapped as outdoor_car.
inline MappingPreset kittiLikePreset() {
  return {"kitti_like", simulation::SceneKind::kOutdoor, "hdl64", simulation::MotionProfile::kCar, 1.8, 0.10, 30.0};
}

// The built-in approximation of an Ouster sensor ("OS-0-128", "OS-1-128").
inline LidarModelConstPtr ousterLikeModel(const std::string& product) {
  return std::make_shared<const LidarModel>(
      parseOusterMetadata(simulation::ousterLikeMetadataJson(product, UdpProfile::kRng19Rfl8Sig16Nir16)).intrinsics);
}

// The preset's sensor: KITTI's HDL-64E as rim simulate's for "hdl64", else the Ouster-like one.
inline LidarModelConstPtr presetModel(const MappingPreset& preset) {
  if (preset.product == "hdl64") return std::make_shared<const LidarModel>(io::kittiHdl64Intrinsics());
  return ousterLikeModel(preset.product);
}

struct SimulatedMappingSequence {
  LidarModelConstPtr model;
  std::vector<RangeImage> scans;           // as the sensor reports them: noisy, motion-distorted
  std::vector<mapping::ScanPose> poses;    // exact: pose at the scan time (column 0), true sweep twist
  std::vector<Eigen::Vector3f> surface;    // ground truth: the scene seen within the range clip
};

// Frames 0, step, 2 step, ... of the preset's route (count of them), each
// cast column by column along the trajectory. The ground truth is the scene
// sampled at the preset's spacing where a noise-free hit of a kept scan lay
// within the clip, closer than seen_distance (default: one voxel).
inline SimulatedMappingSequence simulateMappingSequence(const MappingPreset& preset, int count, int step,
                                                        double seen_distance_m = 0.0) {
  using namespace simulation;
  constexpr double kFrequencyHz = 10.0, kStartS = 1.0;
  constexpr uint32_t kSeed = 1;  // also in sceneSurfaceNearRoute
  SceneOptions scene_options;
  scene_options.kind = preset.scene;
  scene_options.seed = kSeed;
  const Scene scene = generateScene(scene_options);
  MotionOptions motion;
  motion.profile = preset.motion;
  motion.duration_s = kStartS + (count * step + 1) / kFrequencyHz + 0.5;
  motion.seed = kSeed;
  motion.sensor_height_m = preset.sensor_height_m;
  const auto trajectory = makeTrajectory(scene, motion);
  SensorEffects effects;
  effects.range_noise_sigma_m = preset.noise_sigma_m;
  const RayCaster caster(scene.mesh);

  SimulatedMappingSequence sequence;
  sequence.model = presetModel(preset);
  const LidarSimulator simulator(sequence.model, caster, effects, kSeed, kFrequencyHz);
  SeenRegion seen(seen_distance_m > 0.0 ? seen_distance_m : preset.voxel_m);
  const LidarModel& model = *sequence.model;
  SimulatedScan scan;
  for (int k = 0; k < count; ++k) {
    const double start = kStartS + k * step / kFrequencyHz;
    simulator.simulate(*trajectory, start, uint32_t(k * step), scan);
    mapping::ScanPose pose;
    pose.world_from_lidar = scan.column_poses.front();
    const double sweep_s = simulator.columnTime(start, model.columns() - 1) - start;
    pose.twist = twistBetween(scan.column_poses.front(), scan.column_poses.back(), sweep_s);
    pose.scan_time_ns = scanTime(scan.image, ScanTimeSource::kFirstValidColumn);
    for (int v = 0; v < model.rows(); ++v)
      for (int u = 0; u < model.columns(); ++u) {
        const float range = scan.true_range[std::size_t(v) * model.columns() + u];
        if (std::isfinite(range) && range >= preset.min_range_m && range <= preset.max_range_m)
          seen.addHit((scan.column_poses[u] * model.unproject(u, v, range).cast<double>()).cast<float>());
      }
    sequence.scans.push_back(scan.image);
    sequence.poses.push_back(pose);
  }
  SurfaceSampleOptions sampling;
  sampling.spacing_m = preset.sampleSpacingM();
  sampling.seed = kSeed;
  sequence.surface = sampleSeenSurface(scene.mesh, seen, sampling);
  return sequence;
}

// Every surface of the preset's scene within the range clip (plus a metre) of
// the sequence's poses, seen or not, at the preset's spacing: what a map's
// points are on when they are on a real surface, for precision where the
// seen-surface truth is thin (between beam rings, where no hit fell).
inline std::vector<Eigen::Vector3f> sceneSurfaceNearRoute(const MappingPreset& preset,
                                                          const SimulatedMappingSequence& sequence) {
  using namespace simulation;
  SceneOptions scene_options;
  scene_options.kind = preset.scene;
  scene_options.seed = 1;  // as simulateMappingSequence
  const Scene scene = generateScene(scene_options);
  SeenRegion near_route(preset.max_range_m + 1.0);
  for (const mapping::ScanPose& pose : sequence.poses)
    near_route.addHit(pose.world_from_lidar.translation().cast<float>());
  SurfaceSampleOptions sampling;
  sampling.spacing_m = preset.sampleSpacingM();
  sampling.seed = 1;
  return sampleSeenSurface(scene.mesh, near_route, sampling);
}

// A mesh as surface samples for compareSurfaces: a grid of the given spacing
// on every triangle (the preset's sampleSpacingM(), as rim eval mesh does).
inline std::vector<Eigen::Vector3f> meshSamples(const TriangleMesh& mesh, double spacing_m) {
  SurfaceSampleOptions sampling;
  sampling.spacing_m = spacing_m;
  return sampleSurface(mesh, sampling);
}

}  // namespace range_image_mapping::test
