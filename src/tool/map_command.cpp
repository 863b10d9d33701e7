// rim map: a TSDF map of a recording at known poses (ground truth, reference
// poses or rim odometry's estimate), written as a triangle mesh with a report
// of timing, memory and, against a ground-truth surface, accuracy.
#include "commands.h"
#include "outputs.h"
#include "progress.h"

#include "range_image_mapping/evaluation/report.h"
#include "range_image_mapping/evaluation/surface_metrics.h"
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/io/recording.h"
#include "range_image_mapping/pipeline/scan_to_map_pipeline.h"

#include <json/json.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>

namespace range_image_mapping::tool {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct MapCommandOptions {
  io::RecordingOptions recording;
  std::string poses;        // "" = the rim simulate folder's ground truth
  std::string poses_frame;  // lidar or sensor; "" = what the file states, else lidar
  std::string output;
  std::string json;
  std::string eval;
  bool no_deskew = false;
  mapping::TsdfMapOptions map;
};

double secondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Poses in either format; a KITTI file without its times file is read too,
// since scans are matched to poses by index and the times come from the scans.
std::vector<Eigen::Isometry3d> loadPoses(const std::string& path) {
  if (!fs::exists(path)) throw io::PoseFileError("--poses: " + path + " does not exist");
  if (!fs::exists(io::kittiPoseFilePaths(path).times)) {
    try {
      return io::readKittiPoses(path);
    } catch (const io::KittiFormatError&) {
      // Not (well-formed) KITTI: readPoseFile names what is wrong.
    }
  }
  std::vector<Eigen::Isometry3d> poses = io::posesOf(io::readPoseFile(path));
  if (poses.empty()) throw io::PoseFileError("--poses: " + path + " holds no poses");
  return poses;
}

// Poses of the range image's own frame, from the file in the frame asked for
// or stated by the file.
std::vector<Eigen::Isometry3d> lidarPoses(const MapCommandOptions& options, const io::Recording& recording,
                                          std::string& path, std::string& frame) {
  path = options.poses.empty() ? recording.ground_truth.poses : options.poses;
  if (path.empty())
    throw std::invalid_argument("give --poses: " + recording.input +
                                " is not a rim simulate folder with ground truth (poses_kitti.txt)");
  const std::string stated = io::poseFileFrame(path);
  frame = options.poses_frame;
  if (frame.empty()) frame = stated == "os_sensor" ? "sensor" : "lidar";
  if (!stated.empty() && (stated == "os_sensor") != (frame == "sensor"))
    std::cerr << "warning: " << path << " states frame " << stated << ", taken as the " << frame
              << " frame as --poses-frame says\n";
  std::vector<Eigen::Isometry3d> poses = loadPoses(path);
  if (frame == "sensor") {
    if (!recording.ouster)
      throw std::invalid_argument("poses of the Ouster sensor frame (" + path + "): " + recording.input +
                                  " has no such frame");
    // T_world_lidar = T_world_sensor * T_sensor_lidar (lidar_to_sensor).
    for (Eigen::Isometry3d& pose : poses) pose = pose * recording.ouster->intrinsics.lidar_to_sensor;
  }
  return poses;
}

// Scans are matched to poses by index (the k-th pose is the k-th scan's, at
// its scan time). --frames may leave poses over; nothing else may.
void checkPoseCount(std::size_t poses, std::size_t scans, bool stopped_by_frames, const std::string& poses_path,
                    const std::string& input) {
  if (poses < scans || (poses > scans && !stopped_by_frames))
    throw std::invalid_argument("pose count mismatch: " + poses_path + " holds " + std::to_string(poses) +
                                " poses, " + input + " " + std::to_string(scans) +
                                " scans (one pose per scan, matched by index)");
}

struct StageTimes {
  double read = 0, integrate = 0, mesh = 0, write = 0, evaluate = 0;
  std::vector<double> integrate_per_scan;
};

Json::Value timingJson(const StageTimes& times, std::size_t scans) {
  Json::Value timing;
  timing["read_seconds"] = times.read;
  timing["integrate_seconds"] = times.integrate;
  timing["mesh_seconds"] = times.mesh;
  timing["write_seconds"] = times.write;
  timing["evaluate_seconds"] = times.evaluate;
  timing["integrate_ms_per_scan_mean"] = scans ? 1e3 * times.integrate / double(scans) : 0.0;
  timing["integrate_ms_per_scan_median"] = 1e3 * median(times.integrate_per_scan);
  timing["integrate_ms_per_scan_max"] =
      times.integrate_per_scan.empty()
          ? 0.0
          : 1e3 * *std::max_element(times.integrate_per_scan.begin(), times.integrate_per_scan.end());
  timing["read_ms_per_scan_mean"] = scans ? 1e3 * times.read / double(scans) : 0.0;
  return timing;
}

int runMap(const MapCommandOptions& options) {
  const auto started = Clock::now();
  pipeline::PipelineOptions pipeline_options;  // poses from the file, no odometry
  pipeline_options.map = options.map;
  pipeline_options.deskew_map = !options.no_deskew;
  pipeline_options.mesh_period_s = 0.0;  // one mesh at the end
  pipeline::ScanToMapPipeline pipeline(pipeline_options);  // MappingError for bad options, before any reading
  mapping::TsdfMap& map = *pipeline.map();
  if (fs::path(options.output).extension() != ".ply")
    throw std::invalid_argument("--out " + options.output + ": the mesh is written as PLY, name it *.ply");
  const io::Recording recording = io::openRecording(options.recording);
  std::string poses_path, poses_frame;
  const std::vector<Eigen::Isometry3d> poses = lidarPoses(options, recording, poses_path, poses_frame);
  const bool limited = recording.frames > 0;
  // A folder tells its scan count up front: mismatches fail before any work.
  if (recording.expected_frames > 0)
    checkPoseCount(poses.size(), std::size_t(recording.expected_frames),
                   limited && recording.expected_frames == recording.frames, poses_path, recording.input);

  std::cerr << "mapping " << recording.description << " at " << poses.size() << " poses (" << poses_frame
            << " frame) from " << poses_path << "\n";
  reportSensorModel(recording);
  StageTimes times;
  std::size_t scans = 0, integrated = 0, refused = 0, warnings = 0, blocks_refused = 0, blocks_dropped = 0;
  std::size_t points_used = 0;

  // Scan k's twist comes from poses k and k+1 (its own sweep), so each scan is
  // integrated once the next one has arrived; the last reuses the previous twist.
  RangeImage pending;
  std::size_t pending_index = 0;
  bool has_pending = false;
  Twist twist = Twist::Zero();
  const auto integratePending = [&] {
    pipeline::GivenPose pose;
    pose.world_from_lidar = poses[pending_index];
    pose.twist = twist;
    const pipeline::ScanResult result = pipeline.process(pending, pose);
    const double seconds = result.integrate_seconds;
    times.integrate += seconds;
    times.integrate_per_scan.push_back(seconds);
    const bool mapped = result.map && result.map->integrated;
    integrated += mapped;
    refused += !mapped;
    if (result.map) {
      blocks_refused += result.map->integration.blocks_refused;
      blocks_dropped += result.map->blocks_dropped;
      points_used += result.map->integration.points_used;
    }
    for (const std::string& warning : result.warnings)
      if (warnings++ < 10) std::cerr << "\nwarning: scan " << pending_index << ": " << warning << "\n";
    showProgress(int(pending_index + 1), recording.expected_frames, started);
  };

  auto read_started = Clock::now();
  io::RecordingStatistics reading;
  // A point cloud's place in the recording is its pose's index, also after
  // clouds that could not be read (skipped).
  const bool clouds = io::isPointCloudRecording(recording.kind);
  io::forEachScan(
      recording,
      [&](const RangeImage& scan) {
        times.read += secondsSince(read_started);
        const std::size_t index = clouds ? std::size_t(scan.frame_id) : scans;
        ++scans;
        if (index < poses.size()) {
          if (has_pending) {
            const double dt_s = (double(pipeline.scanTime(scan)) - double(pipeline.scanTime(pending))) * 1e-9;
            twist = twistBetween(poses[pending_index], poses[index], dt_s);
            integratePending();
          }
          pending = scan;  // reuses the buffers
          pending_index = index;
          has_pending = true;
        }
        read_started = Clock::now();
        return true;  // scans past the poses are only counted, for the error
      },
      &reading);
  try {
    checkPoseCount(poses.size(), scans + reading.unreadable, limited && scans == std::size_t(recording.frames),
                   poses_path, recording.input);
  } catch (const std::invalid_argument&) {
    finishProgress();  // the error on a line of its own
    throw;
  }
  if (has_pending) integratePending();
  if (recording.expected_frames <= 0 || int(scans) != recording.expected_frames) finishProgress();
  const Json::Value reading_json = reportReading(reading);
  if (scans == 0) throw std::runtime_error("no scans in " + recording.input);
  if (integrated == 0)
    throw std::runtime_error("no scan was integrated: all " + std::to_string(refused) + " were refused (" +
                             std::to_string(warnings) + " warnings above)");

  const auto mesh_started = Clock::now();
  const TriangleMesh mesh = map.fullMesh();  // with the mesh of blocks the radius dropped
  times.mesh += secondsSince(mesh_started);
  const auto write_started = Clock::now();
  writeMeshAtomically(options.output, mesh);
  times.write = secondsSince(write_started);
  const mapping::MapStatistics statistics = map.statistics();

  Json::Value report;
  report["input"] = recording.input;
  report["poses"] = poses_path;
  report["poses_frame"] = poses_frame;
  report["mesh"] = options.output;
  report["options"] = mapOptionsJson(options.map, !options.no_deskew);
  report["scans"] = Json::UInt64(scans);
  report["reading"] = reading_json;
  report["scans_integrated"] = Json::UInt64(integrated);
  report["scans_refused"] = Json::UInt64(refused);
  report["warnings"] = Json::UInt64(warnings);
  report["points_used"] = Json::UInt64(points_used);
  report["blocks"] = Json::UInt64(statistics.blocks);
  report["blocks_refused"] = Json::UInt64(blocks_refused);
  report["blocks_dropped"] = Json::UInt64(blocks_dropped);
  report["memory_bytes"] = Json::UInt64(statistics.memory_bytes);
  report["vertices"] = Json::UInt64(mesh.vertices.size());
  report["triangles"] = Json::UInt64(mesh.triangles.size());
  std::string evaluation_line;
  if (!options.eval.empty()) {
    const auto evaluate_started = Clock::now();
    const SurfaceEvaluation evaluation = evaluateMeshFile(options.output, options.eval, options.map.grid.voxel_size_m);
    report["evaluation"] = evaluation.json;
    evaluation_line = evaluation.summary_line;
    times.evaluate = secondsSince(evaluate_started);
  }
  report["timing"] = timingJson(times, integrated + refused);
  report["wall_seconds"] = secondsSince(started);
  if (!options.json.empty()) writeJsonFile(options.json, report);

  std::cout << scans << " scans (" << integrated << " integrated, " << refused << " refused); " << statistics.blocks
            << " blocks, " << double(statistics.memory_bytes) / (1 << 20) << " MiB; " << mesh.triangles.size()
            << " triangles; integrate " << 1e3 * times.integrate / double(integrated + refused) << " ms/scan, read "
            << 1e3 * times.read / double(scans) << " ms/scan, mesh " << times.mesh << " s; written to "
            << options.output << (options.json.empty() ? "" : ", " + options.json) << "\n";
  if (!evaluation_line.empty()) std::cout << evaluation_line << "\n";
  return 0;
}

}  // namespace

void addMapCommand(Command& rim) {
  auto options = std::make_shared<MapCommandOptions>();
  mapping::TsdfMapOptions& map = options->map;
  map.integrator.max_range_m = 30.0;
  Command& command = rim.subcommand(
      "map",
      "TSDF map of a recording at known poses (paper section 4.2), written as a triangle mesh (PLY) "
      "with a JSON report; scans and poses are matched by index");
  command.option("--poses", options->poses,
                 "KITTI or TUM poses, one per scan in order (default: a rim simulate folder's ground truth)");
  command.option("--poses-frame", options->poses_frame,
                 "whose poses: lidar (the image's frame) or sensor (Ouster); default: what the file states, "
                 "else lidar")
      .check(oneOf({"lidar", "sensor"}));
  command.option("--out,-o", options->output, "mesh PLY").required();
  command.option("--json", options->json, "report: options, counts, timing, memory, evaluation");
  command.option("--eval", options->eval,
                 "ground-truth surface (PLY/OBJ mesh or cloud): precision, recall and F-score at 3 voxels");
  addRecordingOptions(command, options->recording, kRecordingInputHelp, "map only the first N scans");
  command.flag("--no-deskew", options->no_deskew,
               "integrate each scan as if taken at one instant (default: the twist between its pose and the "
               "next moves every column)");
  addMapOptions(command, map);
  command.callback([options] { runMap(*options); });
}

}  // namespace range_image_mapping::tool
