#include "range_image_mapping/pipeline/scan_to_map_pipeline.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace range_image_mapping::pipeline {
namespace {

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

Restart restartOf(registration::RestartReason reason) {
  switch (reason) {
    case registration::RestartReason::kFirstScan: return Restart::kFirstScan;
    case registration::RestartReason::kTimeWentBack: return Restart::kTimeWentBack;
    case registration::RestartReason::kTimeGap: return Restart::kTimeGap;
    case registration::RestartReason::kNone: break;
  }
  return Restart::kNone;
}

}  // namespace

const char* restartName(Restart restart) {
  switch (restart) {
    case Restart::kNone: return "none";
    case Restart::kFirstScan: return "first scan";
    case Restart::kTimeWentBack: return "time went back";
    case Restart::kTimeGap: return "time gap";
    case Restart::kSourceStartedOver: return "source started over";
  }
  return "unknown";
}

void PipelineOptions::validate() const {
  if (!odometry && !map) throw std::invalid_argument("pipeline: neither odometry nor map: nothing to do");
  if (!(mesh_period_s >= 0.0) || !std::isfinite(mesh_period_s))
    throw std::invalid_argument("pipeline: mesh_period_s must be finite and >= 0 (0: on request), not " +
                                std::to_string(mesh_period_s));
  if (!(given_twist_max_gap_s > 0.0) || !std::isfinite(given_twist_max_gap_s))
    throw std::invalid_argument("pipeline: given_twist_max_gap_s must be positive and finite, not " +
                                std::to_string(given_twist_max_gap_s));
  const Eigen::Matrix3d rotation = base_from_lidar.linear();
  if (!base_from_lidar.matrix().allFinite() ||
      (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).norm() > 1e-6)
    throw std::invalid_argument("pipeline: base_from_lidar is not a finite rigid transform");
  if (map) map->validate();
}

ScanToMapPipeline::ScanToMapPipeline(PipelineOptions options) : options_(std::move(options)) {
  options_.validate();
  if (options_.odometry) odometry_ = std::make_unique<registration::LidarOdometry>(*options_.odometry);
  if (options_.map) map_ = std::make_unique<mapping::TsdfMap>(*options_.map);
}

ScanResult ScanToMapPipeline::process(const RangeImage& scan, bool source_started_over) {
  if (!odometry_) throw std::logic_error("ScanToMapPipeline::process(scan): no odometry; give the scan's pose");
  ScanResult result;
  result.scan_time_ns = scanTime(scan);
  registration::OdometryUpdate update = odometry_->process(scan, result.scan_time_ns);
  result.restart = restartOf(update.restart);
  // A replay that starts over shows the same places again: going on from the
  // pose reached at the end would map them a second time, elsewhere.
  if (source_started_over && update.restart == registration::RestartReason::kTimeWentBack) {
    odometry_->reset();
    const double seconds = update.seconds;
    update = odometry_->process(scan, result.scan_time_ns);
    update.seconds += seconds;
    update.warning = "a scan older than the last after the source started over: odometry restarted at the identity";
    result.restart = Restart::kSourceStartedOver;
  }
  result.odometry_seconds = update.seconds;
  if (!update.warning.empty()) result.warnings.push_back("odometry: " + update.warning);
  if (!update.skipped) {
    result.has_pose = true;
    // The odometry's world is the lidar at its first scan; the pipeline's is
    // the base there (REP 105's odom): T_world_lidar = T_base_lidar T_lidar0_lidar.
    result.world_from_lidar = options_.base_from_lidar * update.pose;
    result.world_from_base = result.world_from_lidar * options_.base_from_lidar.inverse();
    result.twist << update.angular_velocity, update.linear_velocity;
    if (update.moving_pixels > 0) {
      // Moving objects stay out of the map: no trail where they passed.
      without_moving_ = scan.column_order == ColumnOrder::kStaggered ? scan : scan.staggered();
      const std::vector<uint8_t>& moving = odometry_->movingPixels();
      for (std::size_t i = 0; i < moving.size() && i < without_moving_.range.size(); ++i)
        if (moving[i]) without_moving_.range[i] = std::numeric_limits<float>::quiet_NaN();
      // Normals of the masked scan, as a Mapper fed the Odometry's
      // static_range_image computes them.
      integrate(without_moving_, result, nullptr);
    } else {
      integrate(scan, result, &odometry_->measuredScan());
    }
  }
  result.odometry = std::move(update);
  meshOnCadence(result);
  return result;
}

ScanResult ScanToMapPipeline::process(const RangeImage& scan, const GivenPose& given) {
  ScanResult result;
  result.scan_time_ns = scanTime(scan);
  if (!given.world_from_lidar.matrix().allFinite() || (given.twist && !given.twist->allFinite())) {
    result.warnings.push_back("the given pose or twist is not finite: scan not mapped");
    return result;
  }
  result.has_pose = true;
  result.world_from_lidar = given.world_from_lidar;
  result.world_from_base = given.world_from_lidar * options_.base_from_lidar.inverse();
  if (given.twist) {
    result.twist = *given.twist;
  } else if (last_given_pose_ && result.scan_time_ns > last_given_time_ns_) {
    // The sweep's motion, assumed constant, from the previous pose: a
    // backward difference, for sources that give poses one at a time.
    const double dt_s = double(result.scan_time_ns - last_given_time_ns_) * 1e-9;
    if (dt_s <= options_.given_twist_max_gap_s) result.twist = twistBetween(*last_given_pose_, given.world_from_lidar, dt_s);
  }
  last_given_pose_ = given.world_from_lidar;
  last_given_time_ns_ = result.scan_time_ns;
  integrate(scan, result, nullptr);
  meshOnCadence(result);
  return result;
}

void ScanToMapPipeline::integrate(const RangeImage& scan, ScanResult& result, const VertexNormalMap* normals) {
  if (!map_) return;
  mapping::ScanPose pose;
  pose.world_from_lidar = result.world_from_lidar;
  pose.scan_time_ns = result.scan_time_ns;
  if (options_.deskew_map) pose.twist = result.twist;
  const auto started = std::chrono::steady_clock::now();
  result.map = map_->integrate(scan, pose, normals);
  result.integrate_seconds = secondsSince(started);
  if (!result.map->warning.empty()) result.warnings.push_back("map: " + result.map->warning);
}

void ScanToMapPipeline::meshOnCadence(ScanResult& result) {
  if (!map_ || options_.mesh_period_s <= 0.0 || !result.has_pose) return;
  const uint64_t now = result.scan_time_ns;
  if (last_mesh_time_ns_ == 0 || now < last_mesh_time_ns_) {  // the first scan, or time went back
    last_mesh_time_ns_ = now;
    return;
  }
  if (double(now - last_mesh_time_ns_) * 1e-9 + 1e-6 < options_.mesh_period_s) return;
  last_mesh_time_ns_ = now;
  result.mesh = map_->updateMesh();
  result.mesh_seconds = result.mesh->seconds;
}

mapping::MeshUpdate ScanToMapPipeline::updateMesh() {
  if (!map_) throw std::logic_error("ScanToMapPipeline::updateMesh: no map");
  return map_->updateMesh();
}

void ScanToMapPipeline::reset() {
  if (odometry_) odometry_->reset();
  if (map_) map_->reset();
  last_given_pose_.reset();
  last_given_time_ns_ = 0;
  last_mesh_time_ns_ = 0;
}

}  // namespace range_image_mapping::pipeline
