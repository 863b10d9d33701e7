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
#include <exception>
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
  // A cloud that cannot be read is left out here and reported by the run
  // that reads them all; none readable throws the first one's error.
  RecordingStatistics skipped;
  forEachCloud(
      first,
      [&](const PointCloudInput& cloud) {
        clouds.push_back(cloud);
        return true;
      },
      &skipped);
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

namespace {

// forEachCloud with each cloud's place in the recording (file or message
// index), which skipped clouds do not shift.
std::size_t forEachIndexedCloud(const Recording& recording,
                                const std::function<bool(const PointCloudInput&, std::size_t)>& on_cloud,
                                RecordingStatistics* statistics) {
  if (!isPointCloudRecording(recording.kind))
    throw RecordingError("INPUT " + recording.input + " holds Ouster packets, not point clouds");
  const std::size_t limit = recording.frames > 0 ? std::size_t(recording.frames) : SIZE_MAX;
  std::size_t given = 0, index = 0;
  // A cloud that cannot be read is counted and skipped when statistics are
  // kept, else its error goes on; the first one's error is thrown when no
  // cloud could be read.
  std::exception_ptr first_error;
  const auto failed = [&](const std::exception_ptr& error, const std::string& name, const std::string& reason) {
    if (!statistics) std::rethrow_exception(error);
    if (!first_error) first_error = error;
    ++statistics->unreadable;
    if (statistics->unreadable_examples.size() < RecordingStatistics::kUnreadableExamples)
      statistics->unreadable_examples.push_back(name + ": " + reason);
  };
  if (limit == 0) return 0;
  if (recording.kind == RecordingKind::kPointCloudBag) {
    const BagReader bag(recording.bag);
    PointCloudInput cloud;
    try {
      bag.forEachPointCloud(recording.topic, [&](const BagPointCloud& message) {
        const std::size_t message_index = index++;
        try {
          readPointCloud(message.layout, message.data, message.size, message.header_stamp_ns, cloud);
        } catch (const PointCloudError& error) {
          const std::string where = "message " + std::to_string(message_index) + " on " + recording.topic;
          failed(std::make_exception_ptr(PointCloudLayoutError(std::string(error.what()) + " (" + where + " in " +
                                                               recording.bag + ")")),
                 where, error.what());
          return true;
        }
        ++given;
        return on_cloud(cloud, message_index) && given < limit;
      });
    } catch (const BagError& error) {
      // Damage after the first cloud: what came before it is kept.
      if (!statistics || given == 0) throw;
      statistics->stopped_early = error.what();
    }
  } else {
    const std::vector<std::string>& files =
        recording.kind == RecordingKind::kKittiVelodyne ? recording.velodyne_files : recording.cloud_files;
    for (; index < files.size() && given < limit; ++index) {
      PointCloudInput cloud;
      try {
        cloud = readCloudFile(files[index], fileStamp(recording, index));
      } catch (const std::runtime_error& error) {  // the readers' format errors, and files that cannot be opened
        failed(std::current_exception(), fs::path(files[index]).filename().string(), error.what());
        continue;
      }
      ++given;
      if (!on_cloud(cloud, index)) break;
    }
  }
  if (given == 0 && first_error) std::rethrow_exception(first_error);
  return given;
}

}  // namespace

std::size_t forEachCloud(const Recording& recording, const std::function<bool(const PointCloudInput&)>& on_cloud,
                         RecordingStatistics* statistics) {
  return forEachIndexedCloud(
      recording, [&](const PointCloudInput& cloud, std::size_t) { return on_cloud(cloud); }, statistics);
}

std::size_t forEachScan(const Recording& recording, const std::function<bool(const RangeImage&)>& on_scan,
                        RecordingStatistics* statistics) {
  const std::size_t limit = recording.frames > 0 ? std::size_t(recording.frames) : SIZE_MAX;
  std::size_t given = 0;
  if (limit == 0) return 0;
  if (!isPointCloudRecording(recording.kind)) {
    RangeImage image;
    bool stopped = false;
    const auto emit = [&](const LidarScan& scan) {
      if (stopped) return;
      toRangeImage(scan, recording.model, ReturnIndex::kFirst, image);
      ++given;
      if (statistics) ++statistics->scans;
      stopped = !on_scan(image) || given >= limit;
    };
    if (recording.kind == RecordingKind::kOusterCapture) {
      const OusterPcapStatistics packets = readOusterScans(recording.pcap, *recording.ouster, emit, &stopped);
      if (statistics) {
        statistics->pcap = packets.pcap;
        statistics->packets = packets.batcher;
        statistics->stopped_early = packets.pcap.stopped_early;
      }
      return given;
    }
    ScanBatcher batcher(*recording.ouster, emit);
    std::size_t packet_size = 0;
    try {
      BagReader(recording.bag).forEachOusterPacket(recording.topic, [&](const BagPacket& packet) {
        packet_size = packet.size;
        batcher.addPacket(packet.data, packet.size);
        return !stopped;
      });
    } catch (const BagError& error) {
      // Damage after the first scan: what came before it is kept.
      if (!statistics || given == 0) throw;
      statistics->stopped_early = error.what();
    }
    if (!stopped) batcher.flush();
    const BatcherStatistics& packets = batcher.statistics();
    if (statistics) statistics->packets = packets;
    if (given == 0 && packets.wrong_size > 0)
      throw RecordingError("INPUT " + recording.input + ": the " + std::to_string(packets.wrong_size) +
                           " packets on " + recording.topic + " (" + std::to_string(packet_size) +
                           " bytes) are not the metadata's lidar packets (" +
                           std::to_string(batcher.format().packetSize()) +
                           " bytes): an IMU topic, or metadata of another sensor or mode?");
    return given;
  }
  if (!recording.model) throw RecordingError("INPUT " + recording.input + " was opened without a sensor model");
  const std::vector<int>& ring_to_row = recording.model_info.ring_to_row;
  forEachIndexedCloud(
      recording,
      [&](const PointCloudInput& cloud, std::size_t frame) {
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
      },
      statistics);
  return given;
}

std::string readingLossWarning(const RecordingStatistics& statistics) {
  std::string warning;
  const auto add = [&](const std::string& sentence) { warning += (warning.empty() ? "" : " ") + sentence; };
  if (statistics.unreadable > 0) {
    std::string examples;
    for (const std::string& example : statistics.unreadable_examples)
      examples += (examples.empty() ? "" : "; ") + example;
    add(std::to_string(statistics.unreadable) + " scan" + (statistics.unreadable == 1 ? "" : "s") +
        " could not be read and " + (statistics.unreadable == 1 ? "was" : "were") + " skipped (" + examples +
        (statistics.unreadable > statistics.unreadable_examples.size() ? "; ..." : "") + "): the results leave " +
        (statistics.unreadable == 1 ? "it" : "them") + " out.");
  }
  if (!statistics.stopped_early.empty())
    add("Reading stopped early, after " + std::to_string(statistics.scans) +
        " scans, at damage in the recording (" + statistics.stopped_early +
        "): the rest of it is not in the results.");
  if (statistics.pcap) {
    const PcapStatistics& pcap = *statistics.pcap;
    if (pcap.skipped_truncated + pcap.skipped_malformed + pcap.fragments_dropped > 0)
      add(std::to_string(pcap.skipped_truncated) + " truncated and " + std::to_string(pcap.skipped_malformed) +
          " malformed records and " + std::to_string(pcap.fragments_dropped) +
          " fragments of incomplete datagrams in the capture were left out (a capture with a snap length "
          "shorter than the packets, or a damaged file).");
  }
  if (statistics.packets) {
    const BatcherStatistics& packets = *statistics.packets;
    const std::size_t dropped = packets.wrong_size + packets.malformed + packets.bad_checksum;
    if (dropped > 0)
      add(std::to_string(dropped) + " lidar packets were dropped (" + std::to_string(packets.wrong_size) +
          " of another size than the metadata's, " + std::to_string(packets.malformed) + " malformed, " +
          std::to_string(packets.bad_checksum) +
          " with a wrong checksum): check that the metadata is this sensor's and mode's.");
    if (packets.incomplete_scans > 0)
      add(std::to_string(packets.incomplete_scans) + " of " + std::to_string(packets.scans) +
          " scans miss columns (" + std::to_string(packets.missing_columns) +
          " in all): packets lost before the recording (network, or a recorder that fell behind)" +
          (statistics.stopped_early.empty() ? "" : ", or the scan the damage cut short") +
          "; those columns are left empty.");
  }
  return warning;
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
