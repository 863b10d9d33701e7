#include "range_image_mapping/ros/parameters.h"

#include <XmlRpcValue.h>
#include <ros/console.h>

#include <cmath>
#include <limits>
#include <sstream>
#include <tuple>

namespace range_image_mapping {
namespace {

const char* typeName(XmlRpc::XmlRpcValue::Type type) {
  switch (type) {
    case XmlRpc::XmlRpcValue::TypeBoolean: return "bool";
    case XmlRpc::XmlRpcValue::TypeInt: return "int";
    case XmlRpc::XmlRpcValue::TypeDouble: return "double";
    case XmlRpc::XmlRpcValue::TypeString: return "string";
    case XmlRpc::XmlRpcValue::TypeArray: return "list";
    case XmlRpc::XmlRpcValue::TypeStruct: return "dictionary";
    default: return "other";
  }
}

template <typename Number>
std::string toText(Number value) {
  std::ostringstream text;
  text << value;
  return text.str();
}

}  // namespace

void startOrRefuseLoad(const std::string& nodelet_name, const std::string& kind,
                       const std::function<void()>& start) {
  try {
    start();
  } catch (const std::exception& error) {
    // Loudly and here: nodelet's Loader logs only "Failed to initialize
    // nodelet", without the reason.
    ROS_FATAL_NAMED(nodelet_name, "%s not started: %s", kind.c_str(), error.what());
    throw;
  }
}

std::string ParameterReader::fullName(const std::string& name) const {
  return node_.resolveName(name);
}

// Each getter reads the raw XmlRpc value so a value of the wrong type is an
// error instead of ros::param::get's silent "not found".
std::string ParameterReader::getString(const std::string& name,
                                       const std::string& default_value) const {
  XmlRpc::XmlRpcValue value;
  if (!node_.getParam(name, value)) return default_value;
  if (value.getType() != XmlRpc::XmlRpcValue::TypeString)
    throw ParameterError("parameter " + fullName(name) + " must be a string, got a " +
                         typeName(value.getType()));
  return static_cast<std::string>(value);
}

std::string ParameterReader::getFrame(const std::string& name, const std::string& default_value) const {
  std::string frame = getString(name, default_value);
  if (frame.empty()) throw ParameterError("parameter " + fullName(name) + " is empty");
  return frame;
}

std::string ParameterReader::getChoice(const std::string& name, const std::string& default_value,
                                       const std::vector<std::string>& choices) const {
  const std::string value = getString(name, default_value);
  std::string listed;
  for (const std::string& choice : choices) {
    if (value == choice) return value;
    listed += (listed.empty() ? "" : ", ") + choice;
  }
  throw ParameterError("parameter " + fullName(name) + " is '" + value + "', expected one of: " +
                       listed);
}

bool ParameterReader::getBool(const std::string& name, bool default_value) const {
  XmlRpc::XmlRpcValue value;
  if (!node_.getParam(name, value)) return default_value;
  if (value.getType() != XmlRpc::XmlRpcValue::TypeBoolean)
    throw ParameterError("parameter " + fullName(name) + " must be true or false, got a " +
                         typeName(value.getType()));
  return static_cast<bool>(value);
}

int ParameterReader::getInt(const std::string& name, int default_value, int minimum,
                            int maximum) const {
  XmlRpc::XmlRpcValue value;
  int result = default_value;
  if (node_.getParam(name, value)) {
    if (value.getType() != XmlRpc::XmlRpcValue::TypeInt)
      throw ParameterError("parameter " + fullName(name) + " must be an integer, got a " +
                           typeName(value.getType()));
    result = static_cast<int>(value);
  }
  if (result < minimum || result > maximum)
    throw ParameterError("parameter " + fullName(name) + " is " + toText(result) +
                         ", expected within [" + toText(minimum) + ", " + toText(maximum) + "]");
  return result;
}

double ParameterReader::getDouble(const std::string& name, double default_value, double minimum,
                                  double maximum) const {
  XmlRpc::XmlRpcValue value;
  double result = default_value;
  if (node_.getParam(name, value)) {
    if (value.getType() == XmlRpc::XmlRpcValue::TypeInt)
      result = static_cast<int>(value);
    else if (value.getType() == XmlRpc::XmlRpcValue::TypeDouble)
      result = static_cast<double>(value);
    else
      throw ParameterError("parameter " + fullName(name) + " must be a number, got a " +
                           typeName(value.getType()));
  }
  if (!(result >= minimum && result <= maximum))
    throw ParameterError("parameter " + fullName(name) + " is " + toText(result) +
                         ", expected within [" + toText(minimum) + ", " + toText(maximum) + "]");
  return result;
}

std::pair<double, double> ParameterReader::getOrderedDoubles(const std::string& lower_name, double lower_default,
                                                             const std::string& upper_name, double upper_default,
                                                             double minimum, double maximum) const {
  const double lower = getDouble(lower_name, lower_default, minimum, maximum);
  const double upper = getDouble(upper_name, upper_default, minimum, maximum);
  if (!(upper > lower))
    throw ParameterError("parameter " + fullName(upper_name) + " (" + toText(upper) + ") must be above " +
                         fullName(lower_name) + " (" + toText(lower) + ")");
  return {lower, upper};
}

std::vector<int> ParameterReader::getIntList(const std::string& name, const std::vector<int>& default_value,
                                             int minimum, int maximum) const {
  XmlRpc::XmlRpcValue value;
  if (!node_.getParam(name, value)) return default_value;
  if (value.getType() != XmlRpc::XmlRpcValue::TypeArray)
    throw ParameterError("parameter " + fullName(name) + " must be a list of integers, got a " +
                         typeName(value.getType()));
  std::vector<int> result;
  for (int i = 0; i < value.size(); ++i) {
    if (value[i].getType() != XmlRpc::XmlRpcValue::TypeInt)
      throw ParameterError("parameter " + fullName(name) + " must be a list of integers, entry " +
                           toText(i) + " is a " + typeName(value[i].getType()));
    const int entry = static_cast<int>(value[i]);
    if (entry < minimum || entry > maximum)
      throw ParameterError("parameter " + fullName(name) + " entry " + toText(i) + " is " + toText(entry) +
                           ", expected within [" + toText(minimum) + ", " + toText(maximum) + "]");
    result.push_back(entry);
  }
  return result;
}

AdapterParameters readAdapterParameters(const ros::NodeHandle& private_node) {
  const ParameterReader reader(private_node);
  AdapterParameters parameters;
  const AdapterParameters defaults;

  parameters.input = reader.getChoice("input", "ouster_packets", {"ouster_packets", "pointcloud"}) ==
                             "pointcloud"
                         ? AdapterInput::kPointCloud
                         : AdapterInput::kOusterPackets;
  parameters.metadata_file = reader.getString("metadata_file", defaults.metadata_file);
  parameters.lidar_frame = reader.getFrame("lidar_frame", defaults.lidar_frame);
  parameters.sensor_frame = reader.getFrame("sensor_frame", defaults.sensor_frame);
  parameters.publish_static_tf = reader.getBool("publish_static_tf", defaults.publish_static_tf);
  parameters.publish_cloud = reader.getBool("publish_cloud", defaults.publish_cloud);

  parameters.ouster_return = reader.getChoice("ouster_return", "first", {"first", "second"}) == "second"
                                 ? ReturnIndex::kSecond
                                 : ReturnIndex::kFirst;
  parameters.stamp_source =
      reader.getChoice("stamp_source", "receive_time", {"receive_time", "sensor_clock"}) ==
              "sensor_clock"
          ? StampSource::kSensorClock
          : StampSource::kReceiveTime;
  parameters.flush_after_idle_s = reader.getDouble("flush_after_idle", defaults.flush_after_idle_s, 0.0, 60.0);
  parameters.packet_queue_size = reader.getInt("packet_queue_size", defaults.packet_queue_size, 1, 1 << 20);
  parameters.pending_packet_limit =
      reader.getInt("pending_packet_limit", defaults.pending_packet_limit, 0, 1 << 20);

  parameters.sensor = reader.getString("sensor", defaults.sensor);
  // A sensor given is the model; without one the clouds' own estimate.
  const std::string intrinsics = reader.getChoice("intrinsics", parameters.sensor.empty() ? "estimate" : "sensor",
                                                  {"estimate", "sensor", "synthetic", "ring", "ouster"});
  parameters.cloud_intrinsics = intrinsics == "sensor"      ? CloudIntrinsicsSource::kSensor
                                : intrinsics == "synthetic" ? CloudIntrinsicsSource::kSynthetic
                                : intrinsics == "ring"      ? CloudIntrinsicsSource::kRing
                                : intrinsics == "ouster"    ? CloudIntrinsicsSource::kOuster
                                                            : CloudIntrinsicsSource::kEstimate;
  if (!parameters.sensor.empty() && parameters.cloud_intrinsics != CloudIntrinsicsSource::kSensor)
    throw ParameterError("parameter " + private_node.resolveName("sensor") + " ('" + parameters.sensor +
                         "') gives the sensor model, but " + private_node.resolveName("intrinsics") + " is " +
                         intrinsics + ": set only one of them");
  if (parameters.input == AdapterInput::kPointCloud && parameters.cloud_intrinsics == CloudIntrinsicsSource::kSensor &&
      parameters.sensor.empty())
    throw ParameterError("parameter " + private_node.resolveName("sensor") +
                         " (a sensor file or a named model) is required with intrinsics: sensor");
  parameters.estimate_clouds = reader.getInt("estimate_clouds", defaults.estimate_clouds, 1, 100);
  parameters.rows = reader.getInt("rows", defaults.rows, 1, 4096);
  parameters.columns = reader.getInt("columns", defaults.columns, 1, 1 << 16);
  std::tie(parameters.fov_down_deg, parameters.fov_up_deg) = reader.getOrderedDoubles(
      "fov_down_deg", defaults.fov_down_deg, "fov_up_deg", defaults.fov_up_deg, -90.0, 90.0);
  if (parameters.input == AdapterInput::kPointCloud &&
      parameters.cloud_intrinsics == CloudIntrinsicsSource::kOuster && parameters.metadata_file.empty())
    throw ParameterError("parameter " + private_node.resolveName("metadata_file") +
                         " is required with intrinsics: ouster");
  parameters.organized_column_order =
      reader.getChoice("organized_columns", "destaggered", {"destaggered", "staggered"}) == "staggered"
          ? ColumnOrder::kStaggered
          : ColumnOrder::kDestaggered;
  parameters.cloud_queue_size = reader.getInt("cloud_queue_size", defaults.cloud_queue_size, 1, 1000);

  parameters.statistics_period_s =
      reader.getDouble("statistics_period", defaults.statistics_period_s, 0.1, 3600.0);
  return parameters;
}

namespace {

// The core's registration options; names without units are SI (m, rad).
registration::RegistrationOptions readRegistrationOptions(const ParameterReader& reader,
                                                          const ros::NodeHandle& private_node) {
  registration::RegistrationOptions options;
  const registration::RegistrationOptions defaults;
  options.strides = reader.getIntList("strides", defaults.strides, 1, 64);
  options.iterations = reader.getIntList("iterations", defaults.iterations, 0, 1000);
  if (options.strides.empty())
    throw ParameterError("parameter " + private_node.resolveName("strides") + " is empty");
  if (options.strides.size() != options.iterations.size())
    throw ParameterError("parameter " + private_node.resolveName("iterations") + " has " +
                         toText(options.iterations.size()) + " entries, " +
                         private_node.resolveName("strides") + " has " + toText(options.strides.size()) +
                         ": one per level");
  options.source_stride = reader.getInt("source_stride", defaults.source_stride, 1, 64);
  options.max_correspondence_distance_m = reader.getDouble(
      "max_correspondence_distance", defaults.max_correspondence_distance_m, 0.0, 100.0);
  options.gate_grows_with_stride = reader.getBool("gate_grows_with_stride", defaults.gate_grows_with_stride);
  options.min_coarse_pairs = reader.getInt("min_coarse_pairs", defaults.min_coarse_pairs, 0, 1000000);
  options.min_normal_cosine = reader.getDouble("min_normal_cosine", defaults.min_normal_cosine, -1.0, 1.0);
  options.area_weight_max_range_m =
      reader.getDouble("area_weight_max_range", defaults.area_weight_max_range_m, 0.0, 1e4);
  options.kernel.type = reader.getChoice("kernel", "pseudo_huber", {"pseudo_huber", "barron"}) == "barron"
                            ? registration::RobustKernel::Type::kBarron
                            : registration::RobustKernel::Type::kPseudoHuber;
  options.kernel.scale_m = reader.getDouble("kernel_scale", defaults.kernel.scale_m, 1e-4, 100.0);
  options.kernel.alpha = reader.getDouble("kernel_alpha", defaults.kernel.alpha, -1e6, 2.0);
  options.normals.method =
      reader.getChoice("normal_method", "cross_product", {"cross_product", "covariance"}) == "covariance"
          ? NormalMethod::kCovariance
          : NormalMethod::kCrossProduct;
  options.normals.window_radius = reader.getInt("normal_window_radius", defaults.normals.window_radius, 1, 16);
  options.normals.max_range_jump_ratio = static_cast<float>(
      reader.getDouble("max_range_jump_ratio", defaults.normals.max_range_jump_ratio, 1e-3, 10.0));
  options.convergence_rotation_rad =
      reader.getDouble("convergence_rotation", defaults.convergence_rotation_rad, 0.0, 1.0);
  options.convergence_translation_m =
      reader.getDouble("convergence_translation", defaults.convergence_translation_m, 0.0, 1.0);
  return options;
}

}  // namespace

OdometryParameters readOdometryParameters(const ros::NodeHandle& private_node) {
  const ParameterReader reader(private_node);
  OdometryParameters parameters;
  const OdometryParameters defaults;

  parameters.odom_frame = reader.getFrame("odom_frame", defaults.odom_frame);
  parameters.base_frame = reader.getFrame("base_frame", defaults.base_frame);
  if (parameters.odom_frame == parameters.base_frame)
    throw ParameterError("parameters " + private_node.resolveName("odom_frame") + " and " +
                         private_node.resolveName("base_frame") + " are both '" + parameters.odom_frame + "'");
  parameters.publish_tf = reader.getBool("publish_tf", defaults.publish_tf);
  parameters.invert_tf = reader.getBool("invert_tf", defaults.invert_tf);
  parameters.publish_deskewed_cloud = reader.getBool("publish_deskewed_cloud", defaults.publish_deskewed_cloud);
  parameters.path_length = reader.getInt("path_length", defaults.path_length, 0, 1 << 24);
  parameters.lidar_transform_timeout_s =
      reader.getDouble("lidar_transform_timeout", defaults.lidar_transform_timeout_s, 0.0, 600.0);
  parameters.queue_size = reader.getInt("queue_size", defaults.queue_size, 1, 1000);
  parameters.statistics_period_s =
      reader.getDouble("statistics_period", defaults.statistics_period_s, 0.1, 3600.0);

  registration::OdometryOptions& odometry = parameters.odometry;
  const registration::OdometryOptions odometry_defaults;
  odometry.registration = readRegistrationOptions(reader, private_node);
  odometry.deskew = reader.getBool("deskew", odometry_defaults.deskew);
  odometry.constant_velocity_prior =
      reader.getBool("constant_velocity_prior", odometry_defaults.constant_velocity_prior);
  odometry.max_condition_number =
      reader.getDouble("max_condition_number", odometry_defaults.max_condition_number, 1.0, 1e300);
  odometry.min_inliers = static_cast<std::size_t>(
      reader.getInt("min_inliers", static_cast<int>(odometry_defaults.min_inliers), 0, 1 << 30));
  odometry.model.keyframes = std::size_t(
      reader.getInt("model_keyframes", int(odometry_defaults.model.keyframes), 1, 1000));
  odometry.model.keyframe_distance_m =
      reader.getDouble("keyframe_distance", odometry_defaults.model.keyframe_distance_m, 0.0, 1000.0);
  odometry.model.keyframe_angle_rad =
      reader.getDouble("keyframe_angle_deg", odometry_defaults.model.keyframe_angle_rad * 180.0 / M_PI, 0.0, 180.0) *
      M_PI / 180.0;
  odometry.model.normal_radius_m =
      reader.getDouble("model_normal_radius", odometry_defaults.model.normal_radius_m, 0.0, 100.0);
  odometry.model.keyframe_range_share =
      reader.getDouble("keyframe_range_share", odometry_defaults.model.keyframe_range_share, 0.0, 100.0);
  odometry.model.max_keyframe_distance_m =
      reader.getDouble("max_keyframe_distance", odometry_defaults.model.max_keyframe_distance_m, 0.0, 1000.0);
  odometry.max_time_gap_s = reader.getDouble("max_time_gap", odometry_defaults.max_time_gap_s, 1e-3, 3600.0);
  odometry.moving_margin_m = reader.getDouble("moving_margin", odometry_defaults.moving_margin_m, 0.0, 100.0);
  odometry.moving_warning_share =
      reader.getDouble("moving_warning_share", odometry_defaults.moving_warning_share, 1e-3, 1.0);
  odometry.min_inlier_share = reader.getDouble("min_inlier_share", odometry_defaults.min_inlier_share, 0.0, 1.0);
  odometry.deskew_passes = reader.getInt("deskew_passes", odometry_defaults.deskew_passes, 0, 100);
  odometry.max_speed_mps = reader.getDouble("max_speed", odometry_defaults.max_speed_mps, 0.0, 1e3);
  odometry.max_angular_rate_radps =
      reader.getDouble("max_angular_rate_deg", odometry_defaults.max_angular_rate_radps * 180.0 / M_PI, 0.0, 1e5) *
      M_PI / 180.0;
  odometry.max_acceleration_mps2 =
      reader.getDouble("max_acceleration", odometry_defaults.max_acceleration_mps2, 0.0, 1e4);
  odometry.velocity_decay_time_s =
      reader.getDouble("velocity_decay_time", odometry_defaults.velocity_decay_time_s, 0.0, 3600.0);
  return parameters;
}

MapperParameters readMapperParameters(const ros::NodeHandle& private_node) {
  const ParameterReader reader(private_node);
  MapperParameters parameters;
  const MapperParameters defaults;
  // The core's own ranges (TsdfMapOptions::validate) are the one source of
  // what it accepts: its values are read with no limits but their type here.
  constexpr double kAny = std::numeric_limits<double>::max();
  constexpr int kAnyInt = std::numeric_limits<int>::max();

  mapping::TsdfMapOptions& map = parameters.map;
  map.grid.voxel_size_m = reader.getDouble("voxel_size", defaults.map.grid.voxel_size_m, -kAny, kAny);
  map.grid.block_edge = reader.getInt("block_edge", defaults.map.grid.block_edge, -kAnyInt, kAnyInt);
  map.grid.max_blocks = static_cast<std::size_t>(
      reader.getInt("max_blocks", static_cast<int>(defaults.map.grid.max_blocks), 0, kAnyInt));
  map.integrator.truncation_m = reader.getDouble("truncation", defaults.map.integrator.truncation_m, -kAny, kAny);
  map.integrator.min_range_m = reader.getDouble("min_range", defaults.map.integrator.min_range_m, -kAny, kAny);
  map.integrator.max_range_m = reader.getDouble("max_range", defaults.map.integrator.max_range_m, -kAny, kAny);
  map.integrator.point_stride =
      reader.getInt("integration_stride", defaults.map.integrator.point_stride, -kAnyInt, kAnyInt);
  map.integrator.max_weight =
      static_cast<float>(reader.getDouble("max_weight", defaults.map.integrator.max_weight, -kAny, kAny));
  map.integrator.range_weighting = reader.getBool("range_weighting", defaults.map.integrator.range_weighting);
  map.integrator.range_weighting_start_m =
      reader.getDouble("range_weighting_start", defaults.map.integrator.range_weighting_start_m, -kAny, kAny);
  map.integrator.incidence_weighting =
      reader.getBool("incidence_weighting", defaults.map.integrator.incidence_weighting);
  map.integrator.free_space_weight = static_cast<float>(
      reader.getDouble("free_space_weight", defaults.map.integrator.free_space_weight, -kAny, kAny));
  map.integrator.plane_fill_m =
      reader.getDouble("plane_fill", defaults.map.integrator.plane_fill_m, -kAny, kAny);
  map.integrator.signed_distance =
      reader.getChoice("signed_distance", "point_to_plane", {"point_to_plane", "along_ray"}) == "along_ray"
          ? mapping::SignedDistance::kAlongRay
          : mapping::SignedDistance::kPointToPlane;
  map.integrator.mesh_tolerance_voxels =
      reader.getDouble("mesh_tolerance", defaults.map.integrator.mesh_tolerance_voxels, -kAny, kAny);
  map.mesh.update_budget_s = reader.getDouble("mesh_update_budget", defaults.map.mesh.update_budget_s, -kAny, kAny);
  map.mesh.min_weight =
      static_cast<float>(reader.getDouble("mesh_min_weight", defaults.map.mesh.min_weight, -kAny, kAny));
  map.integrator.mesh_min_weight = map.mesh.min_weight;  // one threshold, see TsdfMapOptions::validate
  map.memory_radius_m = reader.getDouble("memory_radius", defaults.map.memory_radius_m, -kAny, kAny);
  map.keep_dropped_mesh = reader.getBool("keep_dropped_mesh", defaults.map.keep_dropped_mesh);
  map.max_pose_jump_m = reader.getDouble("max_pose_jump", defaults.map.max_pose_jump_m, -kAny, kAny);
  map.max_refused_jumps = reader.getInt("max_refused_jumps", defaults.map.max_refused_jumps, -kAnyInt, kAnyInt);

  parameters.color_mode = reader.getChoice("color_mode", "height", {"height", "intensity"}) == "intensity"
                              ? MeshColorMode::kIntensity
                              : MeshColorMode::kHeight;
  map.grid.store_intensity = parameters.color_mode == MeshColorMode::kIntensity;
  try {
    map.validate();
  } catch (const mapping::MappingError& error) {
    throw ParameterError("mapper parameters in " + private_node.getNamespace() + " rejected by the map: " +
                         error.what());
  }

  parameters.world_frame = reader.getFrame("world_frame", defaults.world_frame);
  parameters.pose_source = reader.getChoice("pose_source", "tf", {"tf", "odometry"}) == "odometry"
                               ? PoseSourceType::kOdometry
                               : PoseSourceType::kTf;
  parameters.deskew = reader.getBool("deskew", defaults.deskew);
  parameters.max_time_gap_s = reader.getDouble("max_time_gap", defaults.max_time_gap_s, 1e-3, 3600.0);
  if (private_node.hasParam("tf_timeout"))
    throw ParameterError("parameter " + private_node.resolveName("tf_timeout") +
                         " is now pose_timeout (it applies to both pose sources): rename it");
  parameters.pose_timeout_s = reader.getDouble("pose_timeout", defaults.pose_timeout_s, 0.0, 600.0);
  parameters.lidar_transform_timeout_s =
      reader.getDouble("lidar_transform_timeout", defaults.lidar_transform_timeout_s, 0.0, 600.0);
  parameters.queue_size = reader.getInt("queue_size", defaults.queue_size, 1, 1000);

  parameters.mesh_rate_hz = reader.getDouble("mesh_rate", defaults.mesh_rate_hz, 0.01, 100.0);
  std::tie(parameters.height_color_min_m, parameters.height_color_max_m) = reader.getOrderedDoubles(
      "height_color_min", defaults.height_color_min_m, "height_color_max", defaults.height_color_max_m, -1e4, 1e4);
  parameters.intensity_color_max =
      reader.getDouble("intensity_color_max", defaults.intensity_color_max, 1e-6, 1e9);
  parameters.marker_chunk_blocks = reader.getInt("marker_chunk_blocks", defaults.marker_chunk_blocks, 1, 64);
  parameters.display_max_height_m = reader.getDouble("display_max_height", defaults.display_max_height_m, -1e4,
                                                     std::numeric_limits<double>::infinity());
  parameters.display_full_detail_distance_m = reader.getDouble(
      "display_full_detail_distance", defaults.display_full_detail_distance_m, 0.0, 1e6);
  parameters.display_triangle_budget = static_cast<std::size_t>(reader.getInt(
      "display_triangle_budget", static_cast<int>(defaults.display_triangle_budget), 0, kAnyInt));
  parameters.mesh_defer_latency_s =
      reader.getDouble("mesh_defer_latency", defaults.mesh_defer_latency_s, 0.0, 3600.0);
  parameters.triangle_warning = static_cast<std::size_t>(
      reader.getInt("triangle_warning", static_cast<int>(defaults.triangle_warning), 0, kAnyInt));
  parameters.statistics_period_s =
      reader.getDouble("statistics_period", defaults.statistics_period_s, 0.1, 3600.0);
  return parameters;
}

}  // namespace range_image_mapping
