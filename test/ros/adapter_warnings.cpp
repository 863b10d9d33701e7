// The Adapter says when its settings contradict the clouds, once, in the log
// and in /diagnostics: clouds without a model get one estimated from the first
// clouds (and logged with its quality); a frame other than sensor_frame, clouds
// missing from the stream (gaps in the stamps), a model that explains too few
// points, and organized clouds whose column order is not organized_columns
// each get their warning naming the parameter; NaN no-return points are not
// counted as drops; a ring field with more rings than the model's rows is
// warned. Adapters are loaded in this process (as a manager would).
#include "range_image_mapping/LidarRangeImage.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/ros/bag_writer.h"
#include "range_image_mapping/ros/range_image_conversions.h"
#include "range_image_mapping/sensor_catalog.h"
#include "range_image_mapping/simulation/sensor_presets.h"
#include "rostest_main.h"
#include "spin_until.h"

#include <diagnostic_msgs/DiagnosticArray.h>
#include <gtest/gtest.h>
#include <nodelet/loader.h>
#include <ros/console.h>
#include <ros/ros.h>
#include <sensor_msgs/point_cloud2_iterator.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <random>

namespace range_image_mapping {
namespace {

// Every INFO and WARN line logged in this process (the Adapters' too).
struct LogLines : ros::console::LogAppender {
  void log(ros::console::Level level, const char* text, const char*, const char*, int) override {
    std::lock_guard<std::mutex> lock(mutex);
    if (level == ros::console::levels::Warn) warnings.push_back(text);
    if (level == ros::console::levels::Info) infos.push_back(text);
  }
  std::vector<std::string> matching(const std::vector<std::string>& lines, const std::string& part) {
    std::lock_guard<std::mutex> lock(mutex);
    std::vector<std::string> found;
    for (const std::string& line : lines)
      if (line.find(part) != std::string::npos) found.push_back(line);
    return found;
  }
  std::mutex mutex;
  std::vector<std::string> warnings, infos;
};

// Every pixel of a model unprojected at a random range: a plain cloud of that sensor.
std::vector<Eigen::Vector3f> everyPixel(const LidarModel& model, unsigned seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> range(2.0f, 40.0f);
  std::vector<Eigen::Vector3f> points;
  for (int v = 0; v < model.rows(); ++v)
    for (int u = 0; u < model.columns(); ++u) points.push_back(model.unproject(u, v, range(random)));
  return points;
}

sensor_msgs::PointCloud2 plainCloud(const LidarModel& model, unsigned seed, double stamp_s, const std::string& frame) {
  std_msgs::Header header;
  header.stamp = ros::Time(stamp_s);
  header.frame_id = frame;
  sensor_msgs::PointCloud2 cloud;
  pointsToPointCloud2(everyPixel(model, seed), nullptr, header, cloud);
  return cloud;
}

// An organized H x W cloud in staggered column order (row v, column u is
// pixel (v, u) of the staggered image), with every nan_every-th point NaN.
sensor_msgs::PointCloud2 staggeredCloud(const LidarModel& model, double stamp_s, const std::string& frame,
                                        int nan_every, std::size_t* nan_count) {
  sensor_msgs::PointCloud2 cloud;
  cloud.header.stamp = ros::Time(stamp_s);
  cloud.header.frame_id = frame;
  sensor_msgs::PointCloud2Modifier modifier(cloud);
  modifier.setPointCloud2FieldsByString(1, "xyz");
  modifier.resize(std::size_t(model.rows()) * model.columns());
  cloud.height = static_cast<uint32_t>(model.rows());
  cloud.width = static_cast<uint32_t>(model.columns());
  cloud.row_step = cloud.width * cloud.point_step;
  cloud.is_dense = false;
  const std::vector<Eigen::Vector3f> points = everyPixel(model, 7);
  sensor_msgs::PointCloud2Iterator<float> x(cloud, "x"), y(cloud, "y"), z(cloud, "z");
  *nan_count = 0;
  for (std::size_t i = 0; i < points.size(); ++i, ++x, ++y, ++z) {
    const bool nan = i % nan_every == 0;
    *nan_count += nan;
    *x = nan ? std::numeric_limits<float>::quiet_NaN() : points[i].x();
    *y = nan ? std::numeric_limits<float>::quiet_NaN() : points[i].y();
    *z = nan ? std::numeric_limits<float>::quiet_NaN() : points[i].z();
  }
  return cloud;
}

class AdapterWarningsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ros::console::register_appender(&log_);
    diagnostics_subscriber_ = node_.subscribe<diagnostic_msgs::DiagnosticArray>(
        "/diagnostics", 100, [this](const diagnostic_msgs::DiagnosticArray::ConstPtr& array) {
          for (const diagnostic_msgs::DiagnosticStatus& status : array->status) {
            std::map<std::string, std::string>& values = diagnostics_[status.name];
            for (const diagnostic_msgs::KeyValue& value : status.values) values[value.key] = value.value;
          }
        });
  }
  void TearDown() override {
    loader_.clear();
    ros::console::deregister_appender(&log_);
  }

  // An Adapter for PointCloud2 as NAMESPACE/adapter (topics NAMESPACE/points and NAMESPACE/range_image).
  void load(const std::string& ns, const std::map<std::string, std::string>& parameters) {
    ros::NodeHandle private_node(ns + "/adapter");
    private_node.setParam("input", "pointcloud");
    private_node.setParam("statistics_period", 0.5);
    private_node.setParam("cloud_queue_size", 20);  // clouds wait while the model is estimated
    for (const auto& [name, value] : parameters) private_node.setParam(name, value);
    // Loaded directly: rosconsole holds one appender at a time (test::loadNodelet registers its own).
    ASSERT_TRUE(loader_.load(ns + "/adapter", "range_image_mapping/Adapter", nodelet::M_string(), nodelet::V_string()))
        << ns;
    images_[ns] = {};
    subscribers_[ns] = node_.subscribe<LidarRangeImage>(
        ns + "/range_image", 20, [this, ns](const LidarRangeImage::ConstPtr& image) { images_[ns].push_back(image); });
    publishers_[ns] = node_.advertise<sensor_msgs::PointCloud2>(ns + "/points", 10);
  }

  void publish(const std::string& ns, const sensor_msgs::PointCloud2& cloud) {
    ASSERT_TRUE(test::spinUntil(
        [&] { return publishers_[ns].getNumSubscribers() > 0 && subscribers_[ns].getNumPublishers() > 0; }, 10.0));
    publishers_[ns].publish(cloud);
    test::spinUntil([] { return false; }, 0.05);
  }

  // The diagnostics values of NAMESPACE/adapter's point clouds status, once they hold `key`.
  std::map<std::string, std::string> diagnosticsWith(const std::string& ns, const std::string& key) {
    const std::string name = ns.substr(1) + "/adapter: point clouds";
    std::map<std::string, std::string> found;
    test::spinUntil([&] {
      for (const auto& [status, values] : diagnostics_)
        if (status.find(name) != std::string::npos && values.count(key)) {
          found = values;
          return true;
        }
      return false;
    }, 10.0);
    return found;
  }

  ros::NodeHandle node_;
  nodelet::Loader loader_{false};
  LogLines log_;
  ros::Subscriber diagnostics_subscriber_;
  std::map<std::string, ros::Subscriber> subscribers_;
  std::map<std::string, ros::Publisher> publishers_;
  std::map<std::string, std::vector<LidarRangeImage::ConstPtr>> images_;
  std::map<std::string, std::map<std::string, std::string>> diagnostics_;
};

TEST_F(AdapterWarningsTest, EstimatedModelFrameAndMissingClouds) {
  load("/est", {});  // no model: estimated; sensor_frame left at os_sensor
  const LidarModel vlp32c(*catalogSensor("VLP-32C"));
  // 10 Hz, with the clouds of 0.6 and 0.7 s missing.
  const double stamps[] = {100.0, 100.1, 100.2, 100.3, 100.4, 100.5, 100.8, 100.9};
  for (int i = 0; i < 8; ++i) publish("/est", plainCloud(vlp32c, i + 1, stamps[i], "velodyne"));
  ASSERT_TRUE(test::spinUntil([&] { return images_["/est"].size() >= 8; }, 20.0))
      << images_["/est"].size() << " range images of 8";
  const LidarRangeImage& image = *images_["/est"].front();
  EXPECT_EQ(image.height, 32u);
  EXPECT_EQ(image.width, 1808u);
  EXPECT_EQ(image.sensor_model.rfind("estimated", 0), 0u) << image.sensor_model;
  EXPECT_EQ(image.header.stamp, ros::Time(100.0)) << "the held clouds keep their stamps";

  const auto estimate = log_.matching(log_.infos, "sensor model estimated from the first 3 clouds on");
  ASSERT_EQ(estimate.size(), 1u) << "the estimate is logged once";
  EXPECT_NE(estimate[0].find("32 beams"), std::string::npos) << estimate[0];
  EXPECT_NE(estimate[0].find("% kept"), std::string::npos) << estimate[0];
  EXPECT_TRUE(log_.matching(log_.warnings, "explains only").empty()) << "a good estimate is not warned about";

  const auto frame = log_.matching(log_.warnings, "parameter /est/adapter/sensor_frame is 'os_sensor'");
  ASSERT_EQ(frame.size(), 1u) << "warned once";
  EXPECT_NE(frame[0].find("set sensor_frame:=velodyne"), std::string::npos) << frame[0];

  const auto values = diagnosticsWith("/est", "clouds missing (from the stamps)");
  EXPECT_EQ(values.count("warning: sensor_frame"), 1u);
  EXPECT_EQ(values.count("warning: model fit"), 0u);
  test::spinUntil([&] { return !log_.matching(log_.warnings, "missing 2 (from the stamps)").empty(); }, 5.0);
  EXPECT_EQ(diagnosticsWith("/est", "clouds missing (from the stamps)")["clouds missing (from the stamps)"], "2");
  EXPECT_FALSE(log_.matching(log_.warnings, "missing 2 (from the stamps)").empty());
}

TEST_F(AdapterWarningsTest, ModelThatExplainsTooLittleIsWarnedNamingTheParameter) {
  load("/wrong", {{"sensor", "VLP-16"}, {"sensor_frame", "hesai_lidar"}});
  const LidarModel pandar64(*catalogSensor("Pandar64"));
  for (int i = 0; i < 3; ++i) publish("/wrong", plainCloud(pandar64, i + 1, 200.0 + 0.1 * i, "hesai_lidar"));
  ASSERT_TRUE(test::spinUntil([&] { return images_["/wrong"].size() >= 3; }, 20.0));
  EXPECT_EQ(images_["/wrong"].front()->height, 16u) << "the sensor parameter's model";
  const auto fit = log_.matching(log_.warnings, "explains only");
  ASSERT_EQ(fit.size(), 1u);
  EXPECT_NE(fit[0].find("check parameter /wrong/adapter/sensor (VLP-16)"), std::string::npos) << fit[0];
  EXPECT_TRUE(log_.matching(log_.warnings, "sensor_frame").empty()) << "the clouds' frame is sensor_frame";
  EXPECT_EQ(diagnosticsWith("/wrong", "warning: model fit").count("warning: model fit"), 1u);
}

// Stamps 2 ms apart in a 10 Hz stream: a driver stamping with jitter.
TEST_F(AdapterWarningsTest, StampsFarCloserThanThePeriod) {
  load("/jitter", {{"sensor", "VLP-16"}, {"sensor_frame", "velodyne"}});
  const LidarModel vlp16(*catalogSensor("VLP-16"));
  const double stamps[] = {500.0, 500.1, 500.2, 500.3, 500.302};
  for (int i = 0; i < 5; ++i) publish("/jitter", plainCloud(vlp16, i + 1, stamps[i], "velodyne"));
  ASSERT_TRUE(test::spinUntil([&] { return images_["/jitter"].size() >= 5; }, 20.0));
  const auto jitter = log_.matching(log_.warnings, "are stamped less than half a period");
  ASSERT_EQ(jitter.size(), 1u);
  EXPECT_NE(jitter[0].find("TIME_FROM_ROS_TIME"), std::string::npos) << jitter[0];
  EXPECT_EQ(diagnosticsWith("/jitter", "warning: stamps").count("warning: stamps"), 1u);
}

// A ring field with more rings than the model has rows: another sensor.
TEST_F(AdapterWarningsTest, RingCountAgainstTheModelsRows) {
  load("/rings", {{"sensor", "VLP-16"}, {"sensor_frame", "velodyne"}});
  const auto vlp32c = std::make_shared<const LidarModel>(*catalogSensor("VLP-32C"));
  RangeImage image(vlp32c);
  std::mt19937 random(5);
  std::uniform_real_distribution<float> range(2.0f, 40.0f);
  for (float& value : image.range) value = range(random);
  image.stamp_ns = 400'000'000'000ull;
  sensor_msgs::PointCloud2 cloud;
  rangeImageToPointCloud2(image, CloudLayout::kVelodyne, "velodyne", cloud);  // ring 0..31
  publish("/rings", cloud);
  ASSERT_TRUE(test::spinUntil([&] { return !images_["/rings"].empty(); }, 20.0));
  const auto rings = log_.matching(log_.warnings, "carry 32 rings but the sensor model (VLP-16) has 16 rows");
  ASSERT_EQ(rings.size(), 1u);
  EXPECT_NE(rings[0].find("set parameter /rings/adapter/sensor to the 32-beam sensor"), std::string::npos)
      << rings[0];
  EXPECT_EQ(diagnosticsWith("/rings", "warning: rings").count("warning: rings"), 1u);
}

TEST_F(AdapterWarningsTest, StaggeredOrganizedCloudsContradictOrganizedColumns) {
  const std::string metadata = (std::filesystem::temp_directory_path() / "adapter_warnings_os1.json").string();
  std::ofstream(metadata) << simulation::ousterLikeMetadataJson("OS-1-128", UdpProfile::kLegacy);
  load("/staggered", {{"intrinsics", "ouster"}, {"metadata_file", metadata}, {"organized_columns", "destaggered"}});
  const LidarModel model(loadOusterMetadata(metadata).intrinsics);
  std::size_t nan_count = 0;
  publish("/staggered", staggeredCloud(model, 300.0, "os_lidar", 97, &nan_count));
  ASSERT_TRUE(test::spinUntil([&] { return !images_["/staggered"].empty(); }, 20.0));
  const auto order = log_.matching(log_.warnings, "are staggered but parameter /staggered/adapter/organized_columns");
  ASSERT_EQ(order.size(), 1u);
  EXPECT_NE(order[0].find("set organized_columns: staggered"), std::string::npos) << order[0];
  // The data's order is used: every measured point has its own pixel.
  const LidarRangeImage& image = *images_["/staggered"].front();
  const std::size_t valid =
      std::count_if(image.range.begin(), image.range.end(), [](float range) { return std::isfinite(range); });
  EXPECT_EQ(valid, std::size_t(model.rows()) * model.columns() - nan_count);
  EXPECT_EQ(diagnosticsWith("/staggered", "warning: organized_columns").count("warning: organized_columns"), 1u);
  // The NaN no-return points are no drops: with nothing else lost, no
  // summary ("last N s: ...") is logged in three statistics periods.
  ros::WallDuration(1.5).sleep();
  const auto summaries = log_.matching(log_.warnings, "last ");
  EXPECT_TRUE(summaries.empty()) << summaries.front();
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  return range_image_mapping::test::runRostestNode(argc, argv, "adapter_warnings");
}
