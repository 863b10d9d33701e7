// Mapper: range images in (the Adapter's shared pointers, same manager), each
// with its pose from tf or from the Odometry nodelet (PoseSource); a TSDF map
// (paper section 4.2) out as rviz markers of the mesh (MeshMarkers), the mesh
// vertices as a cloud, and a PLY on request.
//
// Every callback (images, odometry, services, timers, subscriber connections)
// runs on the nodelet's single-threaded queue (getNodeHandle), so the members
// need no locks. Nothing thrown by bad input leaves a callback: it is counted
// and logged (throttled). Integration happens in the scan callback, meshing
// only in the mesh timer, so a slow mesh never delays a scan by more than one
// timer callback, and while the Mapper is behind (its last scan entered the
// map more than mesh_defer_latency after its stamp) mesh updates wait, so
// under load integration keeps up and the mesh slows.
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/SaveMesh.h"
#include "range_image_mapping/io/mesh_file.h"
#include "range_image_mapping/pipeline/scan_to_map_pipeline.h"
#include "range_image_mapping/ros/mesh_display.h"
#include "range_image_mapping/ros/parameters.h"
#include "range_image_mapping/ros/pose_source.h"
#include "range_image_mapping/ros/range_image_conversions.h"
#include "range_image_mapping/ros/statistics_window.h"
#include "range_image_mapping/ros/steady_throttle.h"
#include "range_image_mapping/ros/wall_clock_diagnostics.h"

#include <diagnostic_updater/diagnostic_updater.h>
#include <nav_msgs/Odometry.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Empty.h>
#include <visualization_msgs/MarkerArray.h>

#include <boost/make_shared.hpp>

#include <Eigen/Geometry>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

namespace range_image_mapping {
namespace {

// Counts since the start; windows (log, diagnostics) are differences of two snapshots.
struct MapperStatistics {
  std::size_t scans = 0;           // range images received
  std::size_t integrated = 0;      // given to the map and integrated
  std::size_t refused = 0;         // given to the map and refused (pose jump, bad pose, unusable image)
  // Without a pose (PoseSource), by reason.
  std::size_t dropped_queue_full = 0, dropped_timed_out = 0, dropped_skipped = 0, dropped_unusable = 0;
  std::size_t missing_upstream = 0;  // gaps in the frame counter: lost before the Mapper
  std::size_t rejected = 0;        // messages that could not be converted
  double integration_seconds = 0.0;  // wall time in TsdfMap::integrate
  double pose_wait_seconds = 0.0;    // wall time scans waited for their pose
  std::size_t posed = 0;             // scans answered with a pose (pose_wait_seconds' count)
  double latency_seconds = 0.0;      // scan stamp to integrated (ROS time), summed over `latencies`
  std::size_t latencies = 0;
  std::size_t mesh_updates = 0, mesh_deferred = 0;
  double mesh_seconds = 0.0;  // wall time in TsdfMap::updateMesh

  std::size_t droppedNoPose() const {
    return dropped_queue_full + dropped_timed_out + dropped_skipped + dropped_unusable;
  }

  MapperStatistics operator-(const MapperStatistics& earlier) const {
    MapperStatistics d;
    d.scans = scans - earlier.scans;
    d.integrated = integrated - earlier.integrated;
    d.refused = refused - earlier.refused;
    d.dropped_queue_full = dropped_queue_full - earlier.dropped_queue_full;
    d.dropped_timed_out = dropped_timed_out - earlier.dropped_timed_out;
    d.dropped_skipped = dropped_skipped - earlier.dropped_skipped;
    d.dropped_unusable = dropped_unusable - earlier.dropped_unusable;
    d.missing_upstream = missing_upstream - earlier.missing_upstream;
    d.rejected = rejected - earlier.rejected;
    d.integration_seconds = integration_seconds - earlier.integration_seconds;
    d.pose_wait_seconds = pose_wait_seconds - earlier.pose_wait_seconds;
    d.posed = posed - earlier.posed;
    d.latency_seconds = latency_seconds - earlier.latency_seconds;
    d.latencies = latencies - earlier.latencies;
    d.mesh_updates = mesh_updates - earlier.mesh_updates;
    d.mesh_deferred = mesh_deferred - earlier.mesh_deferred;
    d.mesh_seconds = mesh_seconds - earlier.mesh_seconds;
    return d;
  }
};

// Mesh updates in a row that wait while the Mapper is behind: the mesh still
// moves under sustained load.
constexpr int kMaxDeferredMeshUpdates = 5;

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Refuses what io::saveMeshFile could only fail on later, with a message
// naming the problem.
std::string unwritablePathReason(const std::string& path) {
  namespace fs = std::filesystem;
  if (path.empty()) return "the path is empty";
  const fs::path file(path);
  if (!file.is_absolute())
    return "'" + path + "' is not an absolute path (a nodelet's working directory is the manager's)";
  std::error_code error;
  if (fs::is_directory(file, error)) return "'" + path + "' is a directory";
  const fs::path folder = file.parent_path();
  if (!fs::is_directory(folder, error)) return "the folder " + folder.string() + " does not exist";
  if (fs::exists(file, error) ? ::access(path.c_str(), W_OK) != 0 : ::access(folder.c_str(), W_OK) != 0)
    return "'" + path + "' is not writable";
  return "";
}

}  // namespace

class MapperNodelet : public nodelet::Nodelet {
 public:
  void onInit() override;

 private:
  using ImageConstPtr = LidarRangeImage::ConstPtr;

  // Scans (and odometry) in: to the pose source, which answers each scan
  // with its pose or why none (onScanPose).
  void onRangeImage(const ImageConstPtr& message);
  void onScanPose(const LidarRangeImage& message, const PoseLookup& lookup);

  void integrate(const LidarRangeImage& message, const LidarPose& pose);
  void dropScan(const LidarRangeImage& message, const std::string& reason);

  // Mesh output.
  void onMeshTimer(const ros::SteadyTimerEvent&);
  void updateMesh();  // the one caller of TsdfMap::updateMesh: every change reaches mesh_markers_
  void publishSurfacePoints();

  bool onSaveMesh(SaveMesh::Request& request, SaveMesh::Response& response);
  bool onReset(std_srvs::Empty::Request&, std_srvs::Empty::Response&);
  bool onRepublishMesh(std_srvs::Empty::Request&, std_srvs::Empty::Response&);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);
  void onStatisticsTimer(const ros::SteadyTimerEvent&);

  MapperParameters parameters_;
  std::unique_ptr<pipeline::ScanToMapPipeline> pipeline_;  // the map at given poses
  mapping::TsdfMap& map() { return *pipeline_->map(); }
  std::unique_ptr<PoseSource> pose_source_;
  std::unique_ptr<MeshMarkers> mesh_markers_;
  LidarModelCache models_;

  ros::Subscriber range_image_subscriber_, odometry_subscriber_;
  ros::Publisher mesh_publisher_, surface_points_publisher_;
  ros::ServiceServer save_mesh_service_, reset_service_, republish_mesh_service_;
  ros::SteadyTimer mesh_timer_, statistics_timer_;
  std::unique_ptr<WallClockDiagnostics> diagnostics_;

  ros::Time last_scan_stamp_;  // of the last scan with a pose
  Eigen::Vector3f sensor_position_ = Eigen::Vector3f::Zero();  // of the last scan integrated: the display's viewpoint
  std::optional<uint32_t> last_frame_counter_;  // LidarRangeImage::frame_id of the last scan received
  double last_latency_s_ = 0.0;                 // of the last scan integrated
  int scans_since_mesh_tick_ = 0;               // integrated (with a latency) since the last mesh timer callback
  int deferred_in_a_row_ = 0;
  // Diagnostics window maxima (reset by diagnose).
  double max_latency_s_ = 0.0;
  std::size_t max_waiting_ = 0;

  MapperStatistics statistics_;
  StatisticsWindow<MapperStatistics> log_window_, diagnostics_window_;
  std::string last_warning_;
  SteadyThrottle warning_log_, drop_log_, error_log_, triangle_log_;
};

void MapperNodelet::onInit() {
  ros::NodeHandle& node = getNodeHandle();
  ros::NodeHandle& private_node = getPrivateNodeHandle();
  startOrRefuseLoad(getName(), "Mapper", [&] {
    parameters_ = readMapperParameters(private_node);
    pipeline::PipelineOptions options;
    options.map = parameters_.map;
    options.deskew_map = parameters_.deskew;
    options.given_twist_max_gap_s = parameters_.max_time_gap_s;
    // Meshing runs on the mesh timer, apart from the scan callback, so a slow
    // mesh update never holds up integration.
    options.mesh_period_s = 0.0;
    pipeline_ = std::make_unique<pipeline::ScanToMapPipeline>(options);
  });
  pose_source_ = std::make_unique<PoseSource>(
      node, parameters_, getName(),
      [this](const LidarRangeImage& message, const PoseLookup& lookup) { onScanPose(message, lookup); });
  mesh_markers_ = std::make_unique<MeshMarkers>(parameters_);

  // A late subscriber (rviz started after the mapper) gets everything at the
  // next mesh update; the others see the chunks again, which replace themselves.
  // The queue holds a full re-send split into messages (kTrianglesPerMessage).
  mesh_publisher_ = node.advertise<visualization_msgs::MarkerArray>(
      "mesh", 16, [this](const ros::SingleSubscriberPublisher&) { mesh_markers_->requestFullResend(); });
  surface_points_publisher_ = node.advertise<sensor_msgs::PointCloud2>("surface_points", 1);
  save_mesh_service_ = private_node.advertiseService("save_mesh", &MapperNodelet::onSaveMesh, this);
  reset_service_ = private_node.advertiseService("reset", &MapperNodelet::onReset, this);
  republish_mesh_service_ = private_node.advertiseService("republish_mesh", &MapperNodelet::onRepublishMesh, this);

  diagnostics_ = std::make_unique<WallClockDiagnostics>(node, private_node, getName(), "tsdf_mapper");
  diagnostics_->updater().add("mapping", this, &MapperNodelet::diagnose);
  statistics_timer_ = node.createSteadyTimer(ros::WallDuration(parameters_.statistics_period_s),
                                             &MapperNodelet::onStatisticsTimer, this);
  log_window_.advance(statistics_);  // the first windows start now
  diagnostics_window_.advance(statistics_);
  mesh_timer_ = node.createSteadyTimer(ros::WallDuration(1.0 / parameters_.mesh_rate_hz),
                                       &MapperNodelet::onMeshTimer, this);

  range_image_subscriber_ = node.subscribe("range_image", parameters_.queue_size, &MapperNodelet::onRangeImage, this);
  if (parameters_.pose_source == PoseSourceType::kOdometry)
    odometry_subscriber_ = node.subscribe<nav_msgs::Odometry>(
        "odometry", parameters_.queue_size,
        [this](const nav_msgs::Odometry::ConstPtr& odometry) { pose_source_->addOdometry(odometry); });
  const std::string image_topic = range_image_subscriber_.getTopic();
  std::string poses = pose_source_->description();
  if (odometry_subscriber_) poses += ", odometry on " + odometry_subscriber_.getTopic();
  const mapping::TsdfMapOptions& map = parameters_.map;
  NODELET_INFO("Mapper: range images from %s, poses from %s, mesh on %s in %s; voxel %.3f m, blocks of %d^3, "
               "truncation %.3f m, range [%.1f, %.1f] m, %s",
               image_topic.c_str(), poses.c_str(), mesh_publisher_.getTopic().c_str(),
               parameters_.world_frame.c_str(), map.grid.voxel_size_m, map.grid.block_edge,
               map.integrator.truncationFor(map.grid), map.integrator.min_range_m, map.integrator.max_range_m,
               !parameters_.deskew                                     ? "no deskew"
               : parameters_.pose_source == PoseSourceType::kOdometry ? "deskewed with the odometry's twist"
                                                                       : "deskewed with the twist between poses");
}

// ------------------------------------------------------------ scans and their poses

void MapperNodelet::onRangeImage(const ImageConstPtr& message) {
  ++statistics_.scans;
  // A gap in the sensor's counter: scans lost before the Mapper (the
  // Odometry's own drops, which it reports, or this subscriber's full queue).
  if (last_frame_counter_ && message->frame_id > *last_frame_counter_ + 1) {
    const std::size_t missing = message->frame_id - *last_frame_counter_ - 1;
    statistics_.missing_upstream += missing;
    if (drop_log_.allow(1.0))
      NODELET_WARN("%zu scans before scan %u never reached the Mapper (%zu so far): dropped by the Odometry, or "
                   "by a full subscriber queue (queue_size %d)",
                   missing, message->frame_id, statistics_.missing_upstream, parameters_.queue_size);
  }
  last_frame_counter_ = message->frame_id;
  pose_source_->addScan(message);
  max_waiting_ = std::max(max_waiting_, pose_source_->waitingCount());
}

void MapperNodelet::onScanPose(const LidarRangeImage& message, const PoseLookup& lookup) {
  if (!lookup.pose) {
    switch (lookup.no_pose) {
      case NoPoseReason::kQueueFull: ++statistics_.dropped_queue_full; break;
      case NoPoseReason::kTimedOut: ++statistics_.dropped_timed_out; break;
      case NoPoseReason::kSkipped: ++statistics_.dropped_skipped; break;
      default: ++statistics_.dropped_unusable; break;
    }
    dropScan(message, lookup.reason);
    return;
  }
  ++statistics_.posed;
  statistics_.pose_wait_seconds += lookup.waited_s;
  try {
    integrate(message, *lookup.pose);
  } catch (const std::exception& error) {
    ++statistics_.rejected;
    if (error_log_.allow(parameters_.statistics_period_s))
      NODELET_ERROR("range image stamped %.3f failed: %s", message.header.stamp.toSec(), error.what());
  }
}

void MapperNodelet::dropScan(const LidarRangeImage& message, const std::string& reason) {
  last_warning_ = reason;
  if (drop_log_.allow(1.0))
    NODELET_WARN("scan %u stamped %.3f not mapped: %s (%zu without pose so far)", message.frame_id,
                 message.header.stamp.toSec(), reason.c_str(), statistics_.droppedNoPose());
}

// ------------------------------------------------------------ integration

void MapperNodelet::integrate(const LidarRangeImage& message, const LidarPose& lidar_pose) {
  RangeImage image;
  try {
    image = fromMessage(message, models_);
  } catch (const std::exception& error) {
    ++statistics_.rejected;
    if (error_log_.allow(parameters_.statistics_period_s))
      NODELET_ERROR("range image stamped %.3f dropped: %s", message.header.stamp.toSec(), error.what());
    return;
  }
  // The sweep's motion: the odometry's twist, the one it deskewed the scan
  // with; from tf none, and the pipeline takes the twist since the previous
  // pose over the scan times (the sensor's clock when columns carry times).
  pipeline::GivenPose given;
  given.world_from_lidar = lidar_pose.world_from_lidar;
  given.twist = lidar_pose.twist;
  const pipeline::ScanResult result = pipeline_->process(image, given);
  if (result.has_pose) {
    last_scan_stamp_ = message.header.stamp;
    sensor_position_ = lidar_pose.world_from_lidar.translation().cast<float>();
    // Scan-to-map latency on the ROS clock (the bag's in a replay). A stamp
    // from another clock (an unsynchronised sensor) gives nonsense: left out.
    const double latency_s = (ros::Time::now() - message.header.stamp).toSec();
    if (latency_s > -1.0 && latency_s < 3600.0) {
      last_latency_s_ = latency_s;
      ++scans_since_mesh_tick_;
      statistics_.latency_seconds += latency_s;
      ++statistics_.latencies;
      max_latency_s_ = std::max(max_latency_s_, latency_s);
    }
  }
  statistics_.integration_seconds += result.integrate_seconds;
  mapping::MapUpdate update;
  if (result.map) update = *result.map;
  else update.warning = result.warnings.empty() ? "no pose" : result.warnings.front();
  if (update.integrated)
    ++statistics_.integrated;
  else
    ++statistics_.refused;
  if (!update.warning.empty()) {
    last_warning_ = update.warning;
    if (warning_log_.allow(1.0))
      NODELET_WARN("scan %u stamped %.3f %s: %s", message.frame_id, message.header.stamp.toSec(),
                   update.integrated ? "partly integrated" : "refused", update.warning.c_str());
  }
}

// ------------------------------------------------------------ mesh output

void MapperNodelet::updateMesh() {
  const auto start = std::chrono::steady_clock::now();
  const mapping::MeshUpdate update = pipeline_->updateMesh();
  statistics_.mesh_seconds += secondsSince(start);
  ++statistics_.mesh_updates;
  mesh_markers_->noteChanges(update);
}

void MapperNodelet::onMeshTimer(const ros::SteadyTimerEvent&) {
  // Behind: the scans waiting in the subscriber queue come first. Only while
  // scans keep coming: once none came since the last tick (the replay or the
  // sensor stopped, the backlog is gone) the last scan's latency says
  // nothing about scans waiting, and the mesh catches up at once.
  const bool scans_came = scans_since_mesh_tick_ > 0;
  scans_since_mesh_tick_ = 0;
  if (scans_came && parameters_.mesh_defer_latency_s > 0.0 && last_latency_s_ > parameters_.mesh_defer_latency_s &&
      deferred_in_a_row_ < kMaxDeferredMeshUpdates) {
    ++deferred_in_a_row_;
    ++statistics_.mesh_deferred;
    return;
  }
  deferred_in_a_row_ = 0;
  // Nobody listens: no meshing (save_mesh meshes what it needs, and the map
  // meshes blocks before the memory radius drops them).
  if (mesh_publisher_.getNumSubscribers() == 0 && surface_points_publisher_.getNumSubscribers() == 0) {
    mesh_markers_->forgetSubscribers();  // the next subscriber needs all of it
    return;
  }
  try {
    updateMesh();
    const std::size_t triangles = map().mesh().triangleCount();
    if (triangles > parameters_.triangle_warning && triangle_log_.allow(60.0))
      NODELET_WARN("the mesh has %zu triangles (more than triangle_warning %zu), the markers show %zu "
                   "(display_triangle_budget %zu, 0: all); a larger voxel_size or a memory_radius keeps the map "
                   "smaller",
                   triangles, parameters_.triangle_warning, mesh_markers_->shownTriangles(),
                   parameters_.display_triangle_budget);
    if (mesh_publisher_.getNumSubscribers() == 0)
      mesh_markers_->forgetSubscribers();  // nobody holds the mesh: the next subscriber needs all of it
    else
      for (const MeshMarkers::Message& message : mesh_markers_->update(map().mesh(), sensor_position_))
        mesh_publisher_.publish(message);
    if (surface_points_publisher_.getNumSubscribers() > 0) publishSurfacePoints();
  } catch (const std::exception& error) {
    if (error_log_.allow(parameters_.statistics_period_s)) NODELET_ERROR("mesh update failed: %s", error.what());
  }
}

void MapperNodelet::publishSurfacePoints() {
  const auto cloud = boost::make_shared<sensor_msgs::PointCloud2>();
  std_msgs::Header header;
  header.frame_id = parameters_.world_frame;
  header.stamp = last_scan_stamp_;
  meshVerticesToPointCloud2(map().mesh().chunks(), parameters_.map.grid.store_intensity,
                            parameters_.display_max_height_m, header, *cloud);
  surface_points_publisher_.publish(boost::shared_ptr<const sensor_msgs::PointCloud2>(cloud));
}

// ------------------------------------------------------------ services

bool MapperNodelet::onSaveMesh(SaveMesh::Request& request, SaveMesh::Response& response) {
  response.success = false;
  const std::string reason = unwritablePathReason(request.path);
  if (!reason.empty()) {
    response.message = "mesh not saved: " + reason;
    NODELET_ERROR("%s", response.message.c_str());
    return true;
  }
  try {
    updateMesh();  // here rather than inside fullMesh, so the changed chunks still reach rviz
    const std::size_t triangles = map().mesh().triangleCount();
    if (triangles == 0) {
      response.message = "mesh not saved: the map has no surface yet (" + std::to_string(statistics_.integrated) +
                         " scans integrated)";
      return true;
    }
    io::saveMeshFile(request.path, map().fullMesh());
    response.success = true;
    response.message = "saved " + std::to_string(triangles) + " triangles from " +
                       std::to_string(map().statistics().scans_integrated) + " scans to " + request.path;
    NODELET_INFO("%s", response.message.c_str());
  } catch (const std::exception& error) {
    response.message = "mesh not saved to " + request.path + ": " + error.what();
    NODELET_ERROR("%s", response.message.c_str());
  }
  return true;
}

bool MapperNodelet::onReset(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
  map().reset();
  pose_source_->clear();
  // Subscribers drop the old mesh now; the next mesh update sends only new chunks.
  const MeshMarkers::Message clear_all = mesh_markers_->clear();
  if (mesh_publisher_.getNumSubscribers() > 0) mesh_publisher_.publish(clear_all);
  NODELET_INFO("map reset: empty, the next scan starts a new map");
  return true;
}

bool MapperNodelet::onRepublishMesh(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
  mesh_markers_->requestFullResend();  // at the next mesh update
  return true;
}

// ------------------------------------------------------------ statistics

void MapperNodelet::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  const auto [window, period] = diagnostics_window_.advance(statistics_);
  const mapping::MapStatistics map_statistics = map().statistics();
  status.add("rate (Hz)", period > 0.0 ? double(window.integrated) / period : 0.0);
  status.add("scans received", window.scans);
  status.add("scans integrated", window.integrated);
  status.add("scans refused", window.refused);
  status.add("scans without pose", window.droppedNoPose());
  status.add("dropped: pose queue full", window.dropped_queue_full);
  status.add("dropped: pose timed out", window.dropped_timed_out);
  status.add("dropped: skipped by the odometry", window.dropped_skipped);
  status.add("dropped: unusable pose", window.dropped_unusable);
  status.add("scans lost before the mapper", window.missing_upstream);
  status.add("rejected messages", window.rejected);
  status.add("scans waiting for a pose", pose_source_->waitingCount());
  status.add("max scans waiting for a pose", max_waiting_);
  status.add("mean pose wait (ms)", window.posed > 0 ? 1e3 * window.pose_wait_seconds / double(window.posed) : 0.0);
  status.add("mean scan-to-map latency (ms)",
             window.latencies > 0 ? 1e3 * window.latency_seconds / double(window.latencies) : 0.0);
  status.add("max scan-to-map latency (ms)", 1e3 * max_latency_s_);
  max_latency_s_ = 0.0;
  max_waiting_ = pose_source_->waitingCount();
  status.add("mean integration (ms)",
             window.integrated + window.refused > 0
                 ? 1e3 * window.integration_seconds / double(window.integrated + window.refused)
                 : 0.0);
  status.add("mean mesh update (ms)",
             window.mesh_updates > 0 ? 1e3 * window.mesh_seconds / double(window.mesh_updates) : 0.0);
  status.add("mesh updates deferred (behind)", window.mesh_deferred);
  status.add("total scans received", statistics_.scans);
  status.add("total scans without pose", statistics_.droppedNoPose());
  status.add("total scans lost before the mapper", statistics_.missing_upstream);
  status.add("total scans integrated", map_statistics.scans_integrated);
  status.add("total scans refused", map_statistics.scans_refused);
  status.add("blocks", map_statistics.blocks);
  status.add("memory (MB)", double(map_statistics.memory_bytes) / (1024.0 * 1024.0));
  status.add("triangles", map_statistics.triangles);
  status.add("triangles shown", mesh_markers_->shownTriangles());
  status.add("last warning", last_warning_);
  if (window.scans == 0)
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "no range images");
  else if (window.integrated == 0)
    status.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "nothing integrated: " + last_warning_);
  else if (!pose_source_->mountFallback().empty())
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, pose_source_->mountFallback());
  else if (window.refused + window.droppedNoPose() + window.rejected + window.missing_upstream > 0)
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "scans refused, without pose or lost before the mapper");
  else
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "mapping");
}

void MapperNodelet::onStatisticsTimer(const ros::SteadyTimerEvent&) {
  const auto [window, period] = log_window_.advance(statistics_);
  if (window.scans == 0 || period <= 0.0) return;
  const mapping::MapStatistics map_statistics = map().statistics();
  const std::size_t given = window.integrated + window.refused;
  NODELET_INFO("mapper: %.1f Hz, %.1f ms per scan, %.0f ms scan-to-map; integrated %zu, refused %zu, without pose "
               "%zu, lost before %zu, rejected %zu; %zu blocks, %.1f MB, %zu triangles (%zu shown), %.1f ms per mesh "
               "update, %zu deferred",
               double(window.integrated) / period, given > 0 ? 1e3 * window.integration_seconds / double(given) : 0.0,
               window.latencies > 0 ? 1e3 * window.latency_seconds / double(window.latencies) : 0.0,
               window.integrated, window.refused, window.droppedNoPose(), window.missing_upstream, window.rejected,
               map_statistics.blocks, double(map_statistics.memory_bytes) / (1024.0 * 1024.0),
               map_statistics.triangles, mesh_markers_->shownTriangles(),
               window.mesh_updates > 0 ? 1e3 * window.mesh_seconds / double(window.mesh_updates) : 0.0,
               window.mesh_deferred);
}

}  // namespace range_image_mapping

PLUGINLIB_EXPORT_CLASS(range_image_mapping::MapperNodelet, nodelet::Nodelet)
