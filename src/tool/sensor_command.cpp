// rim sensor estimate: a sensor model estimated from a recording's point
// clouds (beams, columns, azimuth offsets, beam origin), written as a sensor
// file, with how well it explains the clouds. rim sensor check: how well a
// sensor file explains a recording.
#include "commands.h"
#include "outputs.h"

#include "range_image_mapping/sensor_model_report.h"
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/recording.h"
#include "range_image_mapping/io/sensor_file.h"
#include "range_image_mapping/sensor_model_estimation.h"

#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>

namespace range_image_mapping::tool {
namespace {

namespace fs = std::filesystem;

struct SensorCommandOptions {
  std::string input;
  std::string metadata;
  std::string output;
  std::string sensor;  // rim sensor check
  std::string topic;
  int frames = 5;
  int columns = 0;
  bool no_beam_origin = false;
  bool no_ring = false;
};

// The recording's first frames as the plain clouds a driver would give: point
// clouds (KITTI, .bin/.pcd/.ply files, a PointCloud2 bag) as stored, Ouster
// scans unprojected with their metadata (lidar frame).
std::vector<PointCloudInput> readClouds(const SensorCommandOptions& options, std::string* description) {
  std::vector<PointCloudInput> clouds;
  io::RecordingOptions recording_options;
  recording_options.input = options.input;
  recording_options.metadata = options.metadata;
  recording_options.topic = options.topic;
  recording_options.frames = options.frames;
  recording_options.choose_model = false;
  const io::Recording recording = io::openRecording(recording_options);
  *description = recording.description;
  io::RecordingStatistics reading;
  if (io::isPointCloudRecording(recording.kind)) {
    io::forEachCloud(
        recording,
        [&](const PointCloudInput& cloud) {
          clouds.push_back(cloud);
          return true;
        },
        &reading);
  } else {
    io::forEachScan(
        recording,
        [&](const RangeImage& image) {
          PointCloudInput cloud;
          for (int v = 0; v < image.rows(); ++v)
            for (int u = 0; u < image.columns(); ++u)
              if (image.valid(v, u)) cloud.points.push_back(image.model->unproject(u, v, image.at(v, u)));
          clouds.push_back(std::move(cloud));
          return static_cast<int>(clouds.size()) < options.frames;
        },
        &reading);
  }
  reportReading(reading);
  return clouds;
}

void printFit(const SensorModelFit& fit) {
  std::printf("%s\n", describeSensorModelFit(fit).c_str());
  if (const std::optional<std::string> warning =
          sensorModelFitWarning(fit, "try rim sensor estimate on this recording"))
    std::printf("warning: %s\n", warning->c_str());
}

void runEstimate(const SensorCommandOptions& options) {
  std::string description;
  const std::vector<PointCloudInput> clouds = readClouds(options, &description);
  if (clouds.empty()) throw CommandFailed("no scans in " + options.input, 3);
  SensorEstimationOptions estimation;
  estimation.columns = options.columns;
  estimation.estimate_beam_origin = !options.no_beam_origin;
  estimation.use_ring_field = !options.no_ring;
  std::cout << "estimating the sensor model from " << clouds.size() << " clouds of " << description << "\n";
  const SensorEstimate estimate = estimateSensorModel(clouds, estimation);
  const LidarIntrinsics& intrinsics = estimate.intrinsics;
  double highest = -90.0, lowest = 90.0;
  for (const double altitude : intrinsics.altitude_rad)
    highest = std::max(highest, altitude * 180.0 / M_PI), lowest = std::min(lowest, altitude * 180.0 / M_PI);
  std::printf("%d beams from %+.2f to %+.2f deg, %d columns (azimuth step %.4f deg), beam origin %.1f mm from the "
              "axis and %.1f mm up%s\n",
              intrinsics.rows, highest, lowest, intrinsics.columns, estimate.azimuth_step_deg,
              intrinsics.beam_origin_radius_m * 1e3, intrinsics.beam_origin_z_m * 1e3,
              estimate.ring_to_row.empty() ? "" : "; rows from the ring field");
  printFit(estimate.fit);
  const fs::path output(options.output);
  if (!output.parent_path().empty()) fs::create_directories(output.parent_path());
  io::writeSensorFile(options.output, intrinsics, estimate.ring_to_row, &estimate);
  std::cout << "sensor file: " << options.output << "\n";
}

void runCheck(const SensorCommandOptions& options) {
  const io::SensorFile file = io::readSensorFile(options.sensor);
  std::string description;
  const std::vector<PointCloudInput> clouds = readClouds(options, &description);
  if (clouds.empty()) throw CommandFailed("no scans in " + options.input, 3);
  std::cout << options.sensor << " (" << file.intrinsics.sensor_model << ", " << file.intrinsics.rows << " x "
            << file.intrinsics.columns << ") on " << clouds.size() << " clouds of " << description << "\n";
  printFit(measureSensorModelFit(clouds, std::make_shared<const LidarModel>(file.intrinsics), file.ring_to_row));
}

void addInputOptions(Command& command, SensorCommandOptions& options) {
  command.option("input", options.input, kRecordingInputHelp).required();
  command.option("--topic", options.topic, "the bag's topic to read (default: the only PointCloud2 or packet one)");
  command.option("--metadata,-m", options.metadata, "Ouster metadata JSON of a pcap (default: metadata.json beside it)")
      .check(existingFile());
  command.option("--frames", options.frames, "use the first N scans").check(positive()).showDefault();
}

}  // namespace

void addSensorCommand(Command& rim) {
  auto options = std::make_shared<SensorCommandOptions>();
  Command& sensor = rim.subcommand("sensor", "Sensor models: estimate one from a recording, check one against it");
  Command& estimate = sensor.subcommand(
      "estimate", "Estimate the sensor model (beams, columns, azimuth offsets, beam origin) from a recording's "
                  "point clouds and write it as a sensor file (YAML)");
  addInputOptions(estimate, *options);
  estimate.option("--out,-o", options->output, "sensor file to write (YAML)").required();
  estimate.option("--columns", options->columns, "columns per revolution (default: from the azimuth step)")
      .check(nonNegative());
  estimate.flag("--no-beam-origin", options->no_beam_origin, "keep the beam origin on the axis (r0 = 0, height 0)");
  estimate.flag("--no-ring", options->no_ring, "ignore a ring field, cluster the elevations");
  estimate.callback([options] { runEstimate(*options); });

  Command& check = sensor.subcommand("check", "How well a sensor file (YAML, or Ouster metadata JSON) explains "
                                              "a recording's point clouds");
  check.option("sensor", options->sensor, "sensor file, or a named model (VLP-16, HDL-64E, ...)").required();
  addInputOptions(check, *options);
  check.callback([options] { runCheck(*options); });
}

}  // namespace range_image_mapping::tool
