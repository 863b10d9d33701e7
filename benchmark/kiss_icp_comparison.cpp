// Our odometry and KISS-ICP side by side, on the same scans, threads and run
// (issue 15, "What it must show"). KISS-ICP 1.2.3 is built unmodified from
// ../shared/peers by cmake/peers.cmake; where that folder is absent this
// program is not built, and says so at configure time.
//
// Datasets:
// - every preset of `rim simulate` (outdoor_car, indoor_cart, handheld_fast,
//   kitti_like, traffic, ... as its --help lists them), simulated in this run
//   into the work folder, with exact ground truth. KISS-ICP gets every point
//   with its column's time, so it deskews; its pose is then the sensor's at
//   the latest point time of the scan, ours at the scan time (the first valid
//   column). Each is compared with the ground truth at its own instant
//   (interpolated between the per-scan ground-truth poses).
// - kitti-raw-22: 22 real KITTI raw scans, no ground truth: path lengths.
// - kitti00-94-95: real KITTI odometry scans 94 and 95 with ground truth: the
//   error of the one step, and its length.
// Real KITTI scans carry no point times: neither system deskews them. KISS-ICP
// gets the raw points of the .bin files (its own input), our odometry the
// range image the project's KITTI reader projects them into (io::forEachScan).
//
// Our odometry runs as `rim run` runs it: the pipeline (odometry only) with
// rim's options, kernel scale 0.2 m for the indoor presets and 0.5 m
// otherwise; the rest are OdometryOptions' defaults. KISS-ICP runs with its
// defaults (max range 100 m, voxel 1 m = max range / 100, adaptive
// threshold); for the indoor presets with max range 20 m and voxel 0.2 m, the
// same rule (--kiss-indoor-range). Measured on 40 frames: 10 m (rim's indoor
// range clip) is KISS-ICP's most accurate indoors (ATE 3.7 against 4.0 cm on
// indoor_cart) but 4-5 times slower (1 s a frame, 3.5 s on handheld_fast),
// too slow for a run of minutes; 50 and 100 m are faster and 2-5 times worse.
//
// Usage: kiss_icp_comparison_benchmark [--frames N] [--datasets a,b,...]
//          [--threads 2] [--work DIR] [--reuse] [--poses DIR] [--kiss-indoor-range M]
#include "range_image_mapping/evaluation/trajectory_metrics.h"
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/io/recording.h"
#include "range_image_mapping/pipeline/scan_to_map_pipeline.h"
#include "range_image_mapping/registration/lidar_odometry.h"
#include "command_line.h"
#include "machine_info.h"
#include "test_data.h"

#include <kiss_icp/pipeline/KissICP.hpp>
#include <tbb/global_control.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace range_image_mapping {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using benchmark_support::splitList;

constexpr const char* kKittiRaw = "kitti-raw-22";
constexpr const char* kKitti00 = "kitti00-94-95";
// rim run's indoor presets (tool/simulate_command.cpp: scene "indoor").
const std::vector<std::string> kIndoorPresets{"indoor_cart", "handheld_fast"};

// Without --frames: presets simulated at their own length (300 scans, 150 for
// handheld_fast), the first kDefaultFrames of each used, so that the whole
// run stays near 10 minutes on 2 shared cores (every scan of the six presets:
// 12.5 minutes at a load of 4).
constexpr int kDefaultFrames = 200;

struct Options {
  int frames = -1;  // scans per dataset (presets simulated with that many); 0: all; -1: kDefaultFrames of each preset
  std::vector<std::string> datasets;  // empty: all
  int threads = 2;
  std::string work = RIM_DEFAULT_WORK_DIR;
  bool reuse = false;  // keep a simulated folder that is already there
  std::string poses;   // write each system's poses (TUM) into this folder; "" = none
  double kiss_indoor_range_m = 20.0;  // KISS-ICP's max range (and voxel = 1/100 of it) indoors
};

std::string shellQuoted(const std::string& text) {
  std::string quoted = "'";
  for (char c : text) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

std::string commandOutput(const std::string& command) {
  std::string output;
  if (FILE* pipe = popen(command.c_str(), "r")) {
    char buffer[4096];
    while (std::size_t read = std::fread(buffer, 1, sizeof buffer, pipe)) output.append(buffer, read);
    pclose(pipe);
  }
  return output;
}

// The presets rim simulate offers, from its --help ("--preset TEXT:{a,b,c}").
std::vector<std::string> simulatorPresets() {
  const std::string help = commandOutput(shellQuoted(RIM_TOOL_PATH) + " simulate --help 2>&1");
  const std::size_t option = help.find("--preset TEXT:{");
  if (option == std::string::npos) throw std::runtime_error(std::string("no preset list in ") + RIM_TOOL_PATH + " simulate --help");
  const std::size_t begin = help.find('{', option) + 1;
  return splitList(help.substr(begin, help.find('}', begin) - begin));
}

// The commit of the source tree this program was built from, and whether it
// had uncommitted changes when this run started (the build may be older).
std::string sourceState() {
  const std::string git = "git -C " + shellQuoted(RIM_SOURCE_DIR);
  std::string commit = commandOutput(git + " log -1 --format='%h %cd' --date=short 2>/dev/null");
  if (commit.empty()) return std::string(RIM_SOURCE_DIR) + " (not a git checkout)";
  commit.erase(commit.find_last_not_of('\n') + 1);
  const std::string changes = commandOutput(git + " status --porcelain --untracked-files=no 2>/dev/null");
  const long changed = std::count(changes.begin(), changes.end(), '\n');
  return std::string(RIM_SOURCE_DIR) + " at " + commit +
         (changed ? " + " + std::to_string(changed) + " files changed, not committed" : "");
}

bool isIndoor(const std::string& preset) {
  return std::find(kIndoorPresets.begin(), kIndoorPresets.end(), preset) != kIndoorPresets.end();
}

// ------------------------------------------------------------- the two systems

struct SystemRun {
  std::vector<io::StampedPose> poses;  // at each system's own instant per scan
  std::vector<double> step_ms;         // wall time of the odometry call, every scan
  int degenerate = 0, skipped = 0, resets = 0;
  double meanMs() const {
    double sum = 0.0;
    for (double ms : step_ms) sum += ms;
    return step_ms.empty() ? 0.0 : sum / double(step_ms.size());
  }
  double medianMs() const {
    if (step_ms.empty()) return 0.0;
    std::vector<double> sorted = step_ms;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    return sorted[sorted.size() / 2];
  }
};

// rim run's odometry: the pipeline without a map, rim's options.
registration::OdometryOptions rimOdometryOptions(bool indoor) {
  registration::OdometryOptions options;
  options.registration.kernel.scale_m = indoor ? 0.2 : 0.5;  // rim run --environment (the paper's)
  return options;
}

SystemRun runOurs(const io::Recording& recording, bool indoor) {
  pipeline::PipelineOptions options;
  options.odometry = rimOdometryOptions(indoor);
  pipeline::ScanToMapPipeline pipeline(options);
  SystemRun run;
  int frame = 0;
  io::forEachScan(recording, [&](const RangeImage& scan) {
    const auto started = Clock::now();
    const pipeline::ScanResult result = pipeline.process(scan);
    run.step_ms.push_back(1e3 * std::chrono::duration<double>(Clock::now() - started).count());
    if (result.has_pose) run.poses.push_back({1e-9 * double(result.scan_time_ns), result.world_from_lidar});
    if (result.odometry) {
      run.degenerate += result.odometry->degenerate;
      run.skipped += result.odometry->skipped;
      run.resets += result.odometry->reset && frame > 0;
    }
    ++frame;
    return true;
  });
  return run;
}

kiss_icp::pipeline::KISSConfig kissConfig(bool indoor, int threads, double indoor_range_m) {
  kiss_icp::pipeline::KISSConfig config;  // its defaults: 100 m, voxel 1 m, adaptive threshold
  if (indoor) config.max_range = indoor_range_m;
  config.voxel_size = config.max_range / 100.0;  // as KISS-ICP's own pipeline does when none is given
  config.max_num_threads = threads;
  config.deskew = true;  // used only where there are point times
  return config;
}

// Each column's time, a column without one (0: no return) taking the time of
// the nearest column before it, else after it.
std::vector<uint64_t> filledColumnTimes(const std::vector<uint64_t>& times) {
  std::vector<uint64_t> filled = times;
  for (std::size_t u = 1; u < filled.size(); ++u)
    if (filled[u] == 0) filled[u] = filled[u - 1];
  for (std::size_t u = filled.size(); u-- > 1;)
    if (filled[u - 1] == 0) filled[u - 1] = filled[u];
  return filled;
}

// One scan as KISS-ICP takes it: points (lidar frame), per-point times in
// seconds (empty without point times) and the time its pose refers to.
struct KissFrame {
  std::vector<Eigen::Vector3d> points;
  std::vector<double> times_s;
  double pose_time_s = 0.0;
};

void kissFrameFromImage(const RangeImage& image, KissFrame& frame) {
  frame.points.clear();
  frame.times_s.clear();
  const LidarModel& model = *image.model;
  const bool timed = image.column_timestamp_ns.size() == std::size_t(image.columns());
  const std::vector<uint64_t> times = timed ? filledColumnTimes(image.column_timestamp_ns) : std::vector<uint64_t>();
  uint64_t latest = 0;
  for (int v = 0; v < image.rows(); ++v)
    for (int u = 0; u < image.columns(); ++u) {
      if (!image.valid(v, u)) continue;
      frame.points.push_back(model.unproject(u, v, image.at(v, u)).cast<double>());
      if (timed) {
        frame.times_s.push_back(1e-9 * double(times[u]));
        latest = std::max(latest, times[u]);
      }
    }
  const uint64_t stamp = image.stamp_ns ? image.stamp_ns : scanTime(image, ScanTimeSource::kFirstValidColumn);
  frame.pose_time_s = timed ? 1e-9 * double(latest) : 1e-9 * double(stamp);
}

// A KITTI .bin as it is, each point with its column's time where the folder
// has column times (rim simulate's HDL-64): the column the project's reader
// files the point under, else the one of its azimuth.
void kissFrameFromKitti(const io::Recording& recording, const RangeImage& image, KissFrame& frame) {
  frame.points.clear();
  frame.times_s.clear();
  const PointCloudInput cloud = io::readKittiVelodyne(recording.velodyne_files.at(image.frame_id));
  const LidarModel& model = *recording.model;
  const bool timed = image.frame_id < recording.column_times.size() &&
                     recording.column_times[image.frame_id].size() == std::size_t(model.columns());
  const std::vector<uint64_t> times =
      timed ? filledColumnTimes(recording.column_times[image.frame_id]) : std::vector<uint64_t>();
  uint64_t latest = 0;
  for (const Eigen::Vector3f& point : cloud.points) {
    if (!point.allFinite() || point.isZero()) continue;
    frame.points.push_back(point.cast<double>());
    if (!timed) continue;
    int column;
    if (const std::optional<ProjectedPixel> pixel = model.project(point)) {
      column = pixel->column;
    } else {
      double azimuth = std::atan2(double(point.y()), double(point.x()));
      if (azimuth < 0) azimuth += 2.0 * M_PI;
      column = int(std::lround(model.columnOfEncoderAngle(float(azimuth)))) % model.columns();
    }
    frame.times_s.push_back(1e-9 * double(times[column]));
    latest = std::max(latest, times[column]);
  }
  frame.pose_time_s = timed ? 1e-9 * double(latest) : 1e-9 * double(image.stamp_ns);
}

Eigen::Isometry3d toIsometry(const Sophus::SE3d& pose) {
  Eigen::Isometry3d isometry = Eigen::Isometry3d::Identity();
  isometry.linear() = pose.rotationMatrix();
  isometry.translation() = pose.translation();
  return isometry;
}

SystemRun runKiss(const io::Recording& recording, bool indoor, const Options& options) {
  kiss_icp::pipeline::KissICP kiss(kissConfig(indoor, options.threads, options.kiss_indoor_range_m));
  SystemRun run;
  KissFrame frame;
  io::forEachScan(recording, [&](const RangeImage& image) {
    // Making KISS-ICP's input is not timed (as reading the scan is not, for ours).
    if (recording.kind == io::RecordingKind::kKittiVelodyne)
      kissFrameFromKitti(recording, image, frame);
    else
      kissFrameFromImage(image, frame);
    const auto started = Clock::now();
    kiss.RegisterFrame(frame.points, frame.times_s);
    run.step_ms.push_back(1e3 * std::chrono::duration<double>(Clock::now() - started).count());
    run.poses.push_back({frame.pose_time_s, toIsometry(kiss.pose())});
    return true;
  });
  return run;
}

// ------------------------------------------------------------- evaluation

// The ground truth at time t: interpolated between the per-scan poses
// (slerp, linear), extrapolated by at most max_extrapolation_s at the ends.
std::optional<Eigen::Isometry3d> truthAt(const std::vector<io::StampedPose>& truth, double t,
                                         double max_extrapolation_s) {
  if (truth.size() < 2) return std::nullopt;
  if (t < truth.front().time_s - max_extrapolation_s || t > truth.back().time_s + max_extrapolation_s)
    return std::nullopt;
  std::size_t k = std::size_t(
      std::upper_bound(truth.begin(), truth.end(), t, [](double time, const io::StampedPose& pose) { return time < pose.time_s; }) -
      truth.begin());
  k = std::clamp<std::size_t>(k, 1, truth.size() - 1);
  const io::StampedPose& a = truth[k - 1];
  const io::StampedPose& b = truth[k];
  const double alpha = (t - a.time_s) / (b.time_s - a.time_s);
  // Along the motion a -> b (alpha outside [0, 1] extrapolates it).
  const Eigen::Isometry3d step = a.pose.inverse() * b.pose;
  const Eigen::AngleAxisd rotation(step.linear());
  Eigen::Isometry3d partial = Eigen::Isometry3d::Identity();
  partial.linear() = Eigen::AngleAxisd(alpha * rotation.angle(), rotation.axis()).toRotationMatrix();
  partial.translation() = alpha * step.translation();
  return a.pose * partial;
}

double pathLength(const std::vector<io::StampedPose>& poses) {
  std::vector<Eigen::Isometry3d> plain;
  for (const io::StampedPose& pose : poses) plain.push_back(pose.pose);
  return plain.size() < 2 ? 0.0 : evaluation::pathDistances(plain).back();
}

struct Accuracy {
  bool evaluated = false;
  double ate_m = 0, truth_path_m = 0;
  bool has_rpe = false;
  double rpe_percent = 0, rpe_deg_per_100m = 0;
  double step_percent = 0;  // frame-to-frame translation error / path, where RPE is not defined
  std::size_t poses = 0;
};

Accuracy againstTruth(const std::vector<io::StampedPose>& estimate, const std::vector<io::StampedPose>& truth) {
  std::vector<Eigen::Isometry3d> estimated, true_poses;
  const double period = truth.size() > 1 ? (truth.back().time_s - truth.front().time_s) / double(truth.size() - 1) : 0.1;
  for (const io::StampedPose& pose : estimate)
    if (const std::optional<Eigen::Isometry3d> true_pose = truthAt(truth, pose.time_s, 1.5 * period)) {
      estimated.push_back(pose.pose);
      true_poses.push_back(*true_pose);
    }
  Accuracy accuracy;
  if (estimated.size() < 3) return accuracy;
  const evaluation::TrajectoryEvaluation evaluation = evaluation::evaluateTrajectory(estimated, true_poses);
  accuracy.evaluated = true;
  accuracy.poses = estimated.size();
  accuracy.ate_m = evaluation.absolute_translation_m.rmse;
  accuracy.truth_path_m = evaluation.ground_truth_length_m;
  accuracy.has_rpe = evaluation.kitti.segments > 0;
  accuracy.rpe_percent = evaluation.kitti.translation_percent;
  accuracy.rpe_deg_per_100m = 100.0 * evaluation.kitti.rotation_deg_per_m;
  accuracy.step_percent = evaluation.frame_to_frame.translation_percent;
  return accuracy;
}

// ------------------------------------------------------------- datasets and the table

struct Row {
  std::string dataset, system, note;
  std::size_t frames = 0;
  Accuracy accuracy;
  double path_m = 0;
  // kitti00-94-95: the one step against the ground truth.
  bool has_step = false;
  double step_error_m = 0, step_error_deg = 0, truth_step_m = 0;
  double mean_ms = 0, median_ms = 0;
  int degenerate = 0, resets = 0, skipped = 0;
};

struct Comparison {
  SystemRun ours_run, kiss_run;
  Row ours, kiss;
  std::string kind;  // "simulated", "real", "real-gt"
};

std::string fixed(double value, int decimals) {
  char text[64];
  std::snprintf(text, sizeof text, "%.*f", decimals, value);
  return text;
}

Row makeRow(const std::string& dataset, const std::string& system, const SystemRun& run) {
  Row row;
  row.dataset = dataset;
  row.system = system;
  row.frames = run.step_ms.size();
  row.path_m = pathLength(run.poses);
  row.mean_ms = run.meanMs();
  row.median_ms = run.medianMs();
  row.degenerate = run.degenerate;
  row.resets = run.resets;
  row.skipped = run.skipped;
  return row;
}

Comparison runBoth(const std::string& dataset, const io::Recording& recording, bool indoor, const Options& options) {
  std::cerr << dataset << ": ours over " << recording.description << "\n";
  Comparison comparison;
  comparison.ours_run = runOurs(recording, indoor);
  std::cerr << dataset << ": KISS-ICP\n";
  comparison.kiss_run = runKiss(recording, indoor, options);
  const SystemRun& ours = comparison.ours_run;
  const SystemRun& kiss = comparison.kiss_run;
  comparison.ours = makeRow(dataset, "rim", ours);
  comparison.kiss = makeRow(dataset, "KISS-ICP", kiss);
  if (!options.poses.empty()) {
    fs::create_directories(options.poses);
    io::PoseFileInfo info;
    info.frame = recording.frame;
    info.comment = "kiss_icp_comparison_benchmark, rim odometry (pose at the scan time)";
    io::writeTumPoses((fs::path(options.poses) / (dataset + "_rim.txt")).string(), ours.poses, info);
    info.comment = "kiss_icp_comparison_benchmark, KISS-ICP (pose at the latest point time)";
    io::writeTumPoses((fs::path(options.poses) / (dataset + "_kiss_icp.txt")).string(), kiss.poses, info);
  }
  if (!recording.ground_truth.poses.empty()) {
    const std::vector<io::StampedPose> truth = io::readKittiPosesWithTimes(recording.ground_truth.poses);
    comparison.ours.accuracy = againstTruth(ours.poses, truth);
    comparison.kiss.accuracy = againstTruth(kiss.poses, truth);
  }
  return comparison;
}

Comparison runPreset(const std::string& preset, const Options& options) {
  const fs::path folder = fs::path(options.work) / preset;
  if (!(options.reuse && fs::exists(folder / "poses_kitti.txt"))) {
    fs::remove_all(folder);
    fs::create_directories(folder);
    const std::string log = (folder.parent_path() / (preset + "_simulate.log")).string();
    std::string command = shellQuoted(RIM_TOOL_PATH) + " simulate --preset " + preset + " --out " +
                          shellQuoted(folder.string());
    if (options.frames > 0) command += " --frames " + std::to_string(options.frames);  // else its own length
    command += " >" + shellQuoted(log) + " 2>&1";
    std::cerr << preset << ": simulating into " << folder.string() << "\n";
    const auto started = Clock::now();
    if (std::system(command.c_str()) != 0) throw std::runtime_error("rim simulate failed: see " + log);
    std::cerr << preset << ": simulated in " << fixed(std::chrono::duration<double>(Clock::now() - started).count(), 0)
              << " s\n";
  }
  io::RecordingOptions recording_options;
  recording_options.input = folder.string();
  recording_options.frames = options.frames < 0 ? kDefaultFrames : options.frames;
  const io::Recording recording = io::openRecording(recording_options);
  Comparison comparison = runBoth(preset, recording, isIndoor(preset), options);
  comparison.kind = "simulated";
  return comparison;
}

std::optional<Comparison> runKittiRaw(const Options& options) {
  const std::string folder = test::dataFile(kKittiRaw);
  if (folder.empty()) {
    std::cerr << kKittiRaw << ": skipped, not found in " << test::dataDirectory() << " (set RIM_DATA_DIR)\n";
    return std::nullopt;
  }
  io::RecordingOptions recording_options;
  recording_options.input = folder;
  recording_options.frames = std::max(options.frames, 0);
  const io::Recording recording = io::openRecording(recording_options);
  Comparison comparison = runBoth(kKittiRaw, recording, false, options);
  comparison.kind = "real";
  return comparison;
}

std::optional<Comparison> runKitti00(const Options& options) {
  const std::string folder = test::dataFile("kitti00");
  if (folder.empty()) {
    std::cerr << kKitti00 << ": skipped, kitti00 not found in " << test::dataDirectory() << " (set RIM_DATA_DIR)\n";
    return std::nullopt;
  }
  io::RecordingOptions recording_options;
  recording_options.input = folder;
  recording_options.kitti = true;
  io::Recording recording = io::openRecording(recording_options);
  std::vector<std::string> pair;
  for (const std::string& file : recording.velodyne_files) {
    const std::string name = fs::path(file).filename().string();
    if (name == "000094.bin" || name == "000095.bin") pair.push_back(file);
  }
  if (pair.size() != 2) throw std::runtime_error(folder + "/velodyne: needs 000094.bin and 000095.bin");
  recording.velodyne_files = pair;
  recording.times_s.clear();  // 10 Hz stamps (KITTI's times differ by 0.104 s here)
  recording.expected_frames = 2;

  // Ground truth: KITTI's T_world_camera0 of frames 94 and 95, in the Velodyne frame.
  const std::vector<Eigen::Isometry3d> camera = io::readKittiPoses(folder + "/poses_00_full_evo.txt");
  const Eigen::Isometry3d tr = io::readKittiVelodyneToCamera(folder + "/calib.txt");
  const Eigen::Isometry3d truth_step =
      io::velodynePoseFromCameraPose(camera.at(94), tr).inverse() * io::velodynePoseFromCameraPose(camera.at(95), tr);

  Comparison comparison = runBoth(kKitti00, recording, false, options);
  comparison.kind = "real-gt";
  const auto fill = [&](Row& row, const SystemRun& run) {
    if (run.poses.size() != 2) {
      row.note = "no step";
      return;
    }
    const Eigen::Isometry3d step = run.poses[0].pose.inverse() * run.poses[1].pose;
    const Eigen::Isometry3d error = truth_step.inverse() * step;
    row.has_step = true;
    row.step_error_m = error.translation().norm();
    row.step_error_deg = evaluation::rotationAngle(error.linear()) * 180.0 / M_PI;
    row.truth_step_m = truth_step.translation().norm();
  };
  fill(comparison.ours, comparison.ours_run);
  fill(comparison.kiss, comparison.kiss_run);
  return comparison;
}

std::string cell(bool present, double value, int decimals) { return present ? fixed(value, decimals) : "-"; }

void printTable(const std::vector<Comparison>& comparisons) {
  std::printf(
      "\n| dataset | frames | system | ATE m | RPE %% | RPE deg/100 m | path m | truth path m | ms/frame mean | "
      "ms/frame median | frames/s | KISS-ICP/rim time | notes |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Comparison& comparison : comparisons) {
    for (const Row* row : {&comparison.ours, &comparison.kiss}) {
      const Accuracy& accuracy = row->accuracy;
      std::string notes = row->note;
      const auto add = [&](const std::string& text) { notes += (notes.empty() ? "" : "; ") + text; };
      if (accuracy.evaluated && !accuracy.has_rpe)
        add("run < 100 m: frame-to-frame error " + fixed(accuracy.step_percent, 2) + " % of the path");
      if (row->has_step)
        add("step error " + fixed(100.0 * row->step_error_m, 1) + " cm (" +
            fixed(100.0 * row->step_error_m / row->truth_step_m, 1) + " %), " + fixed(row->step_error_deg, 3) + " deg");
      if (row->degenerate) add(std::to_string(row->degenerate) + " degenerate");
      if (row->resets) add(std::to_string(row->resets) + " resets");
      if (row->skipped) add(std::to_string(row->skipped) + " skipped");
      const bool ours = row == &comparison.ours;
      const double ratio = comparison.ours.mean_ms > 0 ? comparison.kiss.mean_ms / comparison.ours.mean_ms : 0.0;
      const double truth_path = row->has_step ? row->truth_step_m : accuracy.truth_path_m;
      std::printf("| %s | %zu | %s | %s | %s | %s | %.2f | %s | %.1f | %.1f | %.0f | %s | %s |\n",
                  ours ? row->dataset.c_str() : "", row->frames, row->system.c_str(),
                  cell(accuracy.evaluated, accuracy.ate_m, 3).c_str(), cell(accuracy.has_rpe, accuracy.rpe_percent, 2).c_str(),
                  cell(accuracy.has_rpe, accuracy.rpe_deg_per_100m, 2).c_str(), row->path_m,
                  cell(accuracy.evaluated || row->has_step, truth_path, 2).c_str(), row->mean_ms, row->median_ms,
                  row->mean_ms > 0 ? 1e3 / row->mean_ms : 0.0, ours ? (fixed(ratio, 1) + "x").c_str() : "",
                  notes.c_str());
    }
  }
}

// Issue 15's targets, each measured value beside it.
void printChecks(const std::vector<Comparison>& comparisons) {
  std::printf("\nIssue 15 targets (this run):\n");
  const auto line = [](bool met, const std::string& text) {
    std::printf("  [%s] %s\n", met ? "met" : "NOT met", text.c_str());
  };
  for (const Comparison& comparison : comparisons) {
    const Row& ours = comparison.ours;
    const Row& kiss = comparison.kiss;
    const std::string& name = ours.dataset;
    if (comparison.kind == "simulated" && ours.accuracy.evaluated && kiss.accuracy.evaluated) {
      line(ours.accuracy.ate_m <= kiss.accuracy.ate_m,
           name + ": ATE rim " + fixed(ours.accuracy.ate_m, 3) + " <= KISS-ICP " + fixed(kiss.accuracy.ate_m, 3) + " m");
      if (ours.accuracy.has_rpe && kiss.accuracy.has_rpe) {
        line(ours.accuracy.rpe_percent <= kiss.accuracy.rpe_percent,
             name + ": RPE rim " + fixed(ours.accuracy.rpe_percent, 2) + " <= KISS-ICP " +
                 fixed(kiss.accuracy.rpe_percent, 2) + " %");
        line(ours.accuracy.rpe_deg_per_100m <= kiss.accuracy.rpe_deg_per_100m,
             name + ": RPE rim " + fixed(ours.accuracy.rpe_deg_per_100m, 2) + " <= KISS-ICP " +
                 fixed(kiss.accuracy.rpe_deg_per_100m, 2) + " deg/100 m");
      }
      if (name.rfind("traffic", 0) == 0)
        line(ours.accuracy.ate_m <= 0.10, name + ": ATE rim " + fixed(ours.accuracy.ate_m, 3) + " <= 0.10 m");
    }
    if (comparison.kind != "simulated" && kiss.path_m > 0) {
      const double difference = 100.0 * (ours.path_m - kiss.path_m) / kiss.path_m;
      line(std::abs(difference) <= 1.0, name + ": path rim " + fixed(ours.path_m, 3) + " m vs KISS-ICP " +
                                            fixed(kiss.path_m, 3) + " m: " + fixed(difference, 2) + " % (within 1 %)");
    }
    if (ours.mean_ms > 0) {
      const double ratio = kiss.mean_ms / ours.mean_ms;
      line(ratio >= 5.0, name + ": speed " + fixed(ratio, 1) + "x KISS-ICP per frame (>= 5x)");
    }
    if (name == "outdoor_car" && ours.mean_ms > 0)
      line(1e3 / ours.mean_ms >= 100.0, name + ": rim " + fixed(1e3 / ours.mean_ms, 0) + " frames/s (>= 100)");
  }
  std::printf("  (kitti00-94-95 \"within the current error against ground truth\": compare its step error with the "
              "previous run's; not checked here)\n");
}

int run(int argc, char** argv) {
  Options options;
  for (benchmark_support::ArgumentCursor arguments(argc, argv); arguments.next();) {
    const std::string argument = arguments.name();
    if (argument == "--frames") {
      options.frames = arguments.integer();
      if (options.frames < 0 || options.frames == 1) throw std::invalid_argument("--frames: 0 (all) or at least 2");
    } else if (argument == "--datasets") {
      options.datasets = splitList(arguments.value());
    } else if (argument == "--threads") {
      options.threads = arguments.integer();
      if (options.threads < 1) throw std::invalid_argument("--threads: at least 1");
    } else if (argument == "--work") {
      options.work = arguments.value();
    } else if (argument == "--poses") {
      options.poses = arguments.value();
    } else if (argument == "--kiss-indoor-range") {
      options.kiss_indoor_range_m = arguments.number();
      if (!(options.kiss_indoor_range_m > 0)) throw std::invalid_argument("--kiss-indoor-range: positive");
    } else if (argument == "--reuse") {
      options.reuse = true;
    } else if (argument == "-h" || argument == "--help") {
      std::printf(
          "Usage: %s [--frames N] [--datasets a,b,...] [--threads 2] [--work DIR] [--reuse] [--poses DIR]\n"
          "         [--kiss-indoor-range M]\n"
          "  --frames N      the first N scans of each dataset, presets simulated with N; 0: all of them\n"
          "                  (default: the first %d scans of each preset simulated at its own length, every real scan)\n"
          "  --datasets      comma-separated: rim simulate's presets, %s, %s (default: all)\n"
          "  --threads       TBB threads for both systems (default 2)\n"
          "  --work DIR      where the presets are simulated (default %s)\n"
          "  --reuse         keep presets already simulated there (default: simulate again)\n"
          "  --kiss-indoor-range M  KISS-ICP's max range indoors, voxel M/100 (default 20)\n"
          "  --poses DIR     write each system's poses there (TUM: DATASET_rim.txt, DATASET_kiss_icp.txt)\n"
          "Real data from $RIM_DATA_DIR (default %s).\n",
          argv[0], kDefaultFrames, kKittiRaw, kKitti00, RIM_DEFAULT_WORK_DIR, RIM_DEFAULT_DATA_DIR);
      return 0;
    } else {
      throw std::invalid_argument("unknown argument " + argument + " (see --help)");
    }
  }
  // rim simulate uses the real sensors' metadata from the data folder, as rim run does.
  setenv("RIM_DATA_DIR", test::dataDirectory().c_str(), 0);

  const std::vector<std::string> presets = simulatorPresets();
  std::vector<std::string> datasets = options.datasets;
  if (datasets.empty()) {
    datasets = presets;
    datasets.push_back(kKittiRaw);
    datasets.push_back(kKitti00);
  }
  for (const std::string& dataset : datasets)
    if (std::find(presets.begin(), presets.end(), dataset) == presets.end() && dataset != kKittiRaw &&
        dataset != kKitti00)
      throw std::invalid_argument("unknown dataset " + dataset);

  tbb::global_control threads(tbb::global_control::max_allowed_parallelism, std::size_t(options.threads));
  const auto started = Clock::now();
  std::printf("kiss_icp_comparison_benchmark: rim odometry vs KISS-ICP 1.2.3 (%s), same scans, same process\n",
              RIM_PEERS_DIR "/kiss-icp");
  std::printf("machine: %s, %u hardware threads, load %s; %s\n", benchmark_support::cpuModel().c_str(),
              std::thread::hardware_concurrency(), benchmark_support::loadAverage().c_str(),
              benchmark_support::now().c_str());
  std::printf("source: %s\n", sourceState().c_str());
  std::printf("both on %d threads (TBB max_allowed_parallelism, KISS-ICP max_num_threads); %s\n", options.threads,
              options.frames > 0    ? ("the first " + std::to_string(options.frames) +
                                       " scans of each dataset (presets simulated with as many)").c_str()
              : options.frames == 0 ? "every scan: each preset at its own length, every real scan"
                                    : ("default: the first " + std::to_string(kDefaultFrames) +
                                       " scans of each preset (simulated at its own length; --frames 0 for all), "
                                       "every real scan").c_str());
  std::printf("rim: the pipeline's odometry as rim run, kernel 0.2 m indoors (%s) and 0.5 m otherwise, "
              "OdometryOptions defaults; pose at the scan time (first valid column)\n",
              "indoor_cart, handheld_fast");
  std::printf("KISS-ICP: its defaults (max range 100 m, voxel 1 m), indoors max range %g m and voxel %g m; "
              "per-point (column) times where the data has them, pose at the latest point time\n",
              options.kiss_indoor_range_m, options.kiss_indoor_range_m / 100.0);
  std::printf("ATE: RMSE after SE(3) alignment; RPE: KITTI devkit over 100-800 m; ground truth at each pose's "
              "own instant; ms/frame: wall time of one odometry call, every scan\n");
  std::fflush(stdout);

  std::vector<Comparison> comparisons;
  for (const std::string& dataset : datasets) {
    if (dataset == kKittiRaw) {
      if (auto comparison = runKittiRaw(options)) comparisons.push_back(std::move(*comparison));
    } else if (dataset == kKitti00) {
      if (auto comparison = runKitti00(options)) comparisons.push_back(std::move(*comparison));
    } else {
      comparisons.push_back(runPreset(dataset, options));
    }
  }
  printTable(comparisons);
  printChecks(comparisons);
  std::printf("\nload at the end %s; %.0f s in all (simulation included)\n", benchmark_support::loadAverage().c_str(),
              std::chrono::duration<double>(Clock::now() - started).count());
  return 0;
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  using range_image_mapping::benchmark_support::runReportingErrors;
  return runReportingErrors("kiss_icp_comparison_benchmark", range_image_mapping::run, argc, argv);
}
