// Recordings the offline tools read (rim odometry, rim map, rim run, rim
// decode): an Ouster capture (pcap + metadata JSON), a ROS 1 bag of Ouster
// packets or of PointCloud2 clouds, a folder of .bin, .pcd or .ply scans, a
// KITTI velodyne folder, or a folder written by rim simulate. Resolves INPUT
// into a sensor model (the Ouster metadata, a sensor file, KITTI's HDL-64E, or
// estimated from the first clouds) and a stream of staggered range images, and
// says where a simulated folder keeps its ground truth.
#pragma once

#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/point_cloud_projection.h"
#include "range_image_mapping/range_image.h"
#include "range_image_mapping/scan_batcher.h"
#include "range_image_mapping/sensor_model_estimation.h"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::io {

// INPUT that is missing or not a recording; what() names the input.
// (Files that exist but are broken throw their reader's error: PcapError,
// MetadataError, KittiFormatError, PcdFormatError, PlyFormatError, BagError,
// PointCloudLayoutError, SensorFileError, PoseFileError.)
class RecordingError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

struct RecordingOptions {
  // A pcap, a folder holding capture.pcap (and metadata.json), a .bag, a
  // folder of *.bin, *.pcd or *.ply scans (or one such file), a KITTI
  // velodyne folder given with kitti, or a folder holding velodyne/ (KITTI).
  std::string input;
  // Ouster metadata JSON of the pcap or packet bag; "" = metadata.json in the
  // INPUT folder, or the bag's metadata topic.
  std::string metadata;
  bool kitti = false;    // read INPUT as a KITTI velodyne folder even if it holds a capture
  // Sensor file (io/sensor_file.h: YAML, or an Ouster metadata JSON) whose
  // model projects the clouds; "" = KITTI's synthetic HDL-64E for a KITTI
  // folder, else a model estimated from the first clouds. An Ouster
  // recording's model is its metadata's: giving one is an error.
  std::string sensor;
  // A bag's topic: a PointCloud2 topic or an Ouster packet topic; "" chooses
  // the only one (Ouster packets first, being exact, when the bag has both).
  std::string topic;
  int frames = 0;               // give only the first N scans (0: all)
  int estimation_scans = 5;     // clouds a model is estimated from (and its fit measured on)
  // false: a point-cloud recording is opened without a model (for reading its
  // clouds only, as rim sensor does); forEachScan then cannot be used.
  bool choose_model = true;
};

enum class RecordingKind {
  kOusterCapture,    // pcap + metadata
  kOusterPacketBag,  // ROS 1 bag of ouster_ros/ouster_sensor_msgs PacketMsg + metadata
  kKittiVelodyne,    // a KITTI velodyne folder of *.bin
  kCloudFiles,       // a folder of *.bin, *.pcd or *.ply scans, or one such file
  kPointCloudBag,    // ROS 1 bag of sensor_msgs/PointCloud2
};

// True for the kinds whose scans are point clouds projected with the model
// (KITTI, cloud files, PointCloud2 bags), false for Ouster packets.
bool isPointCloudRecording(RecordingKind kind);

// Where a recording's model came from and how well it explains the first
// clouds (point-cloud recordings only).
struct RecordingModel {
  std::string source;  // e.g. "estimated from 5 scans", "sensor file s.yaml", "KITTI HDL-64E"
  std::vector<int> ring_to_row;   // the sensor file's or estimate's ring map, if any
  std::optional<SensorModelFit> fit;  // on the first clouds
  std::string summary;            // one line for people: source, size, fit
  std::string warning;            // "" or what is wrong and the fix (fit under 95 %)
};

// What a rim simulate folder holds besides the scans; empty paths where absent
// (and always for a pcap or KITTI folder given directly).
struct RecordingGroundTruth {
  std::string poses;         // poses_kitti.txt, with its _times.txt and .json sidecar
  std::string poses_frame;   // the frame its sidecar states: the images' own (os_lidar, velodyne)
  std::string sensor_poses;  // poses_sensor_kitti.txt: the Ouster sensor frame
  std::string surface;       // surface.ply: samples of the surface the sensor saw
  std::string scene;         // scene.ply: the scene mesh
};

struct Recording {
  RecordingKind kind = RecordingKind::kOusterCapture;
  std::string input;
  std::string description;  // for people, e.g. "OS-0-128 1024x10 scans in DIR/capture.pcap"
  LidarModelConstPtr model;
  std::optional<OusterMetadata> ouster;  // Ouster kinds only
  RecordingModel model_info;
  std::string pcap;                      // Ouster capture
  std::string bag;                       // bag kinds
  std::string topic;                     // bag kinds: the topic read
  std::vector<std::string> velodyne_files;          // KITTI, sorted
  std::vector<std::string> cloud_files;             // cloud files (.bin, .pcd or .ply), sorted
  std::vector<std::vector<uint64_t>> column_times;  // rim simulate's column_times.txt, if any
  std::vector<double> times_s;                      // KITTI or cloud files: times.txt, if any
  std::string frame;  // the images' frame: os_lidar, velodyne, a bag's frame_id, or "lidar"
  int frames = 0;                                   // RecordingOptions::frames
  int expected_frames = 0;                          // scans forEachScan will give; 0: unknown (a pcap)
  RecordingGroundTruth ground_truth;
};

// Throws RecordingError naming INPUT when it does not exist, is none of the
// kinds above, is a pcap without metadata, or a model cannot be estimated
// from its clouds; the readers' errors for files that cannot be read.
Recording openRecording(const RecordingOptions& options);

// What reading a recording gave and lost, over the scans given.
struct RecordingStatistics {
  ProjectionStatistics projection;  // point-cloud recordings
  std::size_t scans = 0;
  // Point-cloud recordings: clouds that could not be read (a malformed file or
  // message), skipped; the first kUnreadableExamples of them as "name: reason".
  static constexpr std::size_t kUnreadableExamples = 5;
  std::size_t unreadable = 0;
  std::vector<std::string> unreadable_examples;
  // Ouster recordings: what the capture's records held (pcap only) and what
  // the batcher made of the packets (dropped, scans with columns missing).
  std::optional<PcapStatistics> pcap;
  std::optional<BatcherStatistics> packets;
  // Reading ended before the recording did (a capture or bag damaged or cut
  // off mid-record): why. The scans before it were given.
  std::string stopped_early;
};

// "" when reading lost nothing; else one sentence per loss, what was lost and
// what to check, for rim's warnings and reports.
std::string readingLossWarning(const RecordingStatistics& statistics);

// Calls on_scan with each scan in order (the image is reused between calls)
// until it returns false or `frames` scans were given; returns how many were
// given. Point clouds are projected with the recording's model (through its
// ring map when the cloud has rings), stamped from their points' times, else
// the bag's header stamps, else times.txt (or 10 Hz); in a rim simulate
// folder they get their column times so they can be deskewed. statistics,
// when given, sums what the projections kept and lost and what reading lost:
// then a cloud that cannot be read is skipped and counted (its image's
// frame_id stays its place in the recording), and a recording damaged after
// its first scan ends early with the scans before the damage given; without
// it they throw the reader's error. A recording none of whose clouds can be
// read throws the first one's error either way.
std::size_t forEachScan(const Recording& recording, const std::function<bool(const RangeImage&)>& on_scan,
                        RecordingStatistics* statistics = nullptr);

// The clouds of a point-cloud recording, in order and stamped as forEachScan
// stamps them, until on_cloud returns false or `frames` were given; what
// cannot be read as forEachScan says. Throws RecordingError for an Ouster
// recording.
std::size_t forEachCloud(const Recording& recording, const std::function<bool(const PointCloudInput&)>& on_cloud,
                         RecordingStatistics* statistics = nullptr);

// The frame a pose file says it holds: its KITTI sidecar's "frame", or a TUM
// "# frame: ..." header line; "" when it says nothing.
std::string poseFileFrame(const std::string& poses_path);

}  // namespace range_image_mapping::io
