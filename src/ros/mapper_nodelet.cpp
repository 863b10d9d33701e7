// Mapper: range images in (the Adapter's shared pointers, same manager), each
// with its pose from tf or from the Odometry nodelet; a TSDF map (paper
// section 4.2) out as rviz markers of the mesh, the mesh vertices as a cloud,
// and a PLY on request.
//
// Every callback (images, odometry, services, timers, subscriber connections)
// runs on the nodelet's single-threaded queue (getNodeHandle), so the members
// need no locks. Nothing thrown by bad input leaves a callback: it is counted
// and logged (throttled). Integration happens in the scan callback, meshing
// only in the mesh timer, so a slow mesh never delays a scan by more than one
// timer callback.
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/SaveMesh.h"
#include "range_image_mapping/mapping/tsdf_map.h"
#include "range_image_mapping/ros/parameters.h"
#include "range_image_mapping/ros/range_image_conversions.h"
#include "range_image_mapping/ros/statistics_window.h"
#include "range_image_mapping/ros/steady_throttle.h"
#include "range_image_mapping/ros/wall_clock_diagnostics.h"
#include "range_image_mapping/scan_motion.h"

#include <diagnostic_updater/diagnostic_updater.h>
#include <message_filters/subscriber.h>
#include <message_filters/time_synchronizer.h>
#include <nav_msgs/Odometry.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <std_srvs/Empty.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>
#include <visualization_msgs/MarkerArray.h>

#include <boost/make_shared.hpp>

#include <Eigen/Geometry>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <unordered_set>
#include <vector>

namespace range_image_mapping {
namespace {

using mapping::BlockKey;
using mapping::BlockKeyHash;
using ChunkKey = Eigen::Vector3i;  // a cube of marker_chunk_blocks^3 blocks
using ChunkSet = std::unordered_set<ChunkKey, BlockKeyHash>;

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

int floorDivide(int value, int divisor) {
  return value >= 0 ? value / divisor : -((-value + divisor - 1) / divisor);
}

ChunkKey chunkOf(const BlockKey& block, int chunk_blocks) {
  return {floorDivide(block.x(), chunk_blocks), floorDivide(block.y(), chunk_blocks),
          floorDivide(block.z(), chunk_blocks)};
}

// Marker id of a chunk, so a chunk's update replaces its marker: x and y in
// 12 bits each, z in 8 (two's complement, wrapped). Two chunks share an id
// only 4096 chunks apart in x or y or 256 in z (chunks of 4 blocks of 8
// voxels of 10 cm: 13 km and 820 m), which a bounded map never holds at once.
int32_t markerId(const ChunkKey& key) {
  const uint32_t x = uint32_t(key.x()) & 0xfffu, y = uint32_t(key.y()) & 0xfffu, z = uint32_t(key.z()) & 0xffu;
  return int32_t((z << 24) | (y << 12) | x);
}

// A hue ramp from blue (0) through green to red (1).
std_msgs::ColorRGBA rampColor(float t) {
  t = std::clamp(t, 0.0f, 1.0f);
  const float hue = (1.0f - t) * 240.0f / 60.0f;  // sector of the HSV hexagon, 4 = blue, 0 = red
  const float x = 1.0f - std::abs(std::fmod(hue, 2.0f) - 1.0f);
  std_msgs::ColorRGBA color;
  color.a = 1.0f;
  if (hue < 1.0f) color.r = 1.0f, color.g = x;
  else if (hue < 2.0f) color.r = x, color.g = 1.0f;
  else if (hue < 3.0f) color.g = 1.0f, color.b = x;
  else color.g = x, color.b = 1.0f;
  return color;
}

class MeshColoring {
 public:
  explicit MeshColoring(const MapperParameters& parameters) : parameters_(parameters) {}

  // rviz draws vertex-coloured triangle lists unlit, so a flat colour per
  // height would hide every edge: the colour is shaded here with the SDF
  // normal (half-Lambert, one light from above, so no face is black).
  std_msgs::ColorRGBA color(const mapping::MeshChunk& chunk, int vertex) const {
    std_msgs::ColorRGBA color;
    if (parameters_.color_mode == MeshColorMode::kIntensity && !chunk.intensities.empty()) {
      const float grey = std::clamp(chunk.intensities[vertex] / float(parameters_.intensity_color_max), 0.0f, 1.0f);
      color.r = color.g = color.b = 0.15f + 0.85f * grey;
      color.a = 1.0f;
    } else {
      const float z = chunk.vertices[vertex].z();
      color = rampColor(float((z - parameters_.height_color_min_m) /
                              (parameters_.height_color_max_m - parameters_.height_color_min_m)));
    }
    const Eigen::Vector3f light = Eigen::Vector3f(0.35f, 0.25f, 0.9f).normalized();
    const float lambert = vertex < int(chunk.normals.size()) ? chunk.normals[vertex].dot(light) : 1.0f;
    const float shade = 0.3f + 0.7f * (0.5f + 0.5f * lambert);
    color.r *= shade;
    color.g *= shade;
    color.b *= shade;
    return color;
  }

 private:
  const MapperParameters& parameters_;
};

// Mesh vertices at or below max_height as an unorganized x y z (and intensity) cloud.
void meshVerticesToPointCloud2(const std::vector<const mapping::MeshChunk*>& chunks, bool with_intensity,
                               double max_height, const std_msgs::Header& header, sensor_msgs::PointCloud2& cloud) {
  std::size_t count = 0;
  for (const mapping::MeshChunk* chunk : chunks)
    for (const Eigen::Vector3f& vertex : chunk->vertices) count += vertex.z() <= max_height;
  cloud.header = header;
  sensor_msgs::PointCloud2Modifier modifier(cloud);
  if (with_intensity)
    modifier.setPointCloud2Fields(4, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1,
                                  sensor_msgs::PointField::FLOAT32, "z", 1, sensor_msgs::PointField::FLOAT32,
                                  "intensity", 1, sensor_msgs::PointField::FLOAT32);
  else
    modifier.setPointCloud2FieldsByString(1, "xyz");
  modifier.resize(count);
  cloud.height = 1;
  cloud.width = static_cast<uint32_t>(count);
  cloud.is_dense = true;
  sensor_msgs::PointCloud2Iterator<float> x(cloud, "x"), y(cloud, "y"), z(cloud, "z");
  std::optional<sensor_msgs::PointCloud2Iterator<float>> intensity;
  if (with_intensity) intensity.emplace(cloud, "intensity");
  for (const mapping::MeshChunk* chunk : chunks) {
    for (std::size_t i = 0; i < chunk->vertices.size(); ++i) {
      if (!(chunk->vertices[i].z() <= max_height)) continue;
      *x = chunk->vertices[i].x();
      *y = chunk->vertices[i].y();
      *z = chunk->vertices[i].z();
      ++x, ++y, ++z;
      if (intensity) {
        **intensity = i < chunk->intensities.size() ? chunk->intensities[i] : 0.0f;
        ++*intensity;
      }
    }
  }
}

// Refuses what TsdfMap::saveMesh could only fail on later, with a message
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

// MarkerArray messages beyond this many triangles are split, so rviz and the
// transport never see one huge message on a full re-send.
constexpr std::size_t kTrianglesPerMessage = 500'000;

}  // namespace

class MapperNodelet : public nodelet::Nodelet {
 public:
  void onInit() override;

 private:
  using ImageConstPtr = LidarRangeImage::ConstPtr;
  using Synchronizer = message_filters::TimeSynchronizer<LidarRangeImage, nav_msgs::Odometry>;

  // Pose sources.
  void onRangeImageTf(const ImageConstPtr& message);
  void processPendingScans();
  void onRangeImageWithOdometry(const ImageConstPtr& message, const nav_msgs::Odometry::ConstPtr& odometry);
  void onUnmatchedImage(const ImageConstPtr& message);
  // T_base_lidar once tf has it, identity after lidar_transform_timeout.
  const Eigen::Isometry3d* baseFromLidar(const std::string& base_frame, const std::string& lidar_frame);

  void integrate(const LidarRangeImage& message, const Eigen::Isometry3d& world_from_lidar);
  void dropScan(const LidarRangeImage& message, const std::string& reason);

  // Mesh output.
  void onMeshTimer(const ros::SteadyTimerEvent&);
  void updateMesh();  // the one caller of TsdfMap::updateMesh: every change lands in dirty_chunks_
  void publishMeshChanges();
  void publishFullMesh();
  void appendChunkMarker(const ChunkKey& key, visualization_msgs::MarkerArray& markers, std::size_t& triangles);
  void publishMarkers(visualization_msgs::MarkerArray& markers, std::size_t& triangles);
  void publishSurfacePoints();
  visualization_msgs::Marker markerHeader(const ChunkKey& key) const;

  bool onSaveMesh(SaveMesh::Request& request, SaveMesh::Response& response);
  bool onReset(std_srvs::Empty::Request&, std_srvs::Empty::Response&);
  bool onRepublishMesh(std_srvs::Empty::Request&, std_srvs::Empty::Response&);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);
  void onStatisticsTimer(const ros::SteadyTimerEvent&);

  MapperParameters parameters_;
  std::unique_ptr<mapping::TsdfMap> map_;
  std::unique_ptr<MeshColoring> coloring_;
  LidarModelCache models_;

  ros::Subscriber range_image_subscriber_;  // pose_source tf
  std::unique_ptr<message_filters::Subscriber<LidarRangeImage>> synchronized_image_subscriber_;
  std::unique_ptr<message_filters::Subscriber<nav_msgs::Odometry>> odometry_subscriber_;
  std::unique_ptr<Synchronizer> synchronizer_;
  ros::Publisher mesh_publisher_, surface_points_publisher_;
  ros::ServiceServer save_mesh_service_, reset_service_, republish_mesh_service_;
  ros::SteadyTimer mesh_timer_, pending_timer_, statistics_timer_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::unique_ptr<WallClockDiagnostics> diagnostics_;

  // pose_source tf: scans waiting for world_frame -> lidar at their stamp.
  struct PendingScan {
    ImageConstPtr message;
    ros::SteadyTime arrived;
  };
  std::deque<PendingScan> pending_scans_;

  // pose_source odometry: base -> lidar, looked up once per frame pair.
  std::string base_frame_, lidar_frame_;
  std::optional<Eigen::Isometry3d> base_from_lidar_;
  ros::SteadyTime lidar_transform_wait_started_;

  // The previous pose, for the twist over the sweep (deskew); its scan time on
  // the sensor's clock (0 without column timestamps).
  std::optional<Eigen::Isometry3d> last_pose_;
  ros::Time last_pose_stamp_;
  uint64_t last_sensor_time_ns_ = 0;

  // Marker chunks changed since their last publication, and those rviz holds.
  ChunkSet dirty_chunks_, published_chunks_;
  bool full_resend_ = true;

  MapperStatistics statistics_;
  StatisticsWindow<MapperStatistics> log_window_, diagnostics_window_;
  std::string last_warning_;
  SteadyThrottle warning_log_, drop_log_, error_log_, triangle_log_;
};

void MapperNodelet::onInit() {
  ros::NodeHandle& node = getNodeHandle();
  ros::NodeHandle& private_node = getPrivateNodeHandle();
  try {
    parameters_ = readMapperParameters(private_node);
    map_ = std::make_unique<mapping::TsdfMap>(parameters_.map);
  } catch (const std::exception& error) {
    // Loudly: the manager logs the failed load and `nodelet load` exits, so a
    // launch file never runs a mapper that silently maps nothing.
    NODELET_FATAL("Mapper not started: %s", error.what());
    throw;
  }
  coloring_ = std::make_unique<MeshColoring>(parameters_);
  tf_buffer_ = std::make_unique<tf2_ros::Buffer>(ros::Duration(30.0));
  tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_);

  // A late subscriber (rviz started after the mapper) gets everything at the
  // next mesh update; the others see the chunks again, which replace themselves.
  // The queue holds a full re-send split into messages (kTrianglesPerMessage).
  mesh_publisher_ = node.advertise<visualization_msgs::MarkerArray>(
      "mesh", 16, [this](const ros::SingleSubscriberPublisher&) { full_resend_ = true; });
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

  std::string pose_topic;
  if (parameters_.pose_source == PoseSource::kTf) {
    range_image_subscriber_ =
        node.subscribe("range_image", parameters_.queue_size, &MapperNodelet::onRangeImageTf, this);
    // Scans waiting for tf are retried at this period, not only when the next scan arrives.
    pending_timer_ = node.createSteadyTimer(ros::WallDuration(0.02),
                                            [this](const ros::SteadyTimerEvent&) { processPendingScans(); });
    pose_topic = "tf " + parameters_.world_frame + " -> image frame";
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
    pose_topic = odometry_subscriber_->getTopic() + " (same stamp) and tf base -> lidar";
  }
  const mapping::TsdfMapOptions& map = parameters_.map;
  NODELET_INFO("Mapper: range images from %s, poses from %s, mesh on %s in %s; voxel %.3f m, blocks of %d^3, "
               "truncation %.3f m, range [%.1f, %.1f] m, %s",
               parameters_.pose_source == PoseSource::kTf ? range_image_subscriber_.getTopic().c_str()
                                                          : synchronized_image_subscriber_->getTopic().c_str(),
               pose_topic.c_str(), mesh_publisher_.getTopic().c_str(), parameters_.world_frame.c_str(),
               map.grid.voxel_size_m, map.grid.block_edge, map.integrator.truncationFor(map.grid),
               map.integrator.min_range_m, map.integrator.max_range_m,
               parameters_.deskew ? "deskewed with the twist between poses" : "no deskew");
}

// ------------------------------------------------------------ pose sources

void MapperNodelet::onRangeImageTf(const ImageConstPtr& message) {
  ++statistics_.scans;
  if (int(pending_scans_.size()) >= parameters_.queue_size) {
    dropScan(*pending_scans_.front().message, "the queue of scans waiting for tf is full");
    pending_scans_.pop_front();
  }
  pending_scans_.push_back({message, ros::SteadyTime::now()});
  processPendingScans();
}

// In arrival order: a scan waits until tf has world_frame -> its frame at its
// stamp (the odometry publishes it after processing the same scan), at most
// tf_timeout of wall time.
void MapperNodelet::processPendingScans() {
  while (!pending_scans_.empty()) {
    const PendingScan& scan = pending_scans_.front();
    const LidarRangeImage& message = *scan.message;
    std::string error;
    if (tf_buffer_->canTransform(parameters_.world_frame, message.header.frame_id, message.header.stamp, &error)) {
      try {
        const Eigen::Isometry3d world_from_lidar = tf2::transformToEigen(
            tf_buffer_->lookupTransform(parameters_.world_frame, message.header.frame_id, message.header.stamp));
        const ImageConstPtr keep = scan.message;
        pending_scans_.pop_front();
        integrate(*keep, world_from_lidar);
      } catch (const std::exception& lookup_error) {
        dropScan(message, std::string("tf lookup failed: ") + lookup_error.what());
        pending_scans_.pop_front();
      }
      continue;
    }
    if ((ros::SteadyTime::now() - scan.arrived).toSec() < parameters_.tf_timeout_s) return;
    dropScan(message, "no transform " + parameters_.world_frame + " -> " + message.header.frame_id + " within " +
                          std::to_string(parameters_.tf_timeout_s) + " s: " + error);
    pending_scans_.pop_front();
  }
}

void MapperNodelet::onRangeImageWithOdometry(const ImageConstPtr& message,
                                             const nav_msgs::Odometry::ConstPtr& odometry) {
  ++statistics_.scans;
  try {
    if (odometry->header.frame_id != parameters_.world_frame) {
      dropScan(*message, "the odometry is in frame '" + odometry->header.frame_id + "', world_frame is '" +
                             parameters_.world_frame + "'");
      return;
    }
    const Eigen::Isometry3d* base_from_lidar = baseFromLidar(odometry->child_frame_id, message->header.frame_id);
    if (!base_from_lidar) {
      dropScan(*message, "waiting for tf " + odometry->child_frame_id + " -> " + message->header.frame_id);
      return;
    }
    Eigen::Isometry3d world_from_base;
    tf2::fromMsg(odometry->pose.pose, world_from_base);
    integrate(*message, world_from_base * *base_from_lidar);
  } catch (const std::exception& error) {
    ++statistics_.rejected;
    if (error_log_.allow(parameters_.statistics_period_s))
      NODELET_ERROR("range image stamped %.3f failed: %s", message->header.stamp.toSec(), error.what());
  }
}

void MapperNodelet::onUnmatchedImage(const ImageConstPtr& message) {
  if (!message) return;  // an odometry message without its image
  ++statistics_.scans;
  dropScan(*message, "no odometry with the same stamp");
}

// The same rule as the Odometry nodelet: the static mount from tf, or the
// identity (the base is the lidar) when tf has none after the timeout, so
// both agree on what the odometry's pose means.
const Eigen::Isometry3d* MapperNodelet::baseFromLidar(const std::string& base_frame, const std::string& lidar_frame) {
  if (base_frame != base_frame_ || lidar_frame != lidar_frame_) {
    base_frame_ = base_frame;
    lidar_frame_ = lidar_frame;
    base_from_lidar_.reset();
    lidar_transform_wait_started_ = ros::SteadyTime::now();
    if (lidar_frame.empty() || lidar_frame == base_frame) base_from_lidar_ = Eigen::Isometry3d::Identity();
  }
  if (base_from_lidar_) return &*base_from_lidar_;
  std::string error;
  if (tf_buffer_->canTransform(base_frame, lidar_frame, ros::Time(0), &error)) {
    base_from_lidar_ = tf2::transformToEigen(tf_buffer_->lookupTransform(base_frame, lidar_frame, ros::Time(0)));
    const Eigen::Vector3d t = base_from_lidar_->translation();
    NODELET_INFO("%s -> %s from tf: translation (%.3f, %.3f, %.3f) m", base_frame.c_str(), lidar_frame.c_str(),
                 t.x(), t.y(), t.z());
  } else if ((ros::SteadyTime::now() - lidar_transform_wait_started_).toSec() >=
             parameters_.lidar_transform_timeout_s) {
    base_from_lidar_ = Eigen::Isometry3d::Identity();
    NODELET_WARN("no transform %s -> %s after %.1f s (%s): using the identity, so %s is the lidar",
                 base_frame.c_str(), lidar_frame.c_str(), parameters_.lidar_transform_timeout_s, error.c_str(),
                 base_frame.c_str());
  } else {
    return nullptr;
  }
  return &*base_from_lidar_;
}

void MapperNodelet::dropScan(const LidarRangeImage& message, const std::string& reason) {
  ++statistics_.dropped_no_pose;
  last_warning_ = reason;
  if (drop_log_.allow(1.0))
    NODELET_WARN("scan %u stamped %.3f not mapped: %s (%zu dropped so far)", message.frame_id,
                 message.header.stamp.toSec(), reason.c_str(), statistics_.dropped_no_pose);
}

// ------------------------------------------------------------ integration

void MapperNodelet::integrate(const LidarRangeImage& message, const Eigen::Isometry3d& world_from_lidar) {
  RangeImage image;
  try {
    image = fromMessage(message, models_);
  } catch (const std::exception& error) {
    ++statistics_.rejected;
    if (error_log_.allow(parameters_.statistics_period_s))
      NODELET_ERROR("range image stamped %.3f dropped: %s", message.header.stamp.toSec(), error.what());
    return;
  }
  // Column times are on the sensor's clock and the header stamp may be the
  // receive time: a zero stamp makes the core take the first valid column's
  // time as the scan time, so the per-column motion is measured from it.
  uint64_t sensor_time_ns = 0;
  if (std::any_of(image.column_timestamp_ns.begin(), image.column_timestamp_ns.end(),
                  [](uint64_t t) { return t != 0; })) {
    image.stamp_ns = 0;
    sensor_time_ns = scanTime(image);
  }

  mapping::ScanPose pose;
  pose.world_from_lidar = world_from_lidar;
  // The sweep's motion, assumed constant: the twist since the previous pose,
  // over the time between the scans on the sensor's clock when both have
  // one (receive stamps jitter with the load), else between header stamps.
  if (parameters_.deskew && last_pose_ && message.header.stamp > last_pose_stamp_) {
    double dt_s = (message.header.stamp - last_pose_stamp_).toSec();
    if (sensor_time_ns > last_sensor_time_ns_ && last_sensor_time_ns_ != 0)
      dt_s = double(sensor_time_ns - last_sensor_time_ns_) * 1e-9;
    if (dt_s <= parameters_.max_time_gap_s) pose.twist = twistBetween(*last_pose_, world_from_lidar, dt_s);
  }
  if (world_from_lidar.matrix().allFinite()) {
    last_pose_ = world_from_lidar;
    last_pose_stamp_ = message.header.stamp;
    last_sensor_time_ns_ = sensor_time_ns;
  }

  const auto start = std::chrono::steady_clock::now();
  const mapping::MapUpdate update = map_->integrate(image, pose);
  statistics_.integration_seconds += secondsSince(start);
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
  const mapping::MeshUpdate update = map_->updateMesh();
  statistics_.mesh_seconds += secondsSince(start);
  ++statistics_.mesh_updates;
  for (const BlockKey& key : update.changed) dirty_chunks_.insert(chunkOf(key, parameters_.marker_chunk_blocks));
  for (const BlockKey& key : update.removed) dirty_chunks_.insert(chunkOf(key, parameters_.marker_chunk_blocks));
}

void MapperNodelet::onMeshTimer(const ros::SteadyTimerEvent&) {
  try {
    updateMesh();
    const std::size_t triangles = map_->mesh().triangleCount();
    if (triangles > parameters_.triangle_warning && triangle_log_.allow(60.0))
      NODELET_WARN("the mesh has %zu triangles (more than triangle_warning %zu): rviz slows down; a larger "
                   "voxel_size or a memory_radius keeps it smaller",
                   triangles, parameters_.triangle_warning);
    if (mesh_publisher_.getNumSubscribers() == 0)
      full_resend_ = true;  // nobody holds the mesh: the next subscriber needs all of it
    else if (full_resend_)
      publishFullMesh();
    else
      publishMeshChanges();
    dirty_chunks_.clear();
    if (surface_points_publisher_.getNumSubscribers() > 0) publishSurfacePoints();
  } catch (const std::exception& error) {
    if (error_log_.allow(parameters_.statistics_period_s)) NODELET_ERROR("mesh update failed: %s", error.what());
  }
}

visualization_msgs::Marker MapperNodelet::markerHeader(const ChunkKey& key) const {
  visualization_msgs::Marker marker;
  marker.header.frame_id = parameters_.world_frame;
  marker.ns = "mesh";
  marker.id = markerId(key);
  return marker;
}

// The chunk's triangles as one marker (ADD), or a DELETE when it lost them
// and rviz holds it; nothing for a chunk that is empty and never was sent.
void MapperNodelet::appendChunkMarker(const ChunkKey& key, visualization_msgs::MarkerArray& markers,
                                      std::size_t& triangles) {
  const int edge = parameters_.marker_chunk_blocks;
  std::vector<const mapping::MeshChunk*> blocks;
  std::size_t corners = 0;
  for (int k = 0; k < edge; ++k)
    for (int j = 0; j < edge; ++j)
      for (int i = 0; i < edge; ++i)
        if (const mapping::MeshChunk* chunk = map_->mesh().chunk(key * edge + BlockKey(i, j, k))) {
          blocks.push_back(chunk);
          corners += 3 * chunk->triangles.size();
        }
  // A triangle list repeats each vertex for every triangle using it.
  visualization_msgs::Marker marker = markerHeader(key);
  marker.points.reserve(corners);
  marker.colors.reserve(corners);
  const float max_height = float(parameters_.display_max_height_m);
  for (const mapping::MeshChunk* chunk : blocks)
    for (const Eigen::Vector3i& triangle : chunk->triangles) {
      if (!(chunk->vertices[triangle[0]].z() <= max_height && chunk->vertices[triangle[1]].z() <= max_height &&
            chunk->vertices[triangle[2]].z() <= max_height))
        continue;
      for (int corner = 0; corner < 3; ++corner) {
        const Eigen::Vector3f& vertex = chunk->vertices[triangle[corner]];
        geometry_msgs::Point point;
        point.x = vertex.x();
        point.y = vertex.y();
        point.z = vertex.z();
        marker.points.push_back(point);
        marker.colors.push_back(coloring_->color(*chunk, triangle[corner]));
      }
    }
  if (marker.points.empty()) {
    if (published_chunks_.erase(key) == 0) return;
    marker.action = visualization_msgs::Marker::DELETE;
  } else {
    marker.type = visualization_msgs::Marker::TRIANGLE_LIST;
    marker.action = visualization_msgs::Marker::ADD;
    marker.pose.orientation.w = 1.0;
    marker.scale.x = marker.scale.y = marker.scale.z = 1.0;
    marker.color.a = 1.0f;  // rviz takes the alpha of vertex-coloured triangles from here
    triangles += marker.points.size() / 3;
    published_chunks_.insert(key);
  }
  markers.markers.push_back(std::move(marker));
}

void MapperNodelet::publishMarkers(visualization_msgs::MarkerArray& markers, std::size_t& triangles) {
  if (markers.markers.empty()) return;
  const auto message = boost::make_shared<visualization_msgs::MarkerArray>();
  message->markers.swap(markers.markers);
  mesh_publisher_.publish(boost::shared_ptr<const visualization_msgs::MarkerArray>(message));
  triangles = 0;
}

void MapperNodelet::publishMeshChanges() {
  visualization_msgs::MarkerArray markers;
  std::size_t triangles = 0;
  for (const ChunkKey& key : dirty_chunks_) {
    appendChunkMarker(key, markers, triangles);
    if (triangles >= kTrianglesPerMessage) publishMarkers(markers, triangles);
  }
  publishMarkers(markers, triangles);
}

// DELETEALL first, so whatever a subscriber held (before a reset, from an
// earlier run) goes, then every chunk that has triangles.
void MapperNodelet::publishFullMesh() {
  full_resend_ = false;
  published_chunks_.clear();
  visualization_msgs::MarkerArray markers;
  visualization_msgs::Marker clear_all;
  clear_all.header.frame_id = parameters_.world_frame;
  clear_all.ns = "mesh";
  clear_all.action = visualization_msgs::Marker::DELETEALL;
  markers.markers.push_back(clear_all);
  ChunkSet chunks;
  for (const mapping::MeshChunk* chunk : map_->mesh().chunks())
    if (!chunk->triangles.empty()) chunks.insert(chunkOf(chunk->key, parameters_.marker_chunk_blocks));
  std::size_t triangles = 0;
  for (const ChunkKey& key : chunks) {
    appendChunkMarker(key, markers, triangles);
    if (triangles >= kTrianglesPerMessage) publishMarkers(markers, triangles);
  }
  publishMarkers(markers, triangles);
}

void MapperNodelet::publishSurfacePoints() {
  const auto cloud = boost::make_shared<sensor_msgs::PointCloud2>();
  std_msgs::Header header;
  header.frame_id = parameters_.world_frame;
  header.stamp = last_pose_stamp_;
  meshVerticesToPointCloud2(map_->mesh().chunks(), parameters_.map.grid.store_intensity,
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
    updateMesh();  // here rather than inside saveMesh, so the changed chunks still reach rviz
    const std::size_t triangles = map_->mesh().triangleCount();
    if (triangles == 0) {
      response.message = "mesh not saved: the map has no surface yet (" + std::to_string(statistics_.integrated) +
                         " scans integrated)";
      return true;
    }
    map_->saveMesh(request.path);
    response.success = true;
    response.message = "saved " + std::to_string(triangles) + " triangles from " +
                       std::to_string(map_->statistics().scans_integrated) + " scans to " + request.path;
    NODELET_INFO("%s", response.message.c_str());
  } catch (const std::exception& error) {
    response.message = "mesh not saved to " + request.path + ": " + error.what();
    NODELET_ERROR("%s", response.message.c_str());
  }
  return true;
}

bool MapperNodelet::onReset(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
  map_->reset();
  pending_scans_.clear();
  last_pose_.reset();
  dirty_chunks_.clear();
  // Subscribers drop the old mesh now; the next mesh update sends only new chunks.
  published_chunks_.clear();
  if (mesh_publisher_.getNumSubscribers() > 0) {
    const auto message = boost::make_shared<visualization_msgs::MarkerArray>();
    visualization_msgs::Marker clear_all;
    clear_all.header.frame_id = parameters_.world_frame;
    clear_all.ns = "mesh";
    clear_all.action = visualization_msgs::Marker::DELETEALL;
    message->markers.push_back(clear_all);
    mesh_publisher_.publish(boost::shared_ptr<const visualization_msgs::MarkerArray>(message));
  }
  NODELET_INFO("map reset: empty, the next scan starts a new map");
  return true;
}

bool MapperNodelet::onRepublishMesh(std_srvs::Empty::Request&, std_srvs::Empty::Response&) {
  full_resend_ = true;  // at the next mesh update
  return true;
}

// ------------------------------------------------------------ statistics

void MapperNodelet::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  const auto [window, period] = diagnostics_window_.advance(statistics_);
  const mapping::MapStatistics map = map_->statistics();
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
  status.add("total scans integrated", map.scans_integrated);
  status.add("total scans refused", map.scans_refused);
  status.add("blocks", map.blocks);
  status.add("memory (MB)", double(map.memory_bytes) / (1024.0 * 1024.0));
  status.add("triangles", map.triangles);
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
  const mapping::MapStatistics map = map_->statistics();
  const std::size_t given = window.integrated + window.refused;
  NODELET_INFO("mapper: %.1f Hz, %.1f ms per scan; integrated %zu, refused %zu, without pose %zu, rejected %zu; "
               "%zu blocks, %.1f MB, %zu triangles, %.1f ms per mesh update",
               double(window.integrated) / period, given > 0 ? 1e3 * window.integration_seconds / double(given) : 0.0,
               window.integrated, window.refused, window.dropped_no_pose, window.rejected, map.blocks,
               double(map.memory_bytes) / (1024.0 * 1024.0), map.triangles,
               window.mesh_updates > 0 ? 1e3 * window.mesh_seconds / double(window.mesh_updates) : 0.0);
}

}  // namespace range_image_mapping

PLUGINLIB_EXPORT_CLASS(range_image_mapping::MapperNodelet, nodelet::Nodelet)
