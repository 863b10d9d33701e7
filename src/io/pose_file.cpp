#include "range_image_mapping/io/pose_file.h"

#include "range_image_mapping/io/kitti.h"

#include <json/json.h>

#include <charconv>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <sstream>

namespace range_image_mapping::io {
namespace {

constexpr int kTumNumbers = 8;
constexpr int kKittiNumbers = 12;
constexpr double kQuaternionNormTolerance = 1e-3;

std::ifstream openForReading(const std::string& path) {
  std::ifstream file(path);
  if (!file) throw PoseFileError("pose file: cannot open " + path);
  return file;
}

std::ofstream openForWriting(const std::string& path) {
  std::ofstream file(path);
  if (!file) throw PoseFileError("pose file: cannot write " + path);
  return file;
}

void finishWriting(std::ofstream& file, const std::string& path) {
  if (!file.flush()) throw PoseFileError("pose file: writing " + path + " failed");
}

bool isBlankOrComment(const std::string& line) {
  const std::size_t first = line.find_first_not_of(" \t\r");
  return first == std::string::npos || line[first] == '#';
}

// The numbers of a line; false when a word is not a finite number.
bool parseNumbers(const std::string& line, std::vector<double>& numbers) {
  numbers.clear();
  std::istringstream words(line);
  std::string word;
  while (words >> word) {
    std::istringstream parser(word);
    double value;
    if (!(parser >> value) || !parser.eof() || !std::isfinite(value)) return false;
    numbers.push_back(value);
  }
  return true;
}

// Calls on_line(numbers, line_number) for every data line while it returns true.
template <typename OnLine>
void forEachDataLine(const std::string& path, const OnLine& on_line) {
  std::ifstream file = openForReading(path);
  std::string line;
  std::vector<double> numbers;
  for (int line_number = 1; std::getline(file, line); ++line_number) {
    if (isBlankOrComment(line)) continue;
    if (!parseNumbers(line, numbers))
      throw PoseFileError("pose file: " + path + " line " + std::to_string(line_number) +
                          " holds something other than finite numbers");
    if (!on_line(numbers, line_number)) return;
  }
}

std::string headerLine(const std::string& label, const std::string& value) {
  return value.empty() ? "" : "# " + label + ": " + value + "\n";
}

}  // namespace

std::vector<StampedPose> readTumPoses(const std::string& path) {
  std::vector<StampedPose> poses;
  forEachDataLine(path, [&](const std::vector<double>& n, int line_number) {
    const auto fail = [&](const std::string& problem) {
      throw PoseFileError("TUM poses: " + path + " line " + std::to_string(line_number) + " " +
                          problem);
    };
    if (n.size() != kTumNumbers)
      fail("has " + std::to_string(n.size()) + " numbers, not 8 (time tx ty tz qx qy qz qw)");
    const Eigen::Quaterniond rotation(n[7], n[4], n[5], n[6]);
    if (std::abs(rotation.norm() - 1.0) > kQuaternionNormTolerance)
      fail("has a quaternion of norm " + std::to_string(rotation.norm()) +
           ", not 1: the order is qx qy qz qw");
    StampedPose stamped;
    stamped.time_s = n[0];
    stamped.pose.linear() = rotation.normalized().toRotationMatrix();
    stamped.pose.translation() = Eigen::Vector3d(n[1], n[2], n[3]);
    poses.push_back(stamped);
    return true;
  });
  return poses;
}

void writeTumPoses(const std::string& path, const std::vector<StampedPose>& poses,
                   const PoseFileInfo& info) {
  std::ofstream file = openForWriting(path);
  file << "# TUM trajectory: time tx ty tz qx qy qz qw (seconds, metres), pose T_" << info.world
       << "_" << info.frame << " of frame " << info.frame << " in " << info.world << "\n"
       << headerLine("frame", info.frame) << headerLine("world", info.world)
       << headerLine("comment", info.comment);
  file << std::fixed << std::setprecision(12);
  for (const StampedPose& stamped : poses) {
    const Eigen::Quaterniond rotation(stamped.pose.rotation());
    const Eigen::Vector3d& t = stamped.pose.translation();
    file << stamped.time_s << ' ' << t.x() << ' ' << t.y() << ' ' << t.z() << ' ' << rotation.x()
         << ' ' << rotation.y() << ' ' << rotation.z() << ' ' << rotation.w() << '\n';
  }
  finishWriting(file, path);
}

KittiPoseFilePaths kittiPoseFilePaths(const std::string& poses_path) {
  const std::filesystem::path path(poses_path);
  std::filesystem::path times = path;
  times.replace_filename(path.stem().string() + "_times.txt");
  return {poses_path, times.string(), poses_path + ".json"};
}

void writeKittiPosesWithTimes(const std::string& poses_path, const std::vector<StampedPose>& poses,
                              const PoseFileInfo& info) {
  const KittiPoseFilePaths paths = kittiPoseFilePaths(poses_path);
  std::vector<Eigen::Isometry3d> matrices;
  std::vector<double> times;
  for (const StampedPose& stamped : poses) {
    matrices.push_back(stamped.pose);
    times.push_back(stamped.time_s);
  }
  writeKittiPoses(paths.poses, matrices);
  writeTimes(paths.times, times);

  Json::Value sidecar;
  sidecar["format"] = "KITTI odometry poses: one line per scan, row-major 3x4 [R | t] of T_" +
                      info.world + "_" + info.frame + " (metres)";
  sidecar["frame"] = info.frame;
  sidecar["world"] = info.world;
  sidecar["times_file"] = std::filesystem::path(paths.times).filename().string();
  sidecar["time_unit"] = "s";
  sidecar["poses"] = Json::UInt64(poses.size());
  if (!info.comment.empty()) sidecar["comment"] = info.comment;
  std::ofstream file = openForWriting(paths.sidecar);
  file << sidecar.toStyledString();
  finishWriting(file, paths.sidecar);
}

std::vector<StampedPose> readKittiPosesWithTimes(const std::string& poses_path,
                                                 const std::string& times_path) {
  const std::string times_file = times_path.empty() ? kittiPoseFilePaths(poses_path).times : times_path;
  if (!std::filesystem::exists(times_file))
    throw PoseFileError("KITTI poses: " + poses_path + " has no times file " + times_file);
  std::vector<Eigen::Isometry3d> matrices;
  try {
    matrices = readKittiPoses(poses_path);
  } catch (const KittiFormatError& error) {
    throw PoseFileError(error.what());
  }
  const std::vector<double> times = readTimes(times_file);
  if (times.size() != matrices.size())
    throw PoseFileError("KITTI poses: " + poses_path + " holds " + std::to_string(matrices.size()) +
                        " poses, its times file " + times_file + " " +
                        std::to_string(times.size()) + " times");
  std::vector<StampedPose> poses(matrices.size());
  for (std::size_t i = 0; i < poses.size(); ++i) poses[i] = {times[i], matrices[i]};
  return poses;
}

std::vector<double> readTimes(const std::string& path) {
  std::vector<double> times;
  forEachDataLine(path, [&](const std::vector<double>& numbers, int line_number) {
    if (numbers.size() != 1)
      throw PoseFileError("times file: " + path + " line " + std::to_string(line_number) +
                          " has " + std::to_string(numbers.size()) + " numbers, not 1");
    times.push_back(numbers[0]);
    return true;
  });
  return times;
}

void writeTimes(const std::string& path, const std::vector<double>& times_s) {
  std::ofstream file = openForWriting(path);
  file << std::fixed << std::setprecision(12);
  for (const double time : times_s) file << time << '\n';
  finishWriting(file, path);
}

std::vector<StampedPose> readPoseFile(const std::string& path, const std::string& times_path) {
  std::size_t count = 0;
  int first_line = 0;
  forEachDataLine(path, [&](const std::vector<double>& numbers, int line_number) {
    count = numbers.size();
    first_line = line_number;
    return false;  // the first data line decides
  });
  if (first_line == 0) throw PoseFileError("pose file: " + path + " holds no poses");
  if (count == kTumNumbers) return readTumPoses(path);
  if (count == kKittiNumbers) return readKittiPosesWithTimes(path, times_path);
  throw PoseFileError("pose file: " + path + " line " + std::to_string(first_line) + " has " +
                      std::to_string(count) +
                      " numbers: neither TUM (8: time tx ty tz qx qy qz qw) nor KITTI (12: 3x4)");
}

std::vector<StampedPose> changePoseFrame(const std::vector<StampedPose>& poses,
                                         const Eigen::Isometry3d& frame_to_new) {
  const Eigen::Isometry3d new_to_frame = frame_to_new.inverse();
  std::vector<StampedPose> changed = poses;
  for (StampedPose& stamped : changed) stamped.pose = stamped.pose * new_to_frame;
  return changed;
}

ColumnTimesWriter::ColumnTimesWriter(const std::string& path, const PoseFileInfo& info)
    : path_(path), file_(openForWriting(path)) {
  file_ << "# column times: one line per scan, the timestamp of every column in nanoseconds "
           "(0 = not measured), staggered column order (column = measurement id)\n"
        << headerLine("frame", info.frame) << headerLine("comment", info.comment);
}

void ColumnTimesWriter::write(const std::vector<uint64_t>& column_timestamps_ns) {
  if (columns_ == 0) columns_ = column_timestamps_ns.size();
  if (column_timestamps_ns.size() != columns_ || columns_ == 0)
    throw std::invalid_argument("ColumnTimesWriter: a scan of " +
                                std::to_string(column_timestamps_ns.size()) +
                                " columns after scans of " + std::to_string(columns_));
  line_.clear();
  char number[24];
  for (std::size_t i = 0; i < column_timestamps_ns.size(); ++i) {
    if (i > 0) line_.push_back(' ');
    const auto end = std::to_chars(number, number + sizeof(number), column_timestamps_ns[i]).ptr;
    line_.append(number, end);
  }
  line_.push_back('\n');
  file_ << line_;
}

void ColumnTimesWriter::close() {
  if (!file_.is_open()) return;
  finishWriting(file_, path_);
  file_.close();
}

std::vector<std::vector<uint64_t>> readColumnTimes(const std::string& path) {
  std::ifstream file = openForReading(path);
  std::vector<std::vector<uint64_t>> scans;
  std::string line;
  for (int line_number = 1; std::getline(file, line); ++line_number) {
    if (isBlankOrComment(line)) continue;
    std::vector<uint64_t>& times = scans.emplace_back();
    const char* cursor = line.data();
    const char* const end = line.data() + line.size();
    while (true) {
      while (cursor < end && (*cursor == ' ' || *cursor == '\t' || *cursor == '\r')) ++cursor;
      if (cursor == end) break;
      uint64_t value = 0;
      const auto [next, error] = std::from_chars(cursor, end, value);
      if (error != std::errc() || (next < end && *next != ' ' && *next != '\t' && *next != '\r'))
        throw PoseFileError("column times: " + path + " line " + std::to_string(line_number) +
                            " holds something other than non-negative integers");
      times.push_back(value);
      cursor = next;
    }
    if (times.size() != scans.front().size())
      throw PoseFileError("column times: " + path + " line " + std::to_string(line_number) +
                          " has " + std::to_string(times.size()) + " columns, the first scan " +
                          std::to_string(scans.front().size()));
  }
  return scans;
}

std::vector<Eigen::Isometry3d> posesOf(const std::vector<StampedPose>& stamped) {
  std::vector<Eigen::Isometry3d> poses;
  poses.reserve(stamped.size());
  for (const StampedPose& pose : stamped) poses.push_back(pose.pose);
  return poses;
}

}  // namespace range_image_mapping::io
