// rim run: the whole pipeline offline, with no ROS master: the core's
// ScanToMapPipeline, the story the Odometry and Mapper nodelets tell too.
// INPUT is a recording or one of rim simulate's presets (simulated first).
#include "commands.h"
#include "outputs.h"
#include "progress.h"

#include "range_image_mapping/evaluation/report.h"
#include "range_image_mapping/evaluation/trajectory_metrics.h"
#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/io/recording.h"
#include "range_image_mapping/pipeline/scan_to_map_pipeline.h"

#include <Eigen/SVD>
#include <json/json.h>
#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <limits>
#include <iostream>
#include <memory>
#include <optional>

namespace range_image_mapping::tool {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct RunCommandOptions {
  io::RecordingOptions recording;
  std::string output_directory;
  std::string environment;  // indoor or outdoor: voxel, range clip and kernel defaults
  bool sensor_frame = false;
  double mesh_period_s = 1.0;  // re-mesh after this much scan time, as the Mapper's mesh_period
  bool no_plot = false;
  bool simulate_bag = false;  // a preset also writes packets.bag, to replay through the launch
  OdometryCommandLine odometry;
  mapping::TsdfMapOptions map;
};

std::atomic<bool> interrupted{false};

double secondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

double peakResidentMegabytes() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return double(usage.ru_maxrss) / 1024.0;  // Linux: kilobytes
}

// The paper's settings (section 5): 4 cm voxels and a 10 m clip indoors,
// 10 cm and 30 m outdoors, kernel scale 0.2 / 0.5 m. Options given on the
// command line win.
void applyEnvironment(const std::string& environment, const Command& command, RunCommandOptions& options) {
  const bool indoor = environment == "indoor";
  const auto unset = [&](const char* name) { return !command.given(name); };
  if (unset("--voxel")) options.map.grid.voxel_size_m = indoor ? 0.04 : 0.10;
  if (unset("--max-range")) options.map.integrator.max_range_m = indoor ? 10.0 : 30.0;
  if (unset("--kernel-scale")) options.odometry.kernel_scale_m = indoor ? 0.2 : 0.5;
}

struct FrameRecord {
  double time_s = 0;
  double odometry_ms = 0, integrate_ms = 0;
  std::size_t inliers = 0;
  double inlier_share = 0, moving_share = 0;  // NaN where the scan was not registered (a restart)
  bool degenerate = false, suspect = false;
};

struct GroundTruthComparison {
  evaluation::TrajectoryEvaluation trajectory;
  bool has_surface = false;
  SurfaceEvaluation surface;
};

// The rigid motion A that best maps estimated poses onto the ground truth,
// orientations included: R from the SVD of sum R_truth R_estimate^T, then t
// from the positions. Unlike a position-only (Umeyama) fit it is determined
// on a straight path too, where the roll about the path would be free.
Eigen::Isometry3d poseAlignment(const std::vector<Eigen::Isometry3d>& estimate,
                                const std::vector<Eigen::Isometry3d>& truth) {
  Eigen::Matrix3d sum = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < estimate.size(); ++i) sum += truth[i].linear() * estimate[i].linear().transpose();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(sum, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d correction = Eigen::Matrix3d::Identity();
  correction(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  Eigen::Isometry3d alignment = Eigen::Isometry3d::Identity();
  alignment.linear() = svd.matrixU() * correction * svd.matrixV().transpose();
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < estimate.size(); ++i)
    offset += truth[i].translation() - alignment.linear() * estimate[i].translation();
  alignment.translation() = offset / double(estimate.size());
  return alignment;
}

// The estimate against a simulated folder's ground truth: poses associated by
// time (ATE after SE(3) alignment of the positions, as evo), and the mesh
// moved into the ground-truth world by poseAlignment(), compared with the
// surface seen within the range clip.
GroundTruthComparison compareWithGroundTruth(const io::Recording& recording,
                                             const std::vector<io::StampedPose>& estimate,
                                             const TriangleMesh& mesh, double voxel_m,
                                             double range_m, const std::string& aligned_mesh_path) {
  GroundTruthComparison comparison;
  evaluation::StampedTrajectory estimated, truth;
  for (const io::StampedPose& pose : estimate) {
    estimated.times_s.push_back(pose.time_s);
    estimated.poses.push_back(pose.pose);
  }
  for (const io::StampedPose& pose : io::readKittiPosesWithTimes(recording.ground_truth.poses)) {
    truth.times_s.push_back(pose.time_s);
    truth.poses.push_back(pose.pose);
  }
  const evaluation::AssociatedPoses associated = evaluation::associateByTimestamp(estimated, truth, 0.01);
  comparison.trajectory = evaluation::evaluateTrajectory(associated.estimate, associated.ground_truth);
  if (!recording.ground_truth.surface.empty() && !mesh.triangles.empty()) {
    TriangleMesh aligned = mesh;
    const Eigen::Isometry3f alignment = poseAlignment(associated.estimate, associated.ground_truth).cast<float>();
    for (Eigen::Vector3f& vertex : aligned.vertices) vertex = alignment * vertex;
    for (Eigen::Vector3f& normal : aligned.normals) normal = alignment.linear() * normal;
    writeMeshAtomically(aligned_mesh_path, aligned);
    std::vector<Eigen::Vector3f> sensor_positions;
    for (const Eigen::Isometry3d& pose : associated.ground_truth) sensor_positions.push_back(pose.translation().cast<float>());
    comparison.surface = evaluateMeshFileWithinRange(aligned_mesh_path, recording.ground_truth.surface, voxel_m,
                                                     sensor_positions, range_m);
    comparison.has_surface = true;
  }
  return comparison;
}

Json::Value statisticsJson(std::vector<double> values) {
  Json::Value json;
  if (values.empty()) return json;
  double sum = 0;
  for (double value : values) sum += value;
  json["mean"] = sum / double(values.size());
  json["median"] = median(values);
  json["max"] = *std::max_element(values.begin(), values.end());
  json["min"] = *std::min_element(values.begin(), values.end());
  return json;
}

// What the scans gave: poses, per-frame costs and counts.
struct RunRecord {
  std::vector<io::StampedPose> poses;
  std::vector<FrameRecord> records;
  std::vector<double> mesh_update_ms;
  double read_seconds = 0, odometry_seconds = 0, integrate_seconds = 0, mesh_seconds = 0;
  int frames = 0, refused = 0;
  OdometryHealth health;
  io::RecordingStatistics reading;
  Json::Value reading_json;
};

// A preset is simulated into out/sequence first; anything else is read as it is.
io::RecordingOptions simulateIfPreset(RunCommandOptions& options, bool preset, const fs::path& out) {
  if (preset) {
    const fs::path sequence = out / "sequence";
    std::cerr << "simulating " << options.recording.input << " into " << sequence.string() << "\n";
    options.recording.input = simulatePreset(options.recording.input, sequence.string(), options.recording.frames,
                                             options.map.integrator.max_range_m, options.simulate_bag ? "bag" : "");
  }
  return options.recording;
}

pipeline::PipelineOptions pipelineOptions(const RunCommandOptions& options) {
  pipeline::PipelineOptions pipeline;
  pipeline.odometry = options.odometry.options();
  pipeline.map = options.map;
  pipeline.deskew_map = pipeline.odometry->deskew;
  pipeline.mesh_period_s = options.mesh_period_s;
  return pipeline;
}

// Every scan through the pipeline, until the recording ends or Ctrl-C.
RunRecord runScans(pipeline::ScanToMapPipeline& pipeline, const io::Recording& recording, const fs::path& out) {
  RunRecord run;
  OdometryFramesCsv frames_file((out / "odometry_frames.csv").string());
  std::size_t warnings = 0;
  interrupted = false;
  const auto previous_handler = std::signal(SIGINT, [](int) { interrupted = true; });
  const auto loop_started = Clock::now();
  auto read_started = Clock::now();
  io::forEachScan(
      recording,
      [&](const RangeImage& scan) {
        run.read_seconds += secondsSince(read_started);
        const pipeline::ScanResult result = pipeline.process(scan);
        const registration::OdometryUpdate& update = *result.odometry;
        frames_file.add(run.frames, update);
        run.odometry_seconds += result.odometry_seconds;
        run.integrate_seconds += result.integrate_seconds;
        run.health.add(update);
        run.refused += result.map && !result.map->integrated;
        for (const std::string& warning : result.warnings)
          if (warnings++ < 20) std::cerr << "\nwarning: frame " << run.frames << ": " << warning << "\n";
        if (result.has_pose) {
          const double time_s = double(result.scan_time_ns) * 1e-9;
          run.poses.push_back({time_s, result.world_from_lidar});
          constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();  // a gap in report.png
          run.records.push_back({time_s, 1e3 * result.odometry_seconds, 1e3 * result.integrate_seconds,
                                 update.inliers, update.reset ? kNaN : update.inlierShare(),
                                 update.reset ? kNaN : update.movingShare(), update.degenerate, update.suspect});
        }
        if (result.mesh) {
          run.mesh_update_ms.push_back(1e3 * result.mesh_seconds);
          run.mesh_seconds += result.mesh_seconds;
        }
        ++run.frames;
        showProgress(run.frames, recording.expected_frames, loop_started);
        read_started = Clock::now();
        return !interrupted;
      },
      &run.reading);
  std::signal(SIGINT, previous_handler);
  if (recording.expected_frames <= 0 || run.frames != recording.expected_frames) finishProgress();
  frames_file.close();
  if (interrupted) std::cerr << "interrupted after " << run.frames << " scans: saving what there is\n";
  run.reading_json = reportReading(run.reading);
  if (run.poses.empty()) throw std::runtime_error("no usable scans in " + recording.input);
  return run;
}

Json::Value timingJson(const RunRecord& run, std::vector<double>& odometry_ms, std::vector<double>& integrate_ms) {
  for (const FrameRecord& record : run.records) {
    odometry_ms.push_back(record.odometry_ms);
    integrate_ms.push_back(record.integrate_ms);
  }
  Json::Value timing;
  timing["read_seconds"] = run.read_seconds;
  timing["odometry_seconds"] = run.odometry_seconds;
  timing["integrate_seconds"] = run.integrate_seconds;
  timing["mesh_seconds"] = run.mesh_seconds;
  timing["odometry_ms"] = statisticsJson(odometry_ms);
  timing["integrate_ms"] = statisticsJson(integrate_ms);
  timing["mesh_update_ms"] = statisticsJson(run.mesh_update_ms);
  timing["odometry_frames_per_second"] = run.odometry_seconds > 0 ? double(run.frames) / run.odometry_seconds : 0.0;
  timing["mapping_frames_per_second"] =
      run.integrate_seconds > 0 ? double(run.records.size()) / run.integrate_seconds : 0.0;
  return timing;
}

Json::Value groundTruthJson(const GroundTruthComparison& comparison) {
  Json::Value json;
  const evaluation::TrajectoryEvaluation& trajectory = comparison.trajectory;
  json["ate_rmse_m"] = trajectory.absolute_translation_m.rmse;
  json["ate_max_m"] = trajectory.absolute_translation_m.maximum;
  if (trajectory.kitti.segments > 0) {
    json["rpe_translation_percent"] = trajectory.kitti.translation_percent;
    json["rpe_rotation_deg_per_100m"] = 100.0 * trajectory.kitti.rotation_deg_per_m;
  }
  json["trajectory_summary"] = evaluation::trajectorySummaryLine(trajectory);
  if (comparison.has_surface) json["surface"] = comparison.surface.json;
  return json;
}

// report.png; "" or why there is none.
std::string plotRun(const RunRecord& run, const std::optional<GroundTruthComparison>& comparison,
                    const std::vector<double>& odometry_ms, const std::vector<double>& integrate_ms,
                    const std::string& path) {
  evaluation::RunPlotData plot;
  for (const io::StampedPose& pose : run.poses) plot.estimate.push_back(pose.pose);
  if (comparison) {
    plot.estimate = comparison->trajectory.aligned_estimate;
    plot.ground_truth = comparison->trajectory.ground_truth;
    plot.position_errors_m = comparison->trajectory.position_errors_m;
  }
  plot.odometry_ms = odometry_ms;
  plot.integrate_ms = integrate_ms;
  for (const FrameRecord& record : run.records) {
    plot.inlier_share.push_back(record.inlier_share);
    plot.moving_share.push_back(record.moving_share);
    plot.degenerate.push_back(record.degenerate);
    plot.suspect.push_back(record.suspect);
  }
  try {
    evaluation::plotRunReport(plot, path);
    return "";
  } catch (const evaluation::PlotError& error) {
    return std::string("no report.png: ") + error.what();
  }
}

void printSummary(const RunRecord& run, const Json::Value& report,
                  const std::optional<GroundTruthComparison>& comparison) {
  const Json::Value& timing = report["timing"];
  std::cout << run.frames << " scans (" << run.poses.size() << " poses; " << run.health.line() << "; " << run.refused
            << " refused by the map)\n"
            << "odometry " << timing["odometry_frames_per_second"].asDouble() << " frames/s ("
            << timing["odometry_ms"]["median"].asDouble() << " ms median), mapping "
            << timing["mapping_frames_per_second"].asDouble() << " frames/s ("
            << timing["integrate_ms"]["median"].asDouble() << " ms median)\n";
  if (comparison) {
    std::cout << "ATE " << comparison->trajectory.absolute_translation_m.rmse << " m against the ground truth";
    if (comparison->trajectory.kitti.segments > 0)
      std::cout << "; RPE " << comparison->trajectory.kitti.translation_percent << " %, "
                << 100.0 * comparison->trajectory.kitti.rotation_deg_per_m << " deg/100 m";
    std::cout << "\n";
    if (comparison->has_surface) std::cout << "mesh: " << comparison->surface.summary_line << "\n";
  }
  const Json::Value& outputs = report["outputs"];
  std::cout << "mesh " << outputs["mesh"].asString() << " (" << report["mapping"]["triangles"].asUInt64()
            << " triangles, " << report["mapping"]["memory_bytes"].asDouble() / (1 << 20)
            << " MiB of voxels); report " << outputs["report_json"].asString();
  if (outputs.isMember("report_png")) std::cout << " and " << outputs["report_png"].asString();
  std::cout << "; trajectory " << outputs["trajectory_kitti"].asString() << "\n";
}

int runPipeline(RunCommandOptions options, const Command& command) {
  const auto started = Clock::now();
  const fs::path out(options.output_directory);
  fs::create_directories(out);
  const std::vector<std::string> presets = simulationPresetNames();
  const bool preset = std::find(presets.begin(), presets.end(), options.recording.input) != presets.end() &&
                      !fs::exists(options.recording.input);
  std::string environment = options.environment;
  if (preset && environment.empty()) environment = isIndoorPreset(options.recording.input) ? "indoor" : "outdoor";
  if (environment.empty()) environment = "outdoor";
  applyEnvironment(environment, command, options);
  pipeline::ScanToMapPipeline pipeline(pipelineOptions(options));  // bad options fail before any work
  const io::Recording recording = io::openRecording(simulateIfPreset(options, preset, out));
  // The map's world is the base at the first scan, as the nodelets': for an
  // Ouster recording the sensor frame (os_sensor), whose lidar frame the
  // images are in. Poses are written of the lidar frame as before.
  const Eigen::Isometry3d base_from_lidar =
      recording.ouster ? recording.ouster->intrinsics.lidar_to_sensor : Eigen::Isometry3d::Identity();
  pipeline.setBaseFromLidar(base_from_lidar);
  std::cerr << "odometry and mapping over " << recording.description << " (" << environment << ": voxel "
            << options.map.grid.voxel_size_m << " m, range clip " << options.map.integrator.max_range_m
            << " m); Ctrl-C stops and saves\n";
  reportSensorModel(recording);

  RunRecord run = runScans(pipeline, recording, out);
  std::vector<io::StampedPose> lidar_poses = run.poses;  // in the odometry's world: the lidar at the first scan
  for (io::StampedPose& pose : lidar_poses) pose.pose = base_from_lidar.inverse() * pose.pose;

  mapping::TsdfMap& map = *pipeline.map();
  const auto mesh_started = Clock::now();
  const TriangleMesh mesh = map.fullMesh();
  run.mesh_seconds += secondsSince(mesh_started);
  const mapping::MapStatistics statistics = map.statistics();
  Json::Value report;
  Json::Value& outputs = report["outputs"];
  outputs["mesh"] = (out / "mesh.ply").string();
  outputs["trajectory_kitti"] = (out / "trajectory.txt").string();
  outputs["odometry_frames"] = (out / "odometry_frames.csv").string();
  outputs["report_json"] = (out / "report.json").string();
  writeMeshAtomically(outputs["mesh"].asString(), mesh);
  outputs["trajectory_tum"] = writeTrajectory(outputs["trajectory_kitti"].asString(), lidar_poses, recording,
                                              options.sensor_frame, "rim run " + recording.input);

  report["input"] = recording.input;
  report["description"] = recording.description;
  report["environment"] = environment;
  report["interrupted"] = bool(interrupted);
  report["frames"] = run.frames;
  report["poses"] = Json::UInt64(run.poses.size());
  report["reading"] = run.reading_json;
  report["odometry"] = options.odometry.json(recording.model.get());
  const Json::Value health = run.health.json();
  for (const std::string& key : health.getMemberNames()) report["odometry"][key] = health[key];
  report["mapping"] = mapOptionsJson(options.map, options.odometry.options().deskew);
  report["mapping"]["scans_refused"] = run.refused;
  report["mapping"]["blocks"] = Json::UInt64(statistics.blocks);
  report["mapping"]["memory_bytes"] = Json::UInt64(statistics.memory_bytes);
  report["mapping"]["vertices"] = Json::UInt64(mesh.vertices.size());
  report["mapping"]["triangles"] = Json::UInt64(mesh.triangles.size());
  std::vector<double> odometry_ms, integrate_ms, inliers;
  for (const FrameRecord& record : run.records) inliers.push_back(double(record.inliers));
  report["timing"] = timingJson(run, odometry_ms, integrate_ms);
  report["inliers"] = statisticsJson(inliers);
  report["peak_resident_megabytes"] = peakResidentMegabytes();

  std::optional<GroundTruthComparison> comparison;
  if (!recording.ground_truth.poses.empty()) {
    comparison =
        compareWithGroundTruth(recording, run.poses, mesh, options.map.grid.voxel_size_m,
                               options.map.integrator.max_range_m, (out / "mesh_in_ground_truth_frame.ply").string());
    report["ground_truth"] = groundTruthJson(*comparison);
  }
  report["wall_seconds"] = secondsSince(started);
  std::string plot_note;
  if (!options.no_plot) {
    plot_note = plotRun(run, comparison, odometry_ms, integrate_ms, (out / "report.png").string());
    if (plot_note.empty()) outputs["report_png"] = (out / "report.png").string();
  }
  Json::Value written = report;
  written["outputs"].removeMember("report_json");
  writeJsonFile(outputs["report_json"].asString(), written);
  printSummary(run, report, comparison);
  if (!plot_note.empty()) std::cerr << plot_note << "\n";
  return reportHealth(run.health);
}

}  // namespace

void addRunCommand(Command& rim) {
  auto options = std::make_shared<RunCommandOptions>();
  Command& command = rim.subcommand(
      "run",
      "Odometry and TSDF mapping over a recording or a simulated preset, with no ROS master: trajectory "
      "(KITTI, TUM), mesh.ply, report.json and report.png in --out; against ground truth when there is some");
  std::string preset_names;
  for (const std::string& name : simulationPresetNames()) preset_names += (preset_names.empty() ? "" : ", ") + name;
  command.option("--out,-o", options->output_directory, "output folder").required();
  addRecordingOptions(command, options->recording,
                      "a folder from rim simulate, an Ouster pcap (with --metadata), a KITTI velodyne folder, or a "
                      "preset to simulate first (" + preset_names + ")",
                      "process only the first N scans (a preset: simulate N)");
  command.option("--environment", options->environment,
                 "indoor (4 cm voxels, 10 m clip, kernel 0.2 m) or outdoor (10 cm, 30 m, 0.5 m); default: "
                 "the preset's, else outdoor")
      .check(oneOf({"indoor", "outdoor"}));
  command.flag("--sensor-frame", options->sensor_frame, "write poses of the Ouster sensor frame");
  command.option("--mesh-period", options->mesh_period_s,
                 "update the mesh after this many seconds of scan time (the Mapper's mesh_period)")
      .showDefault()
      .check(positive());
  command.flag("--no-plot", options->no_plot, "do not draw report.png");
  command.flag("--bag", options->simulate_bag,
               "a preset also writes sequence/packets.bag (Ouster packets), to replay through "
               "range_image_mapping.launch");
  addOdometryOptions(command, options->odometry);
  addMapOptions(command, options->map);
  command.callback([options, &command] { runPipeline(*options, command); });
}

}  // namespace range_image_mapping::tool
