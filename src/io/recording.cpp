#include "range_image_mapping/io/recording.h"

#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/io/pcd.h"
#include "range_image_mapping/io/ply.h"
#include "range_image_mapping/io/rosbag_reader.h"
#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/io/sensor_file.h"
#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/point_cloud_layout.h"
#include "range_image_mapping/point_cloud_projection.h"
#include "range_image_mapping/scan_batcher.h"
#include "range_image_mapping/sensor_model_report.h"

#include <json/json.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <cstdio>
#include <fstream>
#include <map>

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


bool hasCloudExtension(const fs::path& path) {
  const std::string extension = path.extension().string();
  return extension == ".bin" || extension == ".pcd" || extension == ".ply";
}

// A folder's scans: files of one cloud extension, sorted. Throws when it mixes them.
std::vector<std::string> cloudFiles(const fs::path& directory, const std::string& input) {
  std::map<std::string, std::vector<std::string>> by_extension;
  for (const auto& entry : fs::directory_iterator(directory))
    if (entry.is_regular_file() && hasCloudExtension(entry.path()))
      by_extension[entry.path().extension().string()].push_back(entry.path().string());
  if (by_extension.size() > 1) {
    std::string counts;
    for (const auto& [extension, files] : by_extension)
      counts += (counts.empty() ? "" : ", ") + std::to_string(files.size()) + " " + extension;
    throw RecordingError("INPUT " + input + " holds scans of several formats (" + counts +
                         "): keep one kind of scan per folder");
  }
  if (by_extension.empty()) return {};
  std::vector<std::string> files = by_extension.begin()->second;
  std::sort(files.begin(), files.end());
  return files;
}

// One scan file, with stamp_ns as the stamp its points' times are relative to.
PointCloudInput readCloudFile(const std::string& path, uint64_t stamp_ns) {
  const std::string extension = fs::path(path).extension().string();
  PointCloudInput cloud;
  if (extension == ".pcd") return readPcd(path, stamp_ns);
  if (extension == ".ply") {
    cloud.points = readPlyPoints(path);
    cloud.organized_width = int(cloud.points.size());
  } else {
    cloud = readKittiVelodyne(path);
  }
  cloud.stamp_ns = stamp_ns;
  return cloud;
}

// The model of a point-cloud recording: the sensor file's, KITTI's HDL-64E,
// or estimated from the first clouds; with its fit on those clouds.
void chooseCloudModel(Recording& recording, const RecordingOptions& options) {
  const int scans = std::max(options.estimation_scans, 1);
  Recording first = recording;
  first.frames = scans;
  std::vector<PointCloudInput> clouds;
  forEachCloud(first, [&](const PointCloudInput& cloud) {
    clouds.push_back(cloud);
    return true;
  });
  RecordingModel& info = recording.model_info;
  std::string fix;
  if (!options.sensor.empty()) {
    const SensorFile sensor = readSensorFile(options.sensor);
    recording.model = std::make_shared<const LidarModel>(sensor.intrinsics);
    info.ring_to_row = sensor.ring_to_row;
    info.source = "sensor file " + options.sensor;
    fix = "check that " + options.sensor + " is this sensor's, or leave --sensor out to estimate the model";
  } else if (recording.kind == RecordingKind::kKittiVelodyne) {
    recording.model = std::make_shared<const LidarModel>(kittiHdl64Intrinsics());
    info.source = "KITTI's HDL-64E (synthetic)";
    fix = "give this sensor's model with --sensor FILE (rim sensor estimate INPUT -o FILE estimates one), or "
          "give the folder of scans itself without --kitti to have the model estimated";
  } else {
    if (clouds.empty()) throw RecordingError("INPUT " + recording.input + " has no scans to estimate a sensor model from");
    try {
      const SensorEstimate estimate = estimateSensorModel(clouds);
      recording.model = std::make_shared<const LidarModel>(estimate.intrinsics);
      info.ring_to_row = estimate.ring_to_row;
      info.fit = estimate.fit;
    } catch (const SensorEstimationError& error) {
      throw RecordingError("INPUT " + recording.input + ": no sensor model could be estimated from its first " +
                           std::to_string(clouds.size()) + " scans (" + error.what() +
                           "); give the sensor's model with --sensor FILE");
    }
    info.source = "estimated from the first " + std::to_string(clouds.size()) + " scans";
    fix = "give the sensor's model with --sensor FILE (rim sensor estimate INPUT -o FILE writes the estimate "
          "to start from)";
  }
  if (!info.fit && !clouds.empty()) info.fit = measureSensorModelFit(clouds, recording.model, info.ring_to_row);
  const LidarIntrinsics& intrinsics = recording.model->intrinsics();
  info.summary = "sensor model " + info.source + ": " + describeSensorModel(intrinsics);
  if (recording.kind != RecordingKind::kKittiVelodyne || !options.sensor.empty())
    recording.description += " (sensor model " + (options.sensor.empty() ? info.source : options.sensor) + ": " +
                             std::to_string(intrinsics.rows) + " x " + std::to_string(intrinsics.columns) + ")";
  if (info.fit) {
    info.summary += "; on the first " + describeSensorModelFit(*info.fit);
    if (const std::optional<std::string> warning = sensorModelFitWarning(*info.fit, fix))
      info.warning = *warning + " (the model: " + info.source + ")";
  }
}

void openBag(Recording& recording, const RecordingOptions& options) {
  const BagReader bag(recording.input);
  recording.bag = recording.input;
  const std::vector<BagTopic> packets = bag.ousterPacketTopics();
  bool packets_requested = false;
  for (const BagTopic& topic : packets) packets_requested |= topic.name == options.topic;
  const bool read_packets = packets_requested || (options.topic.empty() && !packets.empty());
  if (!read_packets) {
    recording.kind = RecordingKind::kPointCloudBag;
    recording.topic = choosePointCloudTopic(bag, options.topic);
    for (const BagTopic& topic : bag.topics())
      if (topic.name == recording.topic) recording.expected_frames = int(topic.messages);
    recording.frame = "lidar";
    bag.forEachPointCloud(recording.topic, [&](const BagPointCloud& cloud) {
      if (!cloud.frame_id.empty()) recording.frame = cloud.frame_id;
      return false;
    });
    recording.description = std::to_string(recording.expected_frames) + " PointCloud2 clouds on " +
                            recording.topic + " (frame " + recording.frame + ") in " + recording.input;
    return;
  }
  if (!options.sensor.empty())
    throw RecordingError("INPUT " + recording.input + " holds Ouster packets, whose sensor model is their " +
                         "metadata: give that with --metadata, not a sensor file (" + options.sensor + ")");
  const OusterBagTopics topics = chooseOusterTopics(bag, options.topic);
  recording.kind = RecordingKind::kOusterPacketBag;
  recording.topic = topics.packets;
  std::string metadata_source;
  if (!options.metadata.empty()) {
    recording.ouster = loadOusterMetadata(options.metadata);
    metadata_source = options.metadata;
  } else if (!topics.metadata.empty()) {
    recording.ouster = parseOusterMetadata(bag.firstString(topics.metadata));
    metadata_source = "topic " + topics.metadata;
  } else {
    throw RecordingError("INPUT " + recording.input + ": the Ouster packets on " + topics.packets +
                         " need the sensor metadata, and the bag has no metadata topic (std_msgs/String ending in "
                         "'metadata'): give the metadata JSON with --metadata");
  }
  recording.model = std::make_shared<const LidarModel>(recording.ouster->intrinsics);
  recording.frame = "os_lidar";
  recording.description = recording.ouster->prod_line + " " + recording.ouster->lidar_mode + " packets on " +
                          topics.packets + " in " + recording.input + " (metadata from " + metadata_source + ")";
}

void openOusterCapture(Recording& recording, const RecordingOptions& options, fs::path& sequence) {
  const fs::path input(options.input);
  if (!options.sensor.empty())
    throw RecordingError("INPUT " + options.input + " is an Ouster capture, whose sensor model is its metadata: " +
                         "give that with --metadata, not a sensor file (" + options.sensor + ")");
  const fs::path pcap = fs::is_directory(input) ? input / "capture.pcap" : input;
  if (!fs::exists(pcap))
    throw RecordingError("INPUT " + options.input + ": neither a pcap, a bag, a folder with capture.pcap, a " +
                         "KITTI velodyne folder, nor a folder of .bin, .pcd or .ply scans");
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

// The stamp of a file scan without times of its own: times.txt, else 10 Hz.
uint64_t fileStamp(const Recording& recording, std::size_t frame) {
  const double time_s =
      std::max(frame < recording.times_s.size() ? recording.times_s[frame] : 0.1 * double(frame), 0.0);
  // Whole seconds apart: time_s * 1e9 in one double would round clock times to 256 ns.
  const double seconds = std::floor(time_s);
  return uint64_t(seconds) * 1000000000ull + uint64_t(std::llround((time_s - seconds) * 1e9));
}

}  // namespace

bool isPointCloudRecording(RecordingKind kind) {
  return kind == RecordingKind::kKittiVelodyne || kind == RecordingKind::kCloudFiles ||
         kind == RecordingKind::kPointCloudBag;
}

Recording openRecording(const RecordingOptions& options) {
  Recording recording;
  recording.input = options.input;
  recording.frames = std::max(options.frames, 0);
  const fs::path input(options.input);
  if (options.input.empty()) throw RecordingError("no INPUT recording given");
  if (!fs::exists(input)) throw RecordingError("INPUT " + options.input + " does not exist");
  fs::path sequence = input;  // the folder that may hold column_times.txt / times.txt
  const bool is_folder = fs::is_directory(input);
  const bool has_velodyne = fs::is_directory(input / "velodyne");
  if (options.kitti && !is_folder) throw RecordingError("KITTI input: INPUT " + options.input + " is not a folder");
  if (!options.topic.empty() && input.extension() != ".bag")
    throw RecordingError("--topic " + options.topic + " is for a bag; INPUT " + options.input + " is none");
  if (is_folder && (options.kitti || (has_velodyne && !fs::exists(input / "capture.pcap")))) {
    const fs::path folder = has_velodyne ? input / "velodyne" : input;
    recording.kind = RecordingKind::kKittiVelodyne;
    recording.velodyne_files = velodyneFiles(folder);
    if (recording.velodyne_files.empty())
      throw RecordingError("INPUT " + options.input + ": no KITTI scans (*.bin) in " + folder.string());
    if (!has_velodyne) sequence = input.parent_path();
    recording.frame = "velodyne";
    recording.description = std::to_string(recording.velodyne_files.size()) + " KITTI scans in " + folder.string();
    recording.expected_frames = int(recording.velodyne_files.size());
    if (fs::exists(sequence / "times.txt")) recording.times_s = readTimes((sequence / "times.txt").string());
  } else if (!is_folder && input.extension() == ".bag") {
    openBag(recording, options);
  } else if ((!is_folder && hasCloudExtension(input)) ||
             (is_folder && !fs::exists(input / "capture.pcap") &&
              (fs::is_directory(input / "clouds") || !cloudFiles(input, options.input).empty()))) {
    // A rim simulate folder keeps a sensor's plain clouds in clouds/, beside
    // scene.ply and surface.ply, which are no scans.
    const fs::path cloud_folder = is_folder && fs::is_directory(input / "clouds") ? input / "clouds" : input;
    recording.kind = RecordingKind::kCloudFiles;
    recording.cloud_files =
        is_folder ? cloudFiles(cloud_folder, cloud_folder.string()) : std::vector<std::string>{input.string()};
    if (recording.cloud_files.empty())
      throw RecordingError("INPUT " + options.input + ": no scans (.bin, .pcd, .ply) in " + cloud_folder.string());
    if (!is_folder) sequence = input.parent_path();
    recording.frame = "lidar";
    recording.description = std::to_string(recording.cloud_files.size()) + " " +
                            fs::path(recording.cloud_files.front()).extension().string() + " scans in " +
                            cloud_folder.string();
    recording.expected_frames = int(recording.cloud_files.size());
    if (is_folder && fs::exists(cloud_folder / "times.txt"))
      recording.times_s = readTimes((cloud_folder / "times.txt").string());
  } else {
    openOusterCapture(recording, options, sequence);
  }
  if (isPointCloudRecording(recording.kind) && options.choose_model) chooseCloudModel(recording, options);
  // Only a folder given as INPUT is taken for a rim simulate folder: a pcap
  // given directly may sit next to unrelated files.
  if (is_folder) {
    if (fs::exists(sequence / "column_times.txt")) {
      recording.column_times = readColumnTimes((sequence / "column_times.txt").string());
      if (recording.expected_frames == 0) recording.expected_frames = int(recording.column_times.size());
    }
    recording.ground_truth = findGroundTruth(sequence);
    // rim simulate writes a sensor's plain clouds to clouds/, beside its ground truth.
    const fs::path folder = sequence.filename().empty() ? sequence.parent_path() : sequence;  // "clouds/"
    if (recording.kind == RecordingKind::kCloudFiles && recording.ground_truth.poses.empty() &&
        folder.filename() == "clouds")
      recording.ground_truth = findGroundTruth(folder.parent_path());
  }
  if (recording.frames > 0)
    recording.expected_frames =
        recording.expected_frames ? std::min(recording.expected_frames, recording.frames) : recording.frames;
  return recording;
}

std::size_t forEachCloud(const Recording& recording, const std::function<bool(const PointCloudInput&)>& on_cloud) {
  if (!isPointCloudRecording(recording.kind))
    throw RecordingError("INPUT " + recording.input + " holds Ouster packets, not point clouds");
  const std::size_t limit = recording.frames > 0 ? std::size_t(recording.frames) : SIZE_MAX;
  std::size_t given = 0;
  if (limit == 0) return 0;
  if (recording.kind == RecordingKind::kPointCloudBag) {
    const BagReader bag(recording.bag);
    PointCloudInput cloud;
    return bag.forEachPointCloud(recording.topic, [&](const BagPointCloud& message) {
      try {
        readPointCloud(message.layout, message.data, message.size, message.header_stamp_ns, cloud);
      } catch (const PointCloudLayoutError& error) {
        throw PointCloudLayoutError(std::string(error.what()) + " (message " + std::to_string(given) + " on " +
                                    recording.topic + " in " + recording.bag + ")");
      }
      ++given;
      return on_cloud(cloud) && given < limit;
    });
  }
  const std::vector<std::string>& files =
      recording.kind == RecordingKind::kKittiVelodyne ? recording.velodyne_files : recording.cloud_files;
  for (std::size_t frame = 0; frame < files.size() && given < limit; ++frame) {
    const PointCloudInput cloud = readCloudFile(files[frame], fileStamp(recording, frame));
    ++given;
    if (!on_cloud(cloud)) break;
  }
  return given;
}

std::size_t forEachScan(const Recording& recording, const std::function<bool(const RangeImage&)>& on_scan,
                        RecordingStatistics* statistics) {
  const std::size_t limit = recording.frames > 0 ? std::size_t(recording.frames) : SIZE_MAX;
  std::size_t given = 0;
  if (limit == 0) return 0;
  if (!isPointCloudRecording(recording.kind)) {
    struct Stop {};
    RangeImage image;
    const auto emit = [&](const LidarScan& scan) {
      toRangeImage(scan, recording.model, ReturnIndex::kFirst, image);
      ++given;
      if (statistics) ++statistics->scans;
      if (!on_scan(image) || given >= limit) throw Stop{};
    };
    try {
      if (recording.kind == RecordingKind::kOusterCapture) {
        readOusterScans(recording.pcap, *recording.ouster, emit);
      } else {
        ScanBatcher batcher(*recording.ouster, emit);
        std::size_t packet_size = 0;
        BagReader(recording.bag).forEachOusterPacket(recording.topic, [&](const BagPacket& packet) {
          packet_size = packet.size;
          batcher.addPacket(packet.data, packet.size);
          return true;
        });
        batcher.flush();
        const BatcherStatistics& packets = batcher.statistics();
        if (given == 0 && packets.wrong_size > 0)
          throw RecordingError("INPUT " + recording.input + ": the " + std::to_string(packets.wrong_size) +
                               " packets on " + recording.topic + " (" + std::to_string(packet_size) +
                               " bytes) are not the metadata's lidar packets (" +
                               std::to_string(batcher.format().packetSize()) +
                               " bytes): an IMU topic, or metadata of another sensor or mode?");
      }
    } catch (const Stop&) {
    }
    return given;
  }
  if (!recording.model) throw RecordingError("INPUT " + recording.input + " was opened without a sensor model");
  const std::vector<int>& ring_to_row = recording.model_info.ring_to_row;
  forEachCloud(recording, [&](const PointCloudInput& cloud) {
    const std::size_t frame = given;
    ProjectionStatistics projection;
    RangeImage image = !ring_to_row.empty() && !cloud.ring.empty()
                           ? projectPointCloud(cloud, recording.model, ring_to_row, &projection)
                           : projectPointCloud(cloud, recording.model, &projection);
    image.frame_id = uint32_t(frame);
    if (statistics) {
      statistics->projection.add(projection);
      ++statistics->scans;
    }
    // rim simulate's column times make the simulated scans deskewable; real
    // KITTI scans carry no point times, so they stay as they are.
    if (frame < recording.column_times.size() &&
        recording.column_times[frame].size() == std::size_t(recording.model->columns())) {
      image.column_timestamp_ns = recording.column_times[frame];
      image.stamp_ns = 0;  // the first valid column's time, as for Ouster scans
    }
    ++given;
    return on_scan(image);
  });
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
