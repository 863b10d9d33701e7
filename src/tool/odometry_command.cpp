// rim odometry: LiDAR odometry over a recording (an Ouster pcap with its
// metadata, a KITTI velodyne folder, or a folder written by rim simulate),
// written as KITTI and TUM poses plus per-frame statistics.
#include "commands.h"
#include "outputs.h"
#include "progress.h"

#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/io/recording.h"
#include "range_image_mapping/registration/lidar_odometry.h"

#include <json/json.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>

namespace range_image_mapping::tool {
namespace {

namespace fs = std::filesystem;

struct OdometryCommandOptions {
  io::RecordingOptions recording;
  std::string output;  // KITTI poses; the other files are named after it
  OdometryCommandLine odometry;
  std::string frame = "lidar";
};

int runOdometry(const OdometryCommandOptions& options) {
  const io::Recording recording = io::openRecording(options.recording);
  if (options.frame == "sensor" && !recording.ouster)
    throw std::invalid_argument("--frame sensor: KITTI scans have no Ouster sensor frame");

  registration::LidarOdometry odometry(options.odometry.options());

  const fs::path output(options.output);
  if (!output.parent_path().empty()) fs::create_directories(output.parent_path());
  const std::string frames_path = siblingPath(options.output, "frames.csv");
  OdometryFramesCsv frames_file(frames_path);

  std::cerr << "odometry over " << recording.description << "\n";
  reportSensorModel(recording);
  std::vector<io::StampedPose> poses;
  std::vector<double> step_seconds;
  int frames = 0;
  OdometryHealth health;
  const auto started = std::chrono::steady_clock::now();
  io::RecordingStatistics reading;
  io::forEachScan(
      recording,
      [&](const RangeImage& scan) {
        const registration::OdometryUpdate update = odometry.process(scan);
        const double time_s = double(update.stamp_ns) * 1e-9;
        if (!update.skipped) poses.push_back({time_s, update.pose});
        step_seconds.push_back(update.seconds);
        health.add(update);
        frames_file.add(frames, update);
        if (!update.warning.empty()) std::cerr << "\nwarning: frame " << frames << ": " << update.warning << "\n";
        ++frames;
        showProgress(frames, recording.expected_frames, started);
        return true;
      },
      &reading);
  if (recording.expected_frames <= 0 || frames != recording.expected_frames) finishProgress();
  frames_file.close();
  const Json::Value reading_json = reportReading(reading);
  if (frames == 0) throw std::runtime_error("no scans in " + recording.input);
  const double total_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();

  const std::string tum_path =
      writeTrajectory(options.output, poses, recording, options.frame == "sensor",
                      "rim odometry " + recording.input + (options.odometry.no_deskew ? " --no-deskew" : ""));

  double mean_seconds = 0.0;
  for (double seconds : step_seconds) mean_seconds += seconds / double(step_seconds.size());
  Json::Value summary;
  summary["input"] = recording.input;
  summary["frames"] = frames;
  summary["poses"] = Json::UInt64(poses.size());
  summary["reading"] = reading_json;
  const Json::Value health_json = health.json();
  for (const std::string& key : health_json.getMemberNames()) summary[key] = health_json[key];
  const Json::Value odometry_json = options.odometry.json(recording.model.get());
  for (const std::string& key : odometry_json.getMemberNames()) summary[key] = odometry_json[key];
  summary["frame"] = options.frame == "sensor" ? "os_sensor" : recording.frame;
  summary["step_seconds_mean"] = mean_seconds;
  summary["step_seconds_median"] = median(step_seconds);
  summary["step_seconds_max"] =
      step_seconds.empty() ? 0.0 : *std::max_element(step_seconds.begin(), step_seconds.end());
  summary["steps_per_second"] = mean_seconds > 0 ? 1.0 / mean_seconds : 0.0;
  summary["wall_seconds"] = total_seconds;
  summary["poses_kitti"] = options.output;
  summary["poses_tum"] = tum_path;
  summary["frames_csv"] = frames_path;
  const std::string summary_path = siblingPath(options.output, "summary.json");
  writeJsonFile(summary_path, summary);

  std::cout << frames << " scans, " << poses.size() << " poses (" << health.line() << "); odometry step "
            << mean_seconds * 1e3 << " ms mean, " << median(step_seconds) * 1e3 << " ms median; written to "
            << options.output << ", " << tum_path << ", " << frames_path << ", " << summary_path << "\n";
  return reportHealth(health);
}

}  // namespace

void addOdometryCommand(Command& rim) {
  auto options = std::make_shared<OdometryCommandOptions>();
  Command& command = rim.subcommand(
      "odometry",
      "LiDAR odometry over a recording: KITTI and TUM poses (traj.txt, traj_tum.txt), per-frame "
      "statistics (traj_frames.csv) and a summary (traj_summary.json)");
  command.option("--out,-o", options->output, "KITTI poses file; the other outputs are named after it").required();
  addRecordingOptions(command, options->recording, kRecordingInputHelp, "process only the first N scans");
  addOdometryOptions(command, options->odometry);
  command.option("--frame", options->frame, "whose poses: lidar (the image's frame) or sensor (Ouster)")
      .showDefault()
      .check(oneOf({"lidar", "sensor"}));
  command.callback([options] { runOdometry(*options); });
}

}  // namespace range_image_mapping::tool
