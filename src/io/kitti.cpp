#include "range_image_mapping/io/kitti.h"

#include "../sensor/little_endian.h"

#include <cmath>
#include <fstream>
#include <iomanip>
#include <iterator>
#include <sstream>

namespace range_image_mapping::io {
namespace {

constexpr std::size_t kBytesPerVelodynePoint = 4 * sizeof(float);

std::ifstream openForReading(const std::string& path, std::ios::openmode mode = std::ios::in) {
  std::ifstream file(path, mode);
  if (!file) throw KittiFormatError("KITTI: cannot open " + path);
  return file;
}

// Twelve numbers, row-major 3x4 [R | t]. Returns false for a count other than 12.
bool parsePose(std::istream& numbers, Eigen::Isometry3d& pose) {
  Eigen::Matrix<double, 3, 4> matrix;
  for (int i = 0; i < 12; ++i)
    if (!(numbers >> matrix(i / 4, i % 4))) return false;
  std::string extra;
  if (numbers >> extra) return false;
  if (!matrix.allFinite()) return false;
  pose.setIdentity();
  pose.matrix().topRows<3>() = matrix;
  return true;
}

bool isBlank(const std::string& line) {
  return line.find_first_not_of(" \t\r") == std::string::npos;
}

}  // namespace

PointCloudInput readKittiVelodyne(const std::string& path) {
  std::ifstream file = openForReading(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  if (bytes.size() % kBytesPerVelodynePoint != 0)
    throw KittiFormatError("KITTI: " + path + " has " + std::to_string(bytes.size()) +
                           " bytes, not a multiple of 16 (float32 x, y, z, reflectance)");
  const std::size_t count = bytes.size() / kBytesPerVelodynePoint;
  PointCloudInput cloud;
  cloud.points.resize(count);
  cloud.intensity.resize(count);
  cloud.intensity_field = "reflectance";
  cloud.organized_width = static_cast<int>(count);
  for (std::size_t i = 0; i < count; ++i) {
    const char* point = bytes.data() + i * kBytesPerVelodynePoint;
    cloud.points[i] =
        Eigen::Vector3f(readLittleEndian<float>(point), readLittleEndian<float>(point + 4),
                        readLittleEndian<float>(point + 8));
    cloud.intensity[i] = readLittleEndian<float>(point + 12);
  }
  return cloud;
}

void writeKittiVelodyne(const std::string& path, const std::vector<Eigen::Vector3f>& points,
                        const std::vector<float>& intensities) {
  if (!intensities.empty() && intensities.size() != points.size())
    throw std::invalid_argument("writeKittiVelodyne: " + std::to_string(intensities.size()) +
                                " intensities for " + std::to_string(points.size()) + " points");
  std::string bytes;
  bytes.reserve(points.size() * kBytesPerVelodynePoint);
  for (std::size_t i = 0; i < points.size(); ++i) {
    for (int axis = 0; axis < 3; ++axis) appendLittleEndian<float>(bytes, points[i][axis]);
    appendLittleEndian<float>(bytes, intensities.empty() ? 0.0f : intensities[i]);
  }
  std::ofstream file(path, std::ios::binary);
  if (!file) throw KittiFormatError("KITTI: cannot write " + path);
  file.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!file.flush()) throw KittiFormatError("KITTI: writing " + path + " failed");
}

std::vector<Eigen::Isometry3d> readKittiPoses(const std::string& path) {
  std::ifstream file = openForReading(path);
  std::vector<Eigen::Isometry3d> poses;
  std::string line;
  for (int line_number = 1; std::getline(file, line); ++line_number) {
    if (isBlank(line)) continue;
    std::istringstream numbers(line);
    Eigen::Isometry3d pose;
    if (!parsePose(numbers, pose))
      throw KittiFormatError("KITTI poses: " + path + " line " + std::to_string(line_number) +
                             " does not hold 12 finite numbers (row-major 3x4)");
    poses.push_back(pose);
  }
  return poses;
}

void writeKittiPoses(const std::string& path, const std::vector<Eigen::Isometry3d>& poses) {
  std::ofstream file(path);
  if (!file) throw KittiFormatError("KITTI poses: cannot write " + path);
  file << std::setprecision(9) << std::scientific;
  for (const Eigen::Isometry3d& pose : poses) {
    for (int i = 0; i < 12; ++i) file << (i ? " " : "") << pose.matrix()(i / 4, i % 4);
    file << '\n';
  }
  if (!file) throw KittiFormatError("KITTI poses: writing " + path + " failed");
}

Eigen::Isometry3d readKittiVelodyneToCamera(const std::string& calibration_path) {
  std::ifstream file = openForReading(calibration_path);
  std::string line;
  while (std::getline(file, line)) {
    if (line.rfind("Tr:", 0) != 0) continue;
    std::istringstream numbers(line.substr(3));
    Eigen::Isometry3d velodyne_to_camera;
    if (!parsePose(numbers, velodyne_to_camera))
      throw KittiFormatError("KITTI calibration: " + calibration_path +
                             ": the Tr: line does not hold 12 finite numbers");
    return velodyne_to_camera;
  }
  throw KittiFormatError("KITTI calibration: " + calibration_path + " has no Tr: line");
}

Eigen::Isometry3d velodynePoseFromCameraPose(const Eigen::Isometry3d& camera_pose,
                                             const Eigen::Isometry3d& velodyne_to_camera) {
  return velodyne_to_camera.inverse() * camera_pose * velodyne_to_camera;
}

std::vector<Eigen::Isometry3d> velodynePosesFromCameraPoses(
    const std::vector<Eigen::Isometry3d>& camera_poses,
    const Eigen::Isometry3d& velodyne_to_camera) {
  std::vector<Eigen::Isometry3d> velodyne_poses;
  velodyne_poses.reserve(camera_poses.size());
  for (const Eigen::Isometry3d& camera_pose : camera_poses)
    velodyne_poses.push_back(velodynePoseFromCameraPose(camera_pose, velodyne_to_camera));
  return velodyne_poses;
}

}  // namespace range_image_mapping::io
