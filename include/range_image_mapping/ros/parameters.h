// The one place where the nodelets read and validate their ROS parameters.
// Every parameter has a default; a value of the wrong type or out of range is
// an error naming the parameter, never silently replaced by the default, and
// the nodelet refuses to load (startOrRefuseLoad).
#pragma once

#include "range_image_mapping/mapping/tsdf_map.h"
#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/registration/lidar_odometry.h"

#include <ros/node_handle.h>

#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace range_image_mapping {

class ParameterError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// A nodelet's start-up: `start` reads the parameters and builds what they
// configure (the core objects check their options too). Anything it throws
// refuses the load: logged as FATAL under the nodelet's name (`nodelet_name`,
// from getName(); `kind` says which nodelet, e.g. "Mapper") and thrown on,
// so nodelet::Loader::load fails, the manager's load service answers false
// and `nodelet load` exits, instead of a nodelet that stays loaded doing
// nothing. The message names the parameter (ParameterError).
void startOrRefuseLoad(const std::string& nodelet_name, const std::string& kind,
                       const std::function<void()>& start);

// Typed getters on one node handle (usually the nodelet's private one).
class ParameterReader {
 public:
  explicit ParameterReader(const ros::NodeHandle& node) : node_(node) {}

  std::string getString(const std::string& name, const std::string& default_value) const;
  // A tf frame name: a string that must not be empty.
  std::string getFrame(const std::string& name, const std::string& default_value) const;
  // One of choices, compared exactly.
  std::string getChoice(const std::string& name, const std::string& default_value,
                        const std::vector<std::string>& choices) const;
  bool getBool(const std::string& name, bool default_value) const;
  int getInt(const std::string& name, int default_value, int minimum, int maximum) const;
  // Accepts integers too (YAML "10" for 10.0).
  double getDouble(const std::string& name, double default_value, double minimum,
                   double maximum) const;
  // Two numbers within [minimum, maximum] that must be ordered: upper above lower.
  std::pair<double, double> getOrderedDoubles(const std::string& lower_name, double lower_default,
                                              const std::string& upper_name, double upper_default,
                                              double minimum, double maximum) const;
  // A list of integers, each within [minimum, maximum].
  std::vector<int> getIntList(const std::string& name, const std::vector<int>& default_value,
                              int minimum, int maximum) const;

 private:
  std::string fullName(const std::string& name) const;
  ros::NodeHandle node_;
};

// ------------------------------------------------------------ Adapter nodelet

enum class AdapterInput { kOusterPackets, kPointCloud };
// Where the intrinsics of a PointCloud2 input come from: estimated from the
// first clouds, a sensor file or named model (sensor), synthetic tables, the
// ring field, or Ouster metadata.
enum class CloudIntrinsicsSource { kEstimate, kSensor, kSynthetic, kRing, kOuster };
// What the header stamp of a range image from Ouster packets is.
enum class StampSource { kReceiveTime, kSensorClock };

struct AdapterParameters {
  AdapterInput input = AdapterInput::kOusterPackets;
  std::string metadata_file;  // Ouster metadata JSON; wins over the metadata topic
  std::string lidar_frame = "os_lidar";
  std::string sensor_frame = "os_sensor";
  bool publish_static_tf = false;
  bool publish_cloud = false;
  // Ouster packets.
  ReturnIndex ouster_return = ReturnIndex::kFirst;
  StampSource stamp_source = StampSource::kReceiveTime;
  double flush_after_idle_s = 0.5;  // publish the revolution in progress when packets stop
  int packet_queue_size = 2048;
  int pending_packet_limit = 4096;  // packets kept while waiting for metadata
  // PointCloud2.
  CloudIntrinsicsSource cloud_intrinsics = CloudIntrinsicsSource::kEstimate;
  std::string sensor;     // sensor file (YAML, Ouster JSON) or a named model (sensor_catalog.h)
  int estimate_clouds = 3;  // clouds the estimate is made from (intrinsics estimate)
  int rows = 64;
  int columns = 2048;
  double fov_up_deg = 3.0;  // KITTI's HDL-64E, as io::kittiHdl64Intrinsics
  double fov_down_deg = -25.0;
  // Column order of organized clouds of the model's size (the Ouster driver's are destaggered).
  ColumnOrder organized_column_order = ColumnOrder::kDestaggered;
  int cloud_queue_size = 2;
  // Logging.
  double statistics_period_s = 10.0;  // period of the dropped-data summaries
};

// Reads every Adapter parameter from the nodelet's private node handle.
// Throws ParameterError naming the first bad parameter.
AdapterParameters readAdapterParameters(const ros::NodeHandle& private_node);

// ------------------------------------------------------------ Odometry nodelet

struct OdometryParameters {
  registration::OdometryOptions odometry;  // the core's options (kernel, levels, deskew, ...)
  std::string odom_frame = "odom";
  std::string base_frame = "base_link";
  bool publish_tf = true;
  // Publish base_frame -> odom_frame instead, for robots whose wheel odometry
  // already owns odom -> base_link (REP 105: a frame has one parent).
  bool invert_tf = false;
  bool publish_deskewed_cloud = false;
  int path_length = 10000;               // poses kept in the path message; 0: no path
  double lidar_transform_timeout_s = 2.0;  // wall time to wait for base_frame -> lidar frame
  int queue_size = 8;                    // range images waiting for the odometry
  double statistics_period_s = 10.0;     // period of the log summary
};

// Reads every Odometry parameter from the nodelet's private node handle.
// Throws ParameterError naming the first bad parameter.
OdometryParameters readOdometryParameters(const ros::NodeHandle& private_node);

// ------------------------------------------------------------ Mapper nodelet

// Where the pose of each range image comes from (PoseSource, pose_source.h).
enum class PoseSourceType {
  kTf,        // world_frame -> image frame on tf at the image's stamp
  kOdometry,  // the odometry topic at the same stamp, composed with base -> lidar from tf
};
enum class MeshColorMode { kHeight, kIntensity };

struct MapperParameters {
  // The core's options: voxel_size, block_edge, max_blocks, truncation,
  // min_range, max_range, integration_stride, max_weight, memory_radius,
  // max_pose_jump (and intensity storage when color_mode is intensity).
  mapping::TsdfMapOptions map;
  std::string world_frame = "odom";
  PoseSourceType pose_source = PoseSourceType::kTf;
  // Motion compensation: with the odometry's twist (pose_source odometry), or
  // with the twist between consecutive poses (tf).
  bool deskew = true;
  double max_time_gap_s = 0.5;  // tf: poses farther apart give no twist (a gap, a restart)
  // Wall time a scan waits for its pose (tf, or the odometry message with its
  // stamp) before it is dropped, counted and warned about.
  double pose_timeout_s = 1.0;
  double lidar_transform_timeout_s = 2.0;  // odometry source: wall time to wait for base -> lidar
  // Scans waiting for their pose, and the subscribers' queues (range images,
  // odometry): past it the oldest waiting scan is dropped, counted and warned
  // about. 30 is 3 s of a 10 Hz sensor.
  int queue_size = 30;
  // Mesh output.
  double mesh_rate_hz = 1.0;
  MeshColorMode color_mode = MeshColorMode::kHeight;
  double height_color_min_m = -1.0;  // colour scale of color_mode height, world z
  double height_color_max_m = 3.0;
  double intensity_color_max = 255.0;  // intensity of the brightest colour (color_mode intensity)
  int marker_chunk_blocks = 2;  // one marker per cube of this many blocks per edge (3.2 m at 16 x 10 cm)
  // Display only (markers and surface_points): triangles with a corner above
  // this world z are left out, so rviz shows rooms without their ceilings.
  // The map and saved meshes keep everything.
  double display_max_height_m = std::numeric_limits<double>::infinity();
  // Markers only: chunks nearer the sensor than this are shown at full
  // resolution, each doubling of the distance coarsens them one level
  // (mapping::MeshLevelOfDetail); 0: full resolution until the budget.
  double display_full_detail_distance_m = 15.0;
  // Markers only: most triangles shown; everything coarsens until it fits (0: no budget).
  std::size_t display_triangle_budget = 1'000'000;
  // Mesh updates wait while the Mapper is behind: the last scan integrated
  // was older than this (scan-to-map latency), at most kMaxDeferredMeshUpdates
  // in a row. 0: never wait.
  double mesh_defer_latency_s = 0.5;
  std::size_t triangle_warning = 3'000'000;  // warn once the mesh passes this many triangles
  double statistics_period_s = 10.0;         // period of the log summary
};

// Reads every Mapper parameter from the nodelet's private node handle and
// validates the core's options (TsdfMapOptions::validate). Throws
// ParameterError naming the first bad parameter.
MapperParameters readMapperParameters(const ros::NodeHandle& private_node);

}  // namespace range_image_mapping
