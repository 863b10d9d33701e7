// The scan-to-map story, told once: each range image gets its scan time, its
// pose (from the odometry, or given), the twist of its sweep, and goes into
// the TSDF map; the mesh follows at a cadence in scan time. `rim run`,
// `rim map`, the Odometry and Mapper nodelets and the benchmarks all call it,
// so they agree on every convention by construction.
#pragma once

#include "range_image_mapping/mapping/tsdf_map.h"
#include "range_image_mapping/registration/lidar_odometry.h"
#include "range_image_mapping/scan_motion.h"

#include <Eigen/Geometry>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace range_image_mapping::pipeline {

// What each part of the pipeline is: either may be off (the Odometry nodelet
// has no map; the Mapper and `rim map` take poses from elsewhere).
struct PipelineOptions {
  ScanTimeSource scan_time = ScanTimeSource::kFirstValidColumn;
  std::optional<registration::OdometryOptions> odometry;  // none: poses are given
  std::optional<mapping::TsdfMapOptions> map;             // none: odometry only
  // The map is deskewed by the sweep's twist (the odometry's estimate, or the
  // one given); off: each scan is integrated as if taken at one instant.
  bool deskew_map = true;
  // Re-mesh after this much scan time since the last mesh update (0: only
  // when asked, with updateMesh()).
  double mesh_period_s = 1.0;
  // Given poses without a twist: the twist from the previous given pose, if
  // it is at most this much older (a gap or a restart gives none).
  double given_twist_max_gap_s = 0.5;
  // The robot's base from the lidar, for poses of the base. With the odometry,
  // the world (odom, REP 105) is the base at the first scan.
  Eigen::Isometry3d base_from_lidar = Eigen::Isometry3d::Identity();
  // Throws std::invalid_argument naming the field.
  void validate() const;
};

// A pose from outside the pipeline (a pose file, tf, another odometry).
struct GivenPose {
  Eigen::Isometry3d world_from_lidar = Eigen::Isometry3d::Identity();  // at the scan time
  // The sweep's body twist in the lidar frame, when the source knows it; else
  // the pipeline takes it from this pose and the previous given one.
  std::optional<Twist> twist;
};

// Why the pipeline started over (a restart of the odometry, or of the source).
enum class Restart {
  kNone,
  kFirstScan,
  kTimeWentBack,     // the odometry restarted from its current pose
  kTimeGap,          // likewise
  kSourceStartedOver,  // the source replays from its start (a bag loop): odometry at the identity
};
const char* restartName(Restart restart);

struct ScanResult {
  uint64_t scan_time_ns = 0;
  // Present when the pipeline runs the odometry.
  std::optional<registration::OdometryUpdate> odometry;
  bool has_pose = false;  // false: the scan was skipped (see warnings) and nothing below is set
  Eigen::Isometry3d world_from_lidar = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d world_from_base = Eigen::Isometry3d::Identity();
  Twist twist = Twist::Zero();  // of the sweep, lidar frame, [angular, linear]
  Restart restart = Restart::kNone;
  // Present when the pipeline has a map.
  std::optional<mapping::MapUpdate> map;
  // Present when the scan time reached the mesh cadence.
  std::optional<mapping::MeshUpdate> mesh;
  std::vector<std::string> warnings;  // everything the user should hear of this scan
  double odometry_seconds = 0.0, integrate_seconds = 0.0, mesh_seconds = 0.0;
};

class ScanToMapPipeline {
 public:
  explicit ScanToMapPipeline(PipelineOptions options);  // validates

  // Odometry, then the map at the odometry's pose with its twist of that scan.
  // source_started_over: the caller saw its source start again (ROS time went
  // back: a bag loop); if the odometry then finds the scan older than the last,
  // it starts over at the identity instead of going on from its pose.
  ScanResult process(const RangeImage& scan, bool source_started_over = false);
  // The map at a given pose (no odometry needed).
  ScanResult process(const RangeImage& scan, const GivenPose& pose);

  // Re-meshes what changed now, whatever the cadence.
  mapping::MeshUpdate updateMesh();
  // Forgets the odometry's state and the map: the next scan starts afresh.
  void reset();

  uint64_t scanTime(const RangeImage& scan) const { return range_image_mapping::scanTime(scan, options_.scan_time); }
  const PipelineOptions& options() const { return options_; }
  void setBaseFromLidar(const Eigen::Isometry3d& base_from_lidar) { options_.base_from_lidar = base_from_lidar; }
  registration::LidarOdometry* odometry() { return odometry_.get(); }
  const registration::LidarOdometry* odometry() const { return odometry_.get(); }
  mapping::TsdfMap* map() { return map_.get(); }
  const mapping::TsdfMap* map() const { return map_.get(); }

 private:
  // normals: the odometry's map of this scan, when there is one.
  void integrate(const RangeImage& scan, ScanResult& result, const VertexNormalMap* normals);
  void meshOnCadence(ScanResult& result);

  PipelineOptions options_;
  std::unique_ptr<registration::LidarOdometry> odometry_;
  std::unique_ptr<mapping::TsdfMap> map_;
  // The previous given pose and its time, for a twist the source did not give.
  std::optional<Eigen::Isometry3d> last_given_pose_;
  uint64_t last_given_time_ns_ = 0;
  uint64_t last_mesh_time_ns_ = 0;
  RangeImage without_moving_;  // the scan as mapped when the odometry found moving pixels
};

}  // namespace range_image_mapping::pipeline
