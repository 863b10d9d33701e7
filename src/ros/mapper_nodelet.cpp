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
// timer callback.
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
#include <message_filters/subscriber.h>
#include <message_filters/time_synchronizer.h>
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
  std::size_t dropped_no_pose = 0;  // no tf in time, queue full, no base -> lidar transform, wrong frame
  std::size_t rejected = 0;        // messages that could not be converted
  double integration_seconds = 0.0;  // wall time in TsdfMap::integrate
  std::size_t mesh_updates = 0;
  double mesh_seconds = 0.0;  // wall time in TsdfMap::updateMesh

  MapperStatistics operator-(const MapperStatistics& earlier) const {
    MapperStatistics d;
    d.scans = scans - earlier.scans;
    d.integrated = integrated - earlier.integrated;
    d.refused = refused - earlier.refused;
    d.dropped_no_pose = dropped_no_pose - earlier.dropped_no_pose;
    d.rejected = rejected - earlier.rejected;
    d.integration_seconds = integration_seconds - earlier.integration_seconds;
    d.mesh_updates = mesh_updates - earlier.mesh_updates;
    d.mesh_seconds = mesh_seconds - earlier.mesh_seconds;
    return d;
  }
};

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
  using Synchronizer = message_filters::TimeSynchronizer<LidarRangeImage, nav_msgs::Odometry>;

  // Scans in: to the pose source, which answers each with its pose (onScanPose).
  void onRangeImage(const ImageConstPtr& message);
  void onRangeImageWithOdometry(const ImageConstPtr& message, const nav_msgs::Odometry::ConstPtr& odometry);
  void onUnmatchedImage(const ImageConstPtr& message);
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

  ros::Subscriber range_image_subscriber_;  // pose_source tf
  std::unique_ptr<message_filters::Subscriber<LidarRangeImage>> synchronized_image_subscriber_;
  std::unique_ptr<message_filters::Subscriber<nav_msgs::Odometry>> odometry_subscriber_;
  std::unique_ptr<Synchronizer> synchronizer_;
  ros::Publisher mesh_publisher_, surface_points_publisher_;
  ros::ServiceServer save_mesh_service_, reset_service_, republish_mesh_service_;
  ros::SteadyTimer mesh_timer_, statistics_timer_;
  std::unique_ptr<WallClockDiagnostics> diagnostics_;

  ros::Time last_scan_stamp_;  // of the last scan with a pose

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

  std::string image_topic;
  if (parameters_.pose_source == PoseSourceType::kTf) {
    range_image_subscriber_ =
        node.subscribe("range_image", parameters_.queue_size, &MapperNodelet::onRangeImage, this);
    image_topic = range_image_subscriber_.getTopic();
  } else {
    synchronized_image_subscriber_ =
        std::make_unique<message_filters::Subscriber<LidarRangeImage>>(node, "range_image", parameters_.queue_size);
    odometry_subscriber_ =
        std::make_unique<message_filters::Subscriber<nav_msgs::Odometry>>(node, "odometry", parameters_.queue_size);
    synchronizer_ = std::make_unique<Synchronizer>(*synchronized_image_subscriber_, *odometry_subscriber_,
                                                   parameters_.queue_size);
    synchronizer_->registerCallback(
        boost::bind(&MapperNodelet::onRangeImageWithOdometry, this, boost::placeholders::_1, boost::placeholders::_2));
    // An image that leaves the synchronizer's queue unmatched had no odometry
    // (skipped by the Odometry, or the queue is too short for its latency).
    synchronizer_->registerDropCallback(boost::bind(&MapperNodelet::onUnmatchedImage, this, boost::placeholders::_1));
    image_topic = synchronized_image_subscriber_->getTopic();
  }
  std::string poses = pose_source_->description();
  if (odometry_subscriber_) poses += ", odometry on " + odometry_subscriber_->getTopic();
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
  pose_source_->addScan(message);
}

void MapperNodelet::onRangeImageWithOdometry(const ImageConstPtr& message,
                                             const nav_msgs::Odometry::ConstPtr& odometry) {
  ++statistics_.scans;
  pose_source_->addScan(message, *odometry);
}

void MapperNodelet::onUnmatchedImage(const ImageConstPtr& message) {
  if (!message) return;  // an odometry message without its image
  ++statistics_.scans;
  dropScan(*message, "no odometry with the same stamp");
}

void MapperNodelet::onScanPose(const LidarRangeImage& message, const PoseLookup& lookup) {
  if (!lookup.pose) {
    dropScan(message, lookup.reason);
    return;
  }
  try {
    integrate(message, *lookup.pose);
  } catch (const std::exception& error) {
    ++statistics_.rejected;
    if (error_log_.allow(parameters_.statistics_period_s))
      NODELET_ERROR("range image stamped %.3f failed: %s", message.header.stamp.toSec(), error.what());
  }
}

void MapperNodelet::dropScan(const LidarRangeImage& message, const std::string& reason) {
  ++statistics_.dropped_no_pose;
  last_warning_ = reason;
  if (drop_log_.allow(1.0))
    NODELET_WARN("scan %u stamped %.3f not mapped: %s (%zu dropped so far)", message.frame_id,
                 message.header.stamp.toSec(), reason.c_str(), statistics_.dropped_no_pose);
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
  if (result.has_pose) last_scan_stamp_ = message.header.stamp;
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
  try {
    updateMesh();
    const std::size_t triangles = map().mesh().triangleCount();
    if (triangles > parameters_.triangle_warning && triangle_log_.allow(60.0))
      NODELET_WARN("the mesh has %zu triangles (more than triangle_warning %zu): rviz slows down; a larger "
                   "voxel_size or a memory_radius keeps it smaller",
                   triangles, parameters_.triangle_warning);
    if (mesh_publisher_.getNumSubscribers() == 0)
      mesh_markers_->forgetSubscribers();  // nobody holds the mesh: the next subscriber needs all of it
    else
      for (const MeshMarkers::Message& message : mesh_markers_->update(map().mesh())) mesh_publisher_.publish(message);
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
  status.add("scans without pose", window.dropped_no_pose);
  status.add("rejected messages", window.rejected);
  status.add("mean integration (ms)",
             window.integrated + window.refused > 0
                 ? 1e3 * window.integration_seconds / double(window.integrated + window.refused)
                 : 0.0);
  status.add("mean mesh update (ms)",
             window.mesh_updates > 0 ? 1e3 * window.mesh_seconds / double(window.mesh_updates) : 0.0);
  status.add("total scans integrated", map_statistics.scans_integrated);
  status.add("total scans refused", map_statistics.scans_refused);
  status.add("blocks", map_statistics.blocks);
  status.add("memory (MB)", double(map_statistics.memory_bytes) / (1024.0 * 1024.0));
  status.add("triangles", map_statistics.triangles);
  status.add("last warning", last_warning_);
  if (window.scans == 0)
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "no range images");
  else if (window.integrated == 0)
    status.summary(diagnostic_msgs::DiagnosticStatus::ERROR, "nothing integrated: " + last_warning_);
  else if (window.refused + window.dropped_no_pose + window.rejected > 0)
    status.summary(diagnostic_msgs::DiagnosticStatus::WARN, "scans refused or without pose");
  else
    status.summary(diagnostic_msgs::DiagnosticStatus::OK, "mapping");
}

void MapperNodelet::onStatisticsTimer(const ros::SteadyTimerEvent&) {
  const auto [window, period] = log_window_.advance(statistics_);
  if (window.scans == 0 || period <= 0.0) return;
  const mapping::MapStatistics map_statistics = map().statistics();
  const std::size_t given = window.integrated + window.refused;
  NODELET_INFO("mapper: %.1f Hz, %.1f ms per scan; integrated %zu, refused %zu, without pose %zu, rejected %zu; "
               "%zu blocks, %.1f MB, %zu triangles, %.1f ms per mesh update",
               double(window.integrated) / period, given > 0 ? 1e3 * window.integration_seconds / double(given) : 0.0,
               window.integrated, window.refused, window.dropped_no_pose, window.rejected, map_statistics.blocks,
               double(map_statistics.memory_bytes) / (1024.0 * 1024.0), map_statistics.triangles,
               window.mesh_updates > 0 ? 1e3 * window.mesh_seconds / double(window.mesh_updates) : 0.0);
}

}  // namespace range_image_mapping

PLUGINLIB_EXPORT_CLASS(range_image_mapping::MapperNodelet, nodelet::Nodelet)
