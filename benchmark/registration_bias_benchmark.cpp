// Where two scans' registration settles when it starts at the true pose
// (issue 14, the sparse sensors' roll and pitch drift): every consecutive
// pair of scans of a simulated drive registered frame to frame with
// ProjectiveIcp at full resolution only (no pyramid, no deskew, no local
// model), from the ground-truth relative pose. An unbiased registration ends
// where it started, up to the noise; what it ends off on average is a bias
// every odometry step inherits. Also counts the pixels with a normal and of
// them the ground-like ones (normal within 25 deg of the vertical), which
// the depth-jump test of the normal map rejects on sparse beams.
//
// Inputs must be distortion-free (each scan cast from one pose), e.g.
//   rim simulate --preset outdoor_vlp16 --no-motion-distortion --frames 60 --out DIR
// DIR/clouds is read as rim reads it (the model estimated from the clouds),
// DIR/poses_kitti.txt is the ground truth.
//
// Usage: registration_bias_benchmark [--frames N] [--max-range-jump-ratio R]
//          [--kernel-scale M] DIR [DIR...]
#include "command_line.h"
#include "machine_info.h"
#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/io/recording.h"
#include "range_image_mapping/registration/projective_icp.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <stdexcept>
#include <filesystem>
#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

namespace fs = std::filesystem;

struct Options {
  int frames = 60;
  registration::RegistrationOptions registration;
  std::vector<std::string> directories;
};

// Small rotations: the rotation vector's components are roll, pitch, yaw.
struct Sums {
  Eigen::Vector3d rotation_deg = Eigen::Vector3d::Zero(), rotation_squared = Eigen::Vector3d::Zero();
  Eigen::Vector3d translation_cm = Eigen::Vector3d::Zero();
  double normals = 0.0, ground_normals = 0.0, pixels = 0.0;
  int pairs = 0;
};

void measure(const std::string& directory, const Options& options) {
  io::RecordingOptions recording_options;
  recording_options.input = (fs::path(directory) / "clouds").string();
  recording_options.frames = options.frames;
  const io::Recording recording = io::openRecording(recording_options);
  std::vector<RangeImage> scans;
  io::forEachScan(recording, [&](const RangeImage& scan) {
    scans.push_back(scan.column_order == ColumnOrder::kStaggered ? scan : scan.staggered());
    return true;
  });
  const std::vector<Eigen::Isometry3d> truth =
      io::posesOf(io::readPoseFile((fs::path(directory) / "poses_kitti.txt").string()));
  if (truth.size() < scans.size())
    throw std::runtime_error(directory + ": " + std::to_string(truth.size()) + " poses for " +
                             std::to_string(scans.size()) + " scans");

  registration::RegistrationOptions registration = options.registration;
  registration.strides = {1};
  registration.iterations = {30};
  registration::ProjectiveIcp icp(registration);
  constexpr double kGroundCosine = 0.906;  // 25 deg
  Sums sums;
  VertexNormalMap source;
  for (std::size_t i = 1; i < scans.size(); ++i) {
    icp.setTarget(scans[i - 1]);
    computeVertexNormalMap(scans[i], 1, registration.normals, source);
    for (const Eigen::Vector3f& normal : source.normals) {
      sums.pixels += 1.0;
      if (!normal.allFinite()) continue;
      sums.normals += 1.0;
      sums.ground_normals += std::abs(normal.z()) > kGroundCosine;
    }
    const Eigen::Isometry3d target_from_source = truth[i - 1].inverse() * truth[i];
    const registration::RegistrationResult result = icp.align(source, target_from_source);
    const Eigen::Isometry3d error = target_from_source.inverse() * result.target_from_source;
    const Eigen::AngleAxisd rotation(error.linear());
    const Eigen::Vector3d rotation_deg = rotation.angle() * rotation.axis() * 180.0 / M_PI;
    sums.rotation_deg += rotation_deg;
    sums.rotation_squared += rotation_deg.cwiseAbs2();
    sums.translation_cm += 100.0 * error.translation();
    ++sums.pairs;
  }
  if (sums.pairs == 0) throw std::runtime_error(directory + ": fewer than two scans");
  const double n = sums.pairs;
  const Eigen::Vector3d mean = sums.rotation_deg / n;
  const Eigen::Vector3d rms = (sums.rotation_squared / n).cwiseSqrt();
  const Eigen::Vector3d translation = sums.translation_cm / n;
  std::printf("| %s | %s | %d | %+.4f / %.4f | %+.4f / %.4f | %+.4f / %.4f | %+.2f %+.2f %+.2f | %.1f %% | %.0f |\n",
              directory.c_str(),
              (std::to_string(recording.model->rows()) + " x " + std::to_string(recording.model->columns())).c_str(),
              sums.pairs, mean.x(), rms.x(), mean.y(), rms.y(), mean.z(), rms.z(), translation.x(), translation.y(),
              translation.z(), 100.0 * sums.normals / sums.pixels, sums.ground_normals / n);
}

int run(int argc, char** argv) {
  Options options;
  for (benchmark_support::ArgumentCursor arguments(argc, argv); arguments.next();) {
    const std::string argument = arguments.name();
    if (argument == "--frames")
      options.frames = arguments.integer();
    else if (argument == "--max-range-jump-ratio")
      options.registration.normals.max_range_jump_ratio = float(arguments.number());
    else if (argument == "--kernel-scale")
      options.registration.kernel.scale_m = arguments.number();
    else if (!argument.empty() && argument[0] == '-')
      throw std::invalid_argument("unknown option " + argument);
    else
      options.directories.push_back(argument);
  }
  if (options.directories.empty() || options.frames < 2) {
    std::fprintf(stderr,
                 "Usage: %s [--frames N (>= 2)] [--max-range-jump-ratio R] [--kernel-scale M] DIR [DIR...]\n"
                 "  DIR: rim simulate --preset P --no-motion-distortion --out DIR (DIR/clouds, DIR/poses_kitti.txt)\n",
                 argv[0]);
    return 2;
  }
  std::printf("registration_bias_benchmark: frame-to-frame ProjectiveIcp at stride 1 from the true pose\n"
              "machine: %s, load %s; %s\n",
              benchmark_support::cpuModel().c_str(), benchmark_support::loadAverage().c_str(),
              benchmark_support::now().c_str());
  std::printf("normals: jump ratio %.2f; kernel %.2f m, gate %.2f m; %d scans per drive (distortion-free inputs "
              "assumed, not checkable from the files)\n",
              options.registration.normals.max_range_jump_ratio, options.registration.kernel.scale_m,
              options.registration.correspondenceDistance(), options.frames);
  std::printf("| drive | model (estimated) | pairs | roll deg mean / RMS | pitch deg mean / RMS | yaw deg mean / RMS | "
              "translation cm (x y z) mean | pixels with a normal | ground-like normals per scan |\n"
              "|---|---|---|---|---|---|---|---|---|\n");
  for (const std::string& directory : options.directories) measure(directory, options);
  return 0;
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  try {
    return range_image_mapping::run(argc, argv);
  } catch (const std::exception& error) {
    std::fprintf(stderr, "registration_bias_benchmark: %s\n", error.what());
    return 1;
  }
}
