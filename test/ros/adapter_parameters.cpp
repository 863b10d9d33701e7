// readAdapterParameters: defaults, values read, bad values rejected with an
// error naming the parameter; and an Adapter nodelet with a bad parameter
// fails to load instead of running without input. Needs a master only for
// the parameter server.
#include "error_text.h"
#include "nodelet_loading.h"
#include "range_image_mapping/ros/parameters.h"
#include "rostest_main.h"

#include <gtest/gtest.h>
#include <nodelet/loader.h>
#include <ros/ros.h>

#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using test::errorOf;

TEST(AdapterParameters, DefaultsWhenNothingIsSet) {
  const AdapterParameters parameters = readAdapterParameters(ros::NodeHandle("~empty"));
  const AdapterParameters defaults;
  EXPECT_EQ(parameters.input, AdapterInput::kOusterPackets);
  EXPECT_EQ(parameters.lidar_frame, "os_lidar");
  EXPECT_EQ(parameters.sensor_frame, "os_sensor");
  EXPECT_EQ(parameters.rows, defaults.rows);
  EXPECT_EQ(parameters.columns, defaults.columns);
  EXPECT_FALSE(parameters.publish_static_tf);
  // Clouds without a model: estimated from the first clouds.
  EXPECT_EQ(parameters.cloud_intrinsics, CloudIntrinsicsSource::kEstimate);
  EXPECT_TRUE(parameters.sensor.empty());
}

// sensor (a file or a named model) is the model, and refuses to be set
// together with another intrinsics.
TEST(AdapterParameters, SensorGivesTheModelAndExcludesOtherIntrinsics) {
  ros::NodeHandle named("~named_sensor");
  named.setParam("input", "pointcloud");
  named.setParam("sensor", "VLP-32C");
  const AdapterParameters parameters = readAdapterParameters(named);
  EXPECT_EQ(parameters.cloud_intrinsics, CloudIntrinsicsSource::kSensor);
  EXPECT_EQ(parameters.sensor, "VLP-32C");

  ros::NodeHandle both("~sensor_and_ring");
  both.setParam("sensor", "VLP-16");
  both.setParam("intrinsics", "ring");
  const std::string conflict = errorOf([&] { readAdapterParameters(both); });
  EXPECT_NE(conflict.find("/sensor_and_ring/sensor ('VLP-16') gives the sensor model"), std::string::npos) << conflict;
  EXPECT_NE(conflict.find("set only one of them"), std::string::npos) << conflict;

  ros::NodeHandle without("~sensor_without_name");
  without.setParam("input", "pointcloud");
  without.setParam("intrinsics", "sensor");
  const std::string missing = errorOf([&] { readAdapterParameters(without); });
  EXPECT_NE(missing.find("sensor_without_name/sensor (a sensor file or a named model) is required"), std::string::npos)
      << missing;
}

TEST(AdapterParameters, ValuesAreReadAndCheckedByName) {
  ros::NodeHandle node("~set");
  node.setParam("input", "pointcloud");
  node.setParam("intrinsics", "synthetic");
  node.setParam("rows", 32);
  node.setParam("columns", 1024);
  node.setParam("fov_up_deg", 15);  // an integer where a double is expected is fine
  node.setParam("fov_down_deg", -15.5);
  node.setParam("publish_cloud", true);
  node.setParam("organized_columns", "staggered");
  const AdapterParameters parameters = readAdapterParameters(node);
  EXPECT_EQ(parameters.input, AdapterInput::kPointCloud);
  EXPECT_EQ(parameters.rows, 32);
  EXPECT_EQ(parameters.columns, 1024);
  EXPECT_EQ(parameters.fov_up_deg, 15.0);
  EXPECT_EQ(parameters.fov_down_deg, -15.5);
  EXPECT_TRUE(parameters.publish_cloud);
  EXPECT_EQ(parameters.organized_column_order, ColumnOrder::kStaggered);
}

TEST(AdapterParameters, BadValuesAreErrorsNamingTheParameter) {
  const auto error_for = [](const std::string& name, const auto& value) {
    ros::NodeHandle node("~bad_" + name);
    node.setParam(name, value);
    return errorOf([&] { readAdapterParameters(node); });
  };
  const std::string rows_as_text = error_for("rows", std::string("sixty-four"));
  EXPECT_NE(rows_as_text.find("/bad_rows/rows must be an integer, got a string"), std::string::npos)
      << rows_as_text;
  const std::string negative_columns = error_for("columns", -5);
  EXPECT_NE(negative_columns.find("columns is -5, expected within [1, "), std::string::npos)
      << negative_columns;
  const std::string unknown_input = error_for("input", std::string("velodyne_packets"));
  EXPECT_NE(unknown_input.find("input is 'velodyne_packets', expected one of: ouster_packets, pointcloud"),
            std::string::npos)
      << unknown_input;
  const std::string text_bool = error_for("publish_cloud", std::string("yes"));
  EXPECT_NE(text_bool.find("publish_cloud must be true or false"), std::string::npos) << text_bool;
  const std::string fov = error_for("fov_up_deg", -30.0);
  EXPECT_NE(fov.find("must be above"), std::string::npos) << fov;

  ros::NodeHandle ouster_without_file("~ouster_without_file");
  ouster_without_file.setParam("input", "pointcloud");
  ouster_without_file.setParam("intrinsics", "ouster");
  EXPECT_NE(errorOf([&] { readAdapterParameters(ouster_without_file); }).find("metadata_file"),
            std::string::npos);
}

// The nodelet refuses to start, saying which parameter; a metadata_file
// that gives no sensor model for point clouds is refused too.
TEST(AdapterParameters, NodeletWithABadParameterFailsToLoad) {
  const std::string adapter = "range_image_mapping/Adapter";
  nodelet::Loader loader(false);
  test::expectRefused(loader, adapter, "/bad_adapter", "input", std::string("velodyne_packets"),
                      "Adapter not started: parameter /bad_adapter/input is 'velodyne_packets'");
  ros::NodeHandle missing_file("/missing_metadata_adapter");
  missing_file.setParam("input", "pointcloud");
  missing_file.setParam("intrinsics", "ouster");
  test::expectRefused(loader, adapter, "/missing_metadata_adapter", "metadata_file",
                      std::string("/nonexistent/metadata.json"),
                      "/missing_metadata_adapter/metadata_file ('/nonexistent/metadata.json') gives no sensor model");
  // An unknown sensor name: refused, listing the names it knows.
  ros::NodeHandle unknown_sensor("/unknown_sensor_adapter");
  unknown_sensor.setParam("input", "pointcloud");
  test::expectRefused(loader, adapter, "/unknown_sensor_adapter", "sensor", std::string("VLP-17"),
                      "/unknown_sensor_adapter/sensor ('VLP-17') gives no sensor model: VLP-17: is neither a sensor "
                      "file (no such file) nor a named sensor model (known: VLP-16, VLP-32C");
  ros::NodeHandle("/good_adapter").setParam("input", "pointcloud");
  test::expectLoaded(loader, adapter, "/good_adapter");
  loader.clear();
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  return range_image_mapping::test::runRostestNode(argc, argv, "adapter_parameters");
}
