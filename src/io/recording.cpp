#include "range_image_mapping/io/recording.h"

#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/io/sensor_file.h"
#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/point_cloud_projection.h"

#include <json/json.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

namespace range_image_mapping::io {
namespace {

namespace fs = std::filesystem;

std::vector<std::string> velodyneFiles(const fs::path& directory) {
  std::vector<std::string> files;
  for (const auto& entry : fs::directory_iterator(directory))
    if (entry.is_regular_file() && entry.path().extension() == ".bin") files.push_back(entry.path().string());
  std::sort(files.begin(), files.end());
  return files;
}

std::string existingOrEmpty(const fs::path& path) { return fs::exists(path) ? path.string() : ""; }

// rim simulate's ground truth files in its output folder.
RecordingGroundTruth findGroundTruth(const fs::path& folder) {
  RecordingGroundTruth truth;
  truth.poses = existingOrEmpty(folder / "poses_kitti.txt");
  if (!truth.poses.empty()) truth.poses_frame = poseFileFrame(truth.poses);
  truth.sensor_poses = existingOrEmpty(folder / "poses_sensor_kitti.txt");
  truth.surface = existingOrEmpty(folder / "surface.ply");
  truth.scene = existingOrEmpty(folder / "scene.ply");
  return truth;
}

}  // namespace

Recording openRecording(const RecordingOptions& options) {
  Recording recording;
  recording.input = options.input;
  recording.frames = std::max(options.frames, 0);
  const fs::path input(options.input);
  if (options.input.empty()) throw RecordingError("no INPUT recording given");
  if (!fs::exists(input)) throw RecordingError("INPUT " + options.input + " does not exist");
  fs::path sequence = input;  // the folder that may hold column_times.txt / times.txt
  const bool has_velodyne = fs::is_directory(input / "velodyne");
  if (fs::is_directory(input) && (options.kitti || (has_velodyne && !fs::exists(input / "capture.pcap")))) {
    const fs::path folder = has_velodyne ? input / "velodyne" : input;
    recording.kind = RecordingKind::kKittiVelodyne;
    recording.velodyne_files = velodyneFiles(folder);
    if (recording.velodyne_files.empty())
      throw RecordingError("INPUT " + options.input + ": no KITTI scans (*.bin) in " + folder.string());
    if (!has_velodyne) sequence = input.parent_path();
    recording.frame = "velodyne";
    recording.description = std::to_string(recording.velodyne_files.size()) + " KITTI scans in " + folder.string();
    if (options.sensor.empty()) {
      recording.model = std::make_shared<const LidarModel>(kittiHdl64Intrinsics());
    } else {
      const SensorFile sensor = readSensorFile(options.sensor);
      recording.model = std::make_shared<const LidarModel>(sensor.intrinsics);
      recording.description += " (sensor model " + options.sensor + ": " + std::to_string(sensor.intrinsics.rows) +
                               " x " + std::to_string(sensor.intrinsics.columns) + ")";
    }
    recording.expected_frames = int(recording.velodyne_files.size());
    if (fs::exists(sequence / "times.txt")) recording.times_s = readTimes((sequence / "times.txt").string());
  } else {
    if (options.kitti) throw RecordingError("KITTI input: INPUT " + options.input + " is not a folder");
    if (!options.sensor.empty())
      throw RecordingError("INPUT " + options.input + " is an Ouster capture, whose sensor model is its metadata: " +
                           "give that with --metadata, not a sensor file (" + options.sensor + ")");
    const fs::path pcap = fs::is_directory(input) ? input / "capture.pcap" : input;
    if (!fs::exists(pcap))
      throw RecordingError("INPUT " + options.input +
                           ": neither a pcap, a folder with capture.pcap, nor a KITTI velodyne folder");
    fs::path metadata = options.metadata;
    if (metadata.empty() && fs::is_directory(input)) metadata = input / "metadata.json";
    if (metadata.empty() || !fs::exists(metadata))
      throw RecordingError("INPUT " + options.input + ": the pcap " + pcap.string() +
                           " needs its Ouster sensor metadata JSON (--metadata)");
    recording.kind = RecordingKind::kOusterCapture;
    recording.ouster = loadOusterMetadata(metadata.string());
    recording.model = std::make_shared<const LidarModel>(recording.ouster->intrinsics);
    recording.pcap = pcap.string();
    recording.frame = "os_lidar";
    recording.description =
        recording.ouster->prod_line + " " + recording.ouster->lidar_mode + " scans in " + pcap.string();
    if (!fs::is_directory(input)) sequence = input.parent_path();
  }
  // Only a folder given as INPUT is taken for a rim simulate folder: a pcap
  // given directly may sit next to unrelated files.
  if (fs::is_directory(input)) {
    if (fs::exists(sequence / "column_times.txt")) {
      recording.column_times = readColumnTimes((sequence / "column_times.txt").string());
      if (recording.expected_frames == 0) recording.expected_frames = int(recording.column_times.size());
    }
    recording.ground_truth = findGroundTruth(sequence);
  }
  if (recording.frames > 0)
    recording.expected_frames =
        recording.expected_frames ? std::min(recording.expected_frames, recording.frames) : recording.frames;
  return recording;
}

std::size_t forEachScan(const Recording& recording, const std::function<bool(const RangeImage&)>& on_scan) {
  const std::size_t limit = recording.frames > 0 ? std::size_t(recording.frames) : SIZE_MAX;
  std::size_t given = 0;
  if (limit == 0) return 0;
  if (recording.kind == RecordingKind::kOusterCapture) {
    struct Stop {};
    RangeImage image;
    try {
      readOusterScans(recording.pcap, *recording.ouster, [&](const LidarScan& scan) {
        toRangeImage(scan, recording.model, ReturnIndex::kFirst, image);
        ++given;
        if (!on_scan(image) || given >= limit) throw Stop{};
      });
    } catch (const Stop&) {
    }
    return given;
  }
  for (std::size_t frame = 0; frame < recording.velodyne_files.size() && given < limit; ++frame) {
    PointCloudInput cloud = readKittiVelodyne(recording.velodyne_files[frame]);
    const double time_s = frame < recording.times_s.size() ? recording.times_s[frame] : 0.1 * double(frame);
    cloud.stamp_ns = uint64_t(std::llround(time_s * 1e9));
    RangeImage image = projectPointCloud(cloud, recording.model);
    image.frame_id = uint32_t(frame);
    // rim simulate's column times make the simulated scans deskewable; real
    // KITTI scans carry no point times, so they stay as they are.
    if (frame < recording.column_times.size() &&
        recording.column_times[frame].size() == std::size_t(recording.model->columns())) {
      image.column_timestamp_ns = recording.column_times[frame];
      image.stamp_ns = 0;  // the first valid column's time, as for Ouster scans
    }
    ++given;
    if (!on_scan(image)) break;
  }
  return given;
}

std::string poseFileFrame(const std::string& poses_path) {
  const std::string sidecar = kittiPoseFilePaths(poses_path).sidecar;
  if (fs::exists(sidecar)) {
    Json::Value root;
    std::ifstream file(sidecar);
    Json::CharReaderBuilder builder;
    std::string errors;
    if (Json::parseFromStream(builder, file, &root, &errors) && root.isObject() && root["frame"].isString())
      return root["frame"].asString();
    return "";
  }
  std::ifstream file(poses_path);
  const std::string label = "# frame: ";
  for (std::string line; std::getline(file, line);) {
    if (line.rfind('#', 0) != 0) break;  // the header ends at the first data line
    if (line.rfind(label, 0) == 0) {
      std::string frame = line.substr(label.size());
      frame.erase(frame.find_last_not_of(" \t\r") + 1);
      return frame;
    }
  }
  return "";
}

}  // namespace range_image_mapping::io
