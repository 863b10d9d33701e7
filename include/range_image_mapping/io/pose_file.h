// Trajectory files with time: TUM ("t x y z qx qy qz qw"), KITTI poses with a
// times file and a sidecar stating the frame, and per-column time files. The
// formats evo and the KITTI devkit read, so results can be cross-checked.
#pragma once

#include <Eigen/Geometry>

#include <cstdint>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::io {

// A pose file that is missing or malformed; what() names the file, the line
// and the problem.
class PoseFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// T_world_frame at a time in seconds.
struct StampedPose {
  double time_s = 0.0;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
};

// What a file holds, written into the TUM header or the KITTI sidecar.
struct PoseFileInfo {
  std::string frame = "lidar";  // whose pose: "os_lidar", "os_sensor", "velodyne", ...
  std::string world = "world";  // the fixed frame the poses are expressed in
  std::string comment;          // free text, e.g. the command that wrote the file
};

// TUM RGB-D format: one pose per line, "time tx ty tz qx qy qz qw" (seconds,
// metres, unit quaternion); '#' lines are comments. Written with a '#' header
// naming the frame, and 9 decimals. Reading throws PoseFileError for a line of
// another count, a non-finite number or a quaternion whose norm is not 1
// (within 1e-3; a likely column mix-up), naming the line.
std::vector<StampedPose> readTumPoses(const std::string& path);
void writeTumPoses(const std::string& path, const std::vector<StampedPose>& poses,
                   const PoseFileInfo& info = {});

// KITTI poses (io::writeKittiPoses, 12 numbers per line, no header so the
// devkit and evo read them) with two files next to them:
// - times: one time per line in seconds, like KITTI's times.txt;
// - sidecar: JSON with the format, frame, world, times file name and comment.
struct KittiPoseFilePaths {
  std::string poses;    // dir/name.txt
  std::string times;    // dir/name_times.txt
  std::string sidecar;  // dir/name.txt.json
};
KittiPoseFilePaths kittiPoseFilePaths(const std::string& poses_path);
void writeKittiPosesWithTimes(const std::string& poses_path, const std::vector<StampedPose>& poses,
                              const PoseFileInfo& info = {});
// Reads poses and times (times_path "" = kittiPoseFilePaths(poses_path).times);
// throws PoseFileError when the counts differ or the times file is missing.
std::vector<StampedPose> readKittiPosesWithTimes(const std::string& poses_path,
                                                 const std::string& times_path = "");

// One number per line (seconds); blank lines skipped.
std::vector<double> readTimes(const std::string& path);
void writeTimes(const std::string& path, const std::vector<double>& times_s);

// Either format, told apart by the first data line: 8 numbers TUM, 12 KITTI
// (with its times file, times_path "" = the default name).
std::vector<StampedPose> readPoseFile(const std::string& path, const std::string& times_path = "");

// The poses alone, in order (for the trajectory metrics).
std::vector<Eigen::Isometry3d> posesOf(const std::vector<StampedPose>& stamped);

// The same motion for another frame rigidly attached to this one:
// T_world_new = T_world_frame * T_frame_new, where frame_to_new maps
// coordinates of the frame into the new frame (T_new_frame). E.g. lidar
// poses into Ouster sensor poses with frame_to_new = lidar_to_sensor.
std::vector<StampedPose> changePoseFrame(const std::vector<StampedPose>& poses,
                                         const Eigen::Isometry3d& frame_to_new);

// Per-column times of every scan, written as scans are made: a '#' header,
// then one line per scan with its W column timestamps in integer nanoseconds
// (0 = column not measured), in the image's column order (staggered, column =
// measurement id). With the pose files it gives the time of every pixel.
class ColumnTimesWriter {
 public:
  // Throws PoseFileError when the file cannot be created.
  explicit ColumnTimesWriter(const std::string& path, const PoseFileInfo& info = {});
  // Throws std::invalid_argument when the column count changes between scans.
  void write(const std::vector<uint64_t>& column_timestamps_ns);
  void close();  // throws PoseFileError when writing failed

 private:
  std::string path_;
  std::ofstream file_;
  std::size_t columns_ = 0;
  std::string line_;
};
std::vector<std::vector<uint64_t>> readColumnTimes(const std::string& path);

}  // namespace range_image_mapping::io
