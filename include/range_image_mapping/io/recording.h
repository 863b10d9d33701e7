// Recordings the offline tools read (rim odometry, rim map, rim run): an
// Ouster capture (pcap + metadata JSON), a KITTI velodyne folder, or a folder
// written by rim simulate. Resolves INPUT into a sensor model and a stream of
// staggered range images, and says where a simulated folder keeps its ground
// truth.
#pragma once

#include "range_image_mapping/ouster_metadata.h"
#include "range_image_mapping/range_image.h"

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
// MetadataError, KittiFormatError, PoseFileError.)
class RecordingError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

struct RecordingOptions {
  // A pcap, a folder holding capture.pcap (and metadata.json), a KITTI
  // velodyne folder of *.bin scans, or a folder holding velodyne/.
  std::string input;
  std::string metadata;  // Ouster metadata JSON of the pcap; "" = metadata.json in the INPUT folder
  bool kitti = false;    // read INPUT as a KITTI velodyne folder even if it holds a capture
  // Sensor file (io/sensor_file.h: YAML, or an Ouster metadata JSON) whose
  // model projects a KITTI folder's clouds; "" = the synthetic HDL-64E. An
  // Ouster capture's model is its metadata's: giving one is an error.
  std::string sensor;
  int frames = 0;        // give only the first N scans (0: all)
};

enum class RecordingKind { kOusterCapture, kKittiVelodyne };

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
  std::optional<OusterMetadata> ouster;  // absent for KITTI folders
  std::string pcap;                      // Ouster
  std::vector<std::string> velodyne_files;          // KITTI, sorted
  std::vector<std::vector<uint64_t>> column_times;  // rim simulate's column_times.txt, if any
  std::vector<double> times_s;                      // KITTI times.txt, if any
  std::string frame;                                // the images' frame: os_lidar or velodyne
  int frames = 0;                                   // RecordingOptions::frames
  int expected_frames = 0;                          // scans forEachScan will give; 0: unknown (a pcap)
  RecordingGroundTruth ground_truth;
};

// Throws RecordingError naming INPUT when it does not exist, is none of the
// kinds above, or is a pcap without metadata; the readers' errors for
// metadata or time files that cannot be read.
Recording openRecording(const RecordingOptions& options);

// Calls on_scan with each scan in order (the image is reused between calls)
// until it returns false or `frames` scans were given; returns how many were
// given. KITTI scans are projected with the sensor file's model (default:
// the synthetic HDL-64E model), stamped
// from times.txt (or 10 Hz) and, in a rim simulate folder, given their column
// times so they can be deskewed.
std::size_t forEachScan(const Recording& recording, const std::function<bool(const RangeImage&)>& on_scan);

// The frame a pose file says it holds: its KITTI sidecar's "frame", or a TUM
// "# frame: ..." header line; "" when it says nothing.
std::string poseFileFrame(const std::string& poses_path);

}  // namespace range_image_mapping::io
