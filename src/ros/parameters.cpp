#include "range_image_mapping/ros/parameters.h"

#include <XmlRpcValue.h>

#include <sstream>

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

AdapterParameters readAdapterParameters(const ros::NodeHandle& private_node) {
  const ParameterReader reader(private_node);
  AdapterParameters parameters;
  const AdapterParameters defaults;

  parameters.input = reader.getChoice("input", "ouster_packets", {"ouster_packets", "pointcloud"}) ==
                             "pointcloud"
                         ? AdapterInput::kPointCloud
                         : AdapterInput::kOusterPackets;
  parameters.metadata_file = reader.getString("metadata_file", defaults.metadata_file);
  parameters.lidar_frame = reader.getString("lidar_frame", defaults.lidar_frame);
  parameters.sensor_frame = reader.getString("sensor_frame", defaults.sensor_frame);
  if (parameters.lidar_frame.empty())
    throw ParameterError("parameter " + private_node.resolveName("lidar_frame") + " is empty");
  if (parameters.sensor_frame.empty())
    throw ParameterError("parameter " + private_node.resolveName("sensor_frame") + " is empty");
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

  const std::string intrinsics =
      reader.getChoice("intrinsics", "synthetic", {"synthetic", "ring", "ouster"});
  parameters.cloud_intrinsics = intrinsics == "ring"     ? CloudIntrinsicsSource::kRing
                                : intrinsics == "ouster" ? CloudIntrinsicsSource::kOuster
                                                         : CloudIntrinsicsSource::kSynthetic;
  parameters.rows = reader.getInt("rows", defaults.rows, 1, 4096);
  parameters.columns = reader.getInt("columns", defaults.columns, 1, 1 << 16);
  parameters.fov_up_deg = reader.getDouble("fov_up_deg", defaults.fov_up_deg, -90.0, 90.0);
  parameters.fov_down_deg = reader.getDouble("fov_down_deg", defaults.fov_down_deg, -90.0, 90.0);
  if (!(parameters.fov_up_deg > parameters.fov_down_deg))
    throw ParameterError("parameter " + private_node.resolveName("fov_up_deg") + " (" +
                         toText(parameters.fov_up_deg) + ") must be above " +
                         private_node.resolveName("fov_down_deg") + " (" +
                         toText(parameters.fov_down_deg) + ")");
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

}  // namespace range_image_mapping
