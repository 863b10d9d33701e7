// rim odometry: LiDAR odometry over a recording (an Ouster pcap with its
// metadata, a KITTI velodyne folder, or a folder written by rim simulate),
// written as KITTI and TUM poses plus per-frame statistics.
#include "commands.h"
#include "progress.h"

#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pcap_reader.h"
#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/ouster_packet.h"
#include "range_image_mapping/registration/lidar_odometry.h"

#include <json/json.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <iostream>
#include <memory>
#include <optional>

namespace range_image_mapping::tool {
namespace {

namespace fs = std::filesystem;

struct OdometryCommandOptions {
  std::string input;
  std::string output;  // KITTI poses; the other files are named after it
  std::string metadata;
  bool kitti = false;
  int frames = 0;  // 0: all
  bool no_deskew = false;
  double kernel_scale_m = 0.5;
  double keyframe_distance_m = 0.0;
  double keyframe_angle_deg = 0.0;
  std::string frame = "lidar";
};

// Where the scans come from, resolved from INPUT and the options.
struct Recording {
  std::string description;
  LidarModelConstPtr model;
  std::optional<OusterMetadata> ouster;  // absent for KITTI folders
  std::string pcap;                      // Ouster
  std::vector<fs::path> velodyne_files;  // KITTI, sorted
  std::vector<std::vector<uint64_t>> column_times;  // rim simulate's column_times.txt, if any
  std::vector<double> times_s;                      // KITTI times.txt, if any
  std::string frame;                                // os_lidar or velodyne
  int expected_frames = 0;                          // 0: unknown
};

std::vector<fs::path> velodyneFiles(const fs::path& directory) {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(directory))
    if (entry.is_regular_file() && entry.path().extension() == ".bin") files.push_back(entry.path());
  std::sort(files.begin(), files.end());
  return files;
}

Recording openRecording(const OdometryCommandOptions& options) {
  Recording recording;
  const fs::path input(options.input);
  if (!fs::exists(input)) throw std::invalid_argument("INPUT " + options.input + " does not exist");
  fs::path sequence = input;  // the folder that may hold column_times.txt / times.txt
  const bool has_velodyne = fs::is_directory(input / "velodyne");
  if (fs::is_directory(input) && (options.kitti || (has_velodyne && !fs::exists(input / "capture.pcap")))) {
    const fs::path folder = has_velodyne ? input / "velodyne" : input;
    recording.velodyne_files = velodyneFiles(folder);
    if (recording.velodyne_files.empty())
      throw std::invalid_argument("no KITTI scans (*.bin) in " + folder.string());
    if (!has_velodyne) sequence = input.parent_path();
    recording.model = std::make_shared<const LidarModel>(io::kittiHdl64Intrinsics());
    recording.frame = "velodyne";
    recording.description = std::to_string(recording.velodyne_files.size()) + " KITTI scans in " + folder.string();
    recording.expected_frames = int(recording.velodyne_files.size());
    if (fs::exists(sequence / "times.txt")) recording.times_s = io::readTimes((sequence / "times.txt").string());
  } else {
    if (options.kitti) throw std::invalid_argument("--kitti: INPUT " + options.input + " is not a folder");
    const fs::path pcap = fs::is_directory(input) ? input / "capture.pcap" : input;
    if (!fs::exists(pcap))
      throw std::invalid_argument("INPUT " + options.input +
                                  ": neither a pcap, a folder with capture.pcap, nor a KITTI velodyne folder");
    fs::path metadata = options.metadata;
    if (metadata.empty() && fs::is_directory(input)) metadata = input / "metadata.json";
    if (metadata.empty() || !fs::exists(metadata))
      throw std::invalid_argument("the pcap " + pcap.string() + " needs its sensor metadata: give --metadata");
    recording.ouster = loadOusterMetadata(metadata.string());
    recording.model = std::make_shared<const LidarModel>(recording.ouster->intrinsics);
    recording.pcap = pcap.string();
    recording.frame = "os_lidar";
    recording.description = recording.ouster->prod_line + " " + recording.ouster->lidar_mode + " scans in " + pcap.string();
    if (!fs::is_directory(input)) sequence = input.parent_path();
  }
  if (fs::is_directory(input) && fs::exists(sequence / "column_times.txt")) {
    recording.column_times = io::readColumnTimes((sequence / "column_times.txt").string());
    if (recording.expected_frames == 0) recording.expected_frames = int(recording.column_times.size());
  }
  if (options.frames > 0)
    recording.expected_frames =
        recording.expected_frames ? std::min(recording.expected_frames, options.frames) : options.frames;
  return recording;
}

// Calls on_scan for each scan in order until it returns false.
void readScans(const Recording& recording, const std::function<bool(const RangeImage&)>& on_scan) {
  if (!recording.pcap.empty()) {
    struct Stop {};
    RangeImage image;
    try {
      io::readOusterScans(recording.pcap, *recording.ouster, [&](const LidarScan& scan) {
        toRangeImage(scan, recording.model, ReturnIndex::kFirst, image);
        if (!on_scan(image)) throw Stop{};
      });
    } catch (const Stop&) {
    }
    return;
  }
  for (std::size_t frame = 0; frame < recording.velodyne_files.size(); ++frame) {
    PointCloudInput cloud = io::readKittiVelodyne(recording.velodyne_files[frame].string());
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
    if (!on_scan(image)) return;
  }
}

// traj.txt -> traj_<suffix>
std::string siblingPath(const std::string& output, const std::string& suffix) {
  fs::path path(output);
  return (path.parent_path() / (path.stem().string() + "_" + suffix)).string();
}

double median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

int runOdometry(const OdometryCommandOptions& options) {
  const Recording recording = openRecording(options);
  if (options.frame == "sensor" && !recording.ouster)
    throw std::invalid_argument("--frame sensor: KITTI scans have no Ouster sensor frame");

  registration::OdometryOptions odometry_options;
  odometry_options.deskew = !options.no_deskew;
  odometry_options.registration.kernel.scale_m = options.kernel_scale_m;
  odometry_options.keyframe_distance_m = options.keyframe_distance_m;
  odometry_options.keyframe_angle_rad = options.keyframe_angle_deg * M_PI / 180.0;
  registration::LidarOdometry odometry(odometry_options);

  const fs::path output(options.output);
  if (!output.parent_path().empty()) fs::create_directories(output.parent_path());
  const std::string frames_path = siblingPath(options.output, "frames.csv");
  std::ofstream frames_file(frames_path);
  if (!frames_file) throw std::runtime_error("cannot write " + frames_path);
  frames_file << "frame,time_s,seconds,inliers,iterations,condition_number,residual_rms_m,degenerate,reset,"
                 "skipped,warning\n";

  std::cerr << "odometry over " << recording.description << "\n";
  std::vector<io::StampedPose> poses;
  std::vector<double> step_seconds;
  int frames = 0, degenerate = 0, resets = 0, skipped = 0;
  const auto started = std::chrono::steady_clock::now();
  readScans(recording, [&](const RangeImage& scan) {
    const registration::OdometryUpdate update = odometry.process(scan);
    const double time_s = double(update.stamp_ns) * 1e-9;
    if (!update.skipped) poses.push_back({time_s, update.pose});
    step_seconds.push_back(update.seconds);
    degenerate += update.degenerate;
    resets += update.reset && frames > 0;
    skipped += update.skipped;
    std::string warning = update.warning;
    std::replace(warning.begin(), warning.end(), ',', ';');
    frames_file << frames << ',' << std::setprecision(15) << time_s << std::setprecision(6) << ',' << update.seconds
                << ',' << update.inliers << ',' << update.iterations << ',' << update.condition_number << ','
                << update.residual_rms_m << ',' << update.degenerate << ',' << update.reset << ','
                << update.skipped << ',' << warning << '\n';
    if (!update.warning.empty()) std::cerr << "\nwarning: frame " << frames << ": " << update.warning << "\n";
    ++frames;
    showProgress(frames, recording.expected_frames, started);
    return options.frames <= 0 || frames < options.frames;
  });
  if (recording.expected_frames <= 0 || frames != recording.expected_frames) finishProgress();
  frames_file.close();
  if (!frames_file) throw std::runtime_error("cannot write " + frames_path);
  if (frames == 0) throw std::runtime_error("no scans in " + options.input);
  const double total_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();

  io::PoseFileInfo info;
  info.frame = recording.frame;
  info.world = "odom";
  info.comment = "rim odometry " + options.input + (options.no_deskew ? " --no-deskew" : "");
  std::vector<io::StampedPose> written = poses;
  if (options.frame == "sensor") {
    info.frame = "os_sensor";
    written = io::changePoseFrame(poses, recording.ouster->intrinsics.lidar_to_sensor);
  }
  io::writeKittiPosesWithTimes(options.output, written, info);
  const std::string tum_path = siblingPath(options.output, "tum.txt");
  io::writeTumPoses(tum_path, written, info);

  double mean_seconds = 0.0;
  for (double seconds : step_seconds) mean_seconds += seconds / double(step_seconds.size());
  Json::Value summary;
  summary["input"] = options.input;
  summary["frames"] = frames;
  summary["poses"] = Json::UInt64(poses.size());
  summary["degenerate"] = degenerate;
  summary["resets"] = resets;
  summary["skipped"] = skipped;
  summary["deskew"] = !options.no_deskew;
  summary["kernel_scale_m"] = options.kernel_scale_m;
  summary["frame"] = info.frame;
  summary["step_seconds_mean"] = mean_seconds;
  summary["step_seconds_median"] = median(step_seconds);
  summary["step_seconds_max"] = step_seconds.empty() ? 0.0 : *std::max_element(step_seconds.begin(), step_seconds.end());
  summary["steps_per_second"] = mean_seconds > 0 ? 1.0 / mean_seconds : 0.0;
  summary["wall_seconds"] = total_seconds;
  summary["poses_kitti"] = options.output;
  summary["poses_tum"] = tum_path;
  summary["frames_csv"] = frames_path;
  const std::string summary_path = siblingPath(options.output, "summary.json");
  std::ofstream summary_file(summary_path);
  summary_file << Json::writeString(Json::StreamWriterBuilder(), summary) << "\n";
  summary_file.close();
  if (!summary_file) throw std::runtime_error("cannot write " + summary_path);

  std::cout << frames << " scans, " << poses.size() << " poses (" << degenerate << " degenerate, " << resets
            << " resets, " << skipped << " skipped); odometry step " << mean_seconds * 1e3 << " ms mean, "
            << median(step_seconds) * 1e3 << " ms median; written to " << options.output << ", " << tum_path
            << ", " << frames_path << ", " << summary_path << "\n";
  return 0;
}

}  // namespace

void addOdometryCommand(CLI::App& app) {
  auto options = std::make_shared<OdometryCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "odometry",
      "LiDAR odometry over a recording: KITTI and TUM poses (traj.txt, traj_tum.txt), per-frame "
      "statistics (traj_frames.csv) and a summary (traj_summary.json)");
  command->add_option("input", options->input,
                      "a folder from rim simulate, an Ouster pcap (with --metadata) or a KITTI velodyne folder")
      ->required();
  command->add_option("--out,-o", options->output, "KITTI poses file; the other outputs are named after it")
      ->required();
  command->add_option("--metadata", options->metadata, "Ouster metadata JSON of the pcap")
      ->check(CLI::ExistingFile);
  command->add_flag("--kitti", options->kitti, "INPUT is a KITTI velodyne folder (synthetic HDL-64E model)");
  command->add_option("--frames", options->frames, "process only the first N scans")->check(CLI::PositiveNumber);
  command->add_flag("--no-deskew", options->no_deskew, "register the scans as measured");
  command->add_option("--kernel-scale", options->kernel_scale_m,
                      "robust kernel scale, m (paper: 0.5 outdoors, 0.2 indoors)")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  command->add_option("--keyframe-distance", options->keyframe_distance_m,
                      "register to a keyframe renewed after this distance, m (0: previous scan)")
      ->check(CLI::NonNegativeNumber);
  command->add_option("--keyframe-angle", options->keyframe_angle_deg, "... or after this rotation, degrees")
      ->check(CLI::NonNegativeNumber);
  command->add_option("--frame", options->frame, "whose poses: lidar (the image's frame) or sensor (Ouster)")
      ->capture_default_str()
      ->check(CLI::IsMember({"lidar", "sensor"}));
  command->callback([options] { runOdometry(*options); });
}

}  // namespace range_image_mapping::tool
