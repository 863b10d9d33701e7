#include "outputs.h"

#include "range_image_mapping/evaluation/report.h"
#include "range_image_mapping/evaluation/surface_metrics.h"
#include "range_image_mapping/io/mesh_file.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <sstream>

namespace range_image_mapping::tool {

namespace fs = std::filesystem;

double median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

std::string siblingPath(const std::string& output, const std::string& suffix) {
  fs::path path(output);
  return (path.parent_path() / (path.stem().string() + "_" + suffix)).string();
}

void writeJsonFile(const std::string& path, const Json::Value& value) {
  const fs::path json_path(path);
  if (!json_path.parent_path().empty()) fs::create_directories(json_path.parent_path());
  std::ofstream file(path);
  file << Json::writeString(Json::StreamWriterBuilder(), value) << "\n";
  file.close();
  if (!file) throw std::runtime_error("cannot write " + path);
}

registration::OdometryOptions OdometryCommandLine::options() const {
  registration::OdometryOptions options;
  options.deskew = !no_deskew;
  options.deskew_passes = deskew_passes;
  options.registration.kernel.scale_m = kernel_scale_m;
  options.registration.max_correspondence_distance_m = max_correspondence_distance_m;
  options.model.keyframes = std::size_t(model_keyframes);
  options.moving_margin_m = moving_margin_m;
  options.registration.area_weight_max_range_m = area_weight_max_range_m;
  options.model.keyframe_distance_m = keyframe_distance_m;
  options.model.keyframe_angle_rad = keyframe_angle_deg * M_PI / 180.0;
  options.model.keyframe_range_share = keyframe_range_share;
  options.model.max_keyframe_distance_m = max_keyframe_distance_m;
  options.model.normal_radius_m = model_normal_radius_m;
  return options;
}

Json::Value OdometryCommandLine::json(const LidarModel* sensor) const {
  Json::Value json;
  json["deskew"] = !no_deskew;
  json["deskew_passes"] = deskew_passes;
  json["kernel_scale_m"] = kernel_scale_m;
  json["max_correspondence_distance_m"] = options().registration.correspondenceDistance();
  json["model_keyframes"] = model_keyframes;
  json["moving_margin_m"] = moving_margin_m;
  json["area_weight_max_range_m"] = area_weight_max_range_m;
  if (sensor) json["area_weight_range_in_use_m"] = registration::areaWeightRange(options().registration, *sensor);
  json["keyframe_distance_m"] = keyframe_distance_m;
  if (sensor) json["keyframe_distance_least_m"] = registration::keyframeDistance(options().model, *sensor);
  json["keyframe_range_share"] = keyframe_range_share;
  json["max_keyframe_distance_m"] = max_keyframe_distance_m;
  json["keyframe_angle_deg"] = keyframe_angle_deg;
  json["model_normal_radius_m"] = model_normal_radius_m;
  return json;
}

void addRecordingOptions(Command& command, io::RecordingOptions& recording, const std::string& input_help,
                         const std::string& frames_help) {
  command.option("input", recording.input, input_help).required();
  command.option("--metadata,-m", recording.metadata, "Ouster metadata JSON of the pcap or packet bag")
      .check(existingFile());
  command.flag("--kitti", recording.kitti, "INPUT is a KITTI velodyne folder (synthetic HDL-64E model)");
  command.option("--sensor", recording.sensor,
                 "sensor file (YAML from rim sensor estimate, or Ouster metadata JSON) or named model (VLP-16, "
                 "HDL-64E, ...: see the README) for point clouds (default: KITTI's HDL-64E for a KITTI folder, "
                 "else estimated from the first scans)");
  command.option("--topic", recording.topic,
                 "the bag's topic to read: PointCloud2 or Ouster packets (default: the only one)");
  command.option("--frames", recording.frames, frames_help).check(positive());
}

void reportSensorModel(const io::Recording& recording) {
  const io::RecordingModel& model = recording.model_info;
  if (!model.summary.empty()) std::cerr << model.summary << "\n";
  if (!model.warning.empty()) std::cerr << "warning: " << model.warning << "\n";
}

Json::Value reportReading(const io::RecordingStatistics& reading) {
  Json::Value json;
  json["scans"] = Json::UInt64(reading.scans);
  json["unreadable"] = Json::UInt64(reading.unreadable);
  Json::Value& examples = json["unreadable_examples"] = Json::arrayValue;
  for (const std::string& example : reading.unreadable_examples) examples.append(example);
  json["stopped_early"] = reading.stopped_early;
  if (reading.packets) {
    json["packets_dropped"] =
        Json::UInt64(reading.packets->wrong_size + reading.packets->malformed + reading.packets->bad_checksum);
    json["incomplete_scans"] = Json::UInt64(reading.packets->incomplete_scans);
    json["missing_columns"] = Json::UInt64(reading.packets->missing_columns);
  }
  if (reading.pcap) {
    json["pcap_records_truncated"] = Json::UInt64(reading.pcap->skipped_truncated);
    json["pcap_records_malformed"] = Json::UInt64(reading.pcap->skipped_malformed);
    json["pcap_fragments_dropped"] = Json::UInt64(reading.pcap->fragments_dropped);
  }
  const std::string warning = io::readingLossWarning(reading);
  json["warning"] = warning;
  if (!warning.empty()) std::cerr << "warning: " << warning << "\n";
  return json;
}

void addOdometryOptions(Command& command, OdometryCommandLine& odometry) {
  command.flag("--no-deskew", odometry.no_deskew, "register and map the scans as measured");
  command.option("--deskew-passes", odometry.deskew_passes,
                 "at most this many times a scan is deskewed again with the velocity its registration "
                 "gave and registered again (0: deskewed with the previous step's velocity only)")
      .showDefault()
      .check(nonNegative());
  command.option("--kernel-scale", odometry.kernel_scale_m, "robust kernel scale, m (paper: 0.5 outdoors, 0.2 indoors)")
      .showDefault()
      .check(positive());
  command.option("--max-correspondence-distance", odometry.max_correspondence_distance_m,
                 "distance gate of a pair at full resolution, m (0: twice the kernel scale)")
      .showDefault()
      .check(nonNegative());
  command.option("--moving-margin", odometry.moving_margin_m,
                 "a pixel this far in front of the model's surface (a third of it in two scans running) is moving: "
                 "left out of the model and the map; "
                 "this far behind it, facing the same way, stale: left out of the next registration, m (0: off)")
      .showDefault()
      .check(nonNegative());
  command.option("--area-weight-range", odometry.area_weight_max_range_m,
                 "pairs weighted by their pixel's area (range^2) up to this range, m (0: all alike)")
      .showDefault()
      .check(nonNegative());
  command.option("--model-keyframes", odometry.model_keyframes,
                 "keyframes in the local model each scan is registered to (1 with --keyframe-distance 0 "
                 "and --keyframe-angle 0: the previous scan)")
      .showDefault()
      .check(positive());
  command.option("--keyframe-distance", odometry.keyframe_distance_m,
                 "a scan becomes a keyframe this far from the newest one, m (0: every scan)")
      .showDefault()
      .check(nonNegative());
  command.option("--keyframe-angle", odometry.keyframe_angle_deg, "... or after this rotation, degrees (0: off)")
      .showDefault()
      .check(nonNegative());
  command.option("--keyframe-range-share", odometry.keyframe_range_share,
                 "the keyframe distance is raised to this share of the newest keyframe's median range, up to "
                 "--max-keyframe-distance (0: off)")
      .showDefault()
      .check(nonNegative());
  command.option("--max-keyframe-distance", odometry.max_keyframe_distance_m,
                 "... up to this distance, m (it does not lower --keyframe-distance or a sparse sensor's)")
      .showDefault()
      .check(nonNegative());
  command.option("--model-normal-radius", odometry.model_normal_radius_m,
                 "the local model's normals from its keyframes' points within this radius, m (0: each "
                 "keyframe's own, from its scan's neighbouring pixels)")
      .showDefault()
      .check(nonNegative());
}

void addMapOptions(Command& command, mapping::TsdfMapOptions& map) {
  command.option("--voxel", map.grid.voxel_size_m, "voxel size, m").showDefault();
  command.option("--truncation", map.integrator.truncation_m, "TSDF truncation, m (0: 3 voxels)").showDefault();
  command.option("--block-edge", map.grid.block_edge, "voxels per block edge: 8 or 16").showDefault();
  command.option("--min-range", map.integrator.min_range_m, "ignore returns closer than this, m").showDefault();
  command.option("--max-range", map.integrator.max_range_m, "ignore returns farther than this, m").showDefault();
  command.option("--stride", map.integrator.point_stride, "block activation reads every N-th pixel in rows and columns")
      .showDefault();
  command.option("--max-weight", map.integrator.max_weight, "running-average weight cap").showDefault();
  command.option("--memory-radius", map.memory_radius_m,
                 "drop blocks farther than this from the sensor, m (0: keep all); their mesh is kept")
      .showDefault();
  command.flag("--intensity", map.grid.store_intensity, "store intensity in the voxels and the mesh");
}

Json::Value mapOptionsJson(const mapping::TsdfMapOptions& map, bool deskew) {
  Json::Value json;
  json["voxel_m"] = map.grid.voxel_size_m;
  json["block_edge"] = map.grid.block_edge;
  json["truncation_m"] = map.integrator.truncationFor(map.grid);
  json["min_range_m"] = map.integrator.min_range_m;
  json["max_range_m"] = map.integrator.max_range_m;
  json["point_stride"] = map.integrator.point_stride;
  json["max_weight"] = map.integrator.max_weight;
  json["memory_radius_m"] = map.memory_radius_m;
  json["intensity"] = map.grid.store_intensity;
  json["deskew"] = deskew;
  return json;
}

void OdometryHealth::add(const registration::OdometryUpdate& update) {
  degenerate_ += update.degenerate;
  untrusted_ += update.limit_exceeded;
  suspect_ += update.suspect;
  resets_ += update.reset && frames_ > 0;
  skipped_ += update.skipped;
  ++frames_;
  keyframes_ += update.keyframe;
  levels_passed_over_ += update.levels_passed_over > 0;
  every_coarse_level_passed_over_ += update.every_coarse_level_passed_over;
  if (update.skipped || update.reset) return;
  ++registered_;
  keyframe_distance_m_ += update.keyframe_distance_m;
  inlier_share_ += update.inlierShare();
  moving_share_ += update.movingShare();
  most_moving_share_ = std::max(most_moving_share_, update.movingShare());
  prior_difference_m_ += update.prior_difference_m;
}

Json::Value OdometryHealth::json() const {
  const double registered = std::max(1, registered_);
  Json::Value json;
  json["degenerate"] = degenerate_;
  json["untrusted"] = untrusted_;
  json["suspect"] = suspect_;
  json["resets"] = resets_;
  json["skipped"] = skipped_;
  json["mean_inlier_share"] = inlier_share_ / registered;
  json["mean_moving_share"] = moving_share_ / registered;
  json["max_moving_share"] = most_moving_share_;
  json["mean_prior_difference_m"] = prior_difference_m_ / registered;
  json["scans_with_coarse_levels_passed_over"] = levels_passed_over_;
  json["scans_with_every_coarse_level_passed_over"] = every_coarse_level_passed_over_;
  json["keyframes"] = keyframes_;
  json["keyframe_distance_in_use_m"] = keyframe_distance_m_ / registered;  // mean over registered scans
  return json;
}

std::string OdometryHealth::line() const {
  const double registered = std::max(1, registered_);
  std::ostringstream text;
  text.precision(3);
  text << degenerate_ << " degenerate (" << untrusted_ << " untrusted), " << suspect_ << " suspect, " << resets_
       << " resets, " << skipped_ << " skipped; pixels paired " << 100.0 * inlier_share_ / registered
       << " %, moving " << 100.0 * moving_share_ / registered << " % (most " << 100.0 * most_moving_share_
       << " %); coarse levels passed over in " << levels_passed_over_ << " scans (every one in "
       << every_coarse_level_passed_over_ << "); " << keyframes_ << " keyframes " << keyframe_distance_m_ / registered
       << " m apart";
  return text.str();
}

bool OdometryHealth::failed() const { return 2 * (degenerate_ + skipped_) > frames_; }

std::string OdometryHealth::warning() const {
  if (frames_ == 0) return {};
  if (2 * skipped_ > frames_)
    return std::to_string(skipped_) + " of " + std::to_string(frames_) +
           " scans were skipped: empty range images (a sensor model that places none of the points: check it "
           "with rim sensor check INPUT, or give the sensor with --sensor) or stamps that did not advance; the "
           "frames CSV names each";
  if (failed())
    return std::to_string(degenerate_) + " of " + std::to_string(frames_) + " scans were degenerate" +
           (skipped_ ? " and " + std::to_string(skipped_) + " skipped" : std::string()) +
           ": the trajectory is mostly the motion prior (check the sensor model against the data, and the scene)";
  if (2 * suspect_ > frames_)
    return std::to_string(suspect_) + " of " + std::to_string(frames_) +
           " scans were suspect (few pixels paired, or moving objects filling the view): check the warnings in "
           "the frames CSV";
  if (2 * every_coarse_level_passed_over_ > frames_)
    return std::to_string(every_coarse_level_passed_over_) + " of " + std::to_string(frames_) +
           " scans passed over every coarse pyramid level (fewer than min_coarse_pairs pairs): only full resolution "
           "registered them, with a short capture range; check the sensor model (rim sensor check INPUT) or use "
           "fewer, finer strides";
  return {};
}

int reportHealth(const OdometryHealth& health) {
  const std::string warning = health.warning();
  if (warning.empty()) return 0;
  std::cerr << (health.failed() ? "error: " : "warning: ") << warning << "\n";
  return health.failed() ? 3 : 0;
}

OdometryFramesCsv::OdometryFramesCsv(const std::string& path) : path_(path), file_(path) {
  if (!file_) throw std::runtime_error("cannot write " + path);
  file_ << "frame,time_s,seconds,inliers,iterations,levels_passed_over,condition_number,residual_rms_m,"
           "degenerate,reset,skipped,valid_pixels,inlier_share,moving_share,prior_difference_m,"
           "prior_difference_deg,keyframe,keyframe_distance_m,warning\n";
}

void OdometryFramesCsv::add(int frame, const registration::OdometryUpdate& update) {
  std::string warning = update.warning;
  std::replace(warning.begin(), warning.end(), ',', ';');
  file_ << frame << ',' << std::setprecision(15) << double(update.stamp_ns) * 1e-9 << std::setprecision(6) << ','
        << update.seconds << ',' << update.inliers << ',' << update.iterations << ','
        << update.levels_passed_over << ',' << update.condition_number << ',' << update.residual_rms_m << ','
        << update.degenerate << ',' << update.reset << ',' << update.skipped << ',' << update.valid_pixels << ','
        << update.inlierShare() << ',' << update.movingShare() << ',' << update.prior_difference_m << ','
        << update.prior_difference_rad * 180.0 / M_PI << ',' << update.keyframe << ',' << update.keyframe_distance_m
        << ',' << warning << '\n';
}

void OdometryFramesCsv::close() {
  file_.close();
  if (!file_) throw std::runtime_error("cannot write " + path_);
}

std::string writeTrajectory(const std::string& kitti_path, const std::vector<io::StampedPose>& poses,
                            const io::Recording& recording, bool sensor_frame, const std::string& comment) {
  if (sensor_frame && !recording.ouster)
    throw std::invalid_argument("poses of the sensor frame: " + recording.input + " has no Ouster sensor frame");
  io::PoseFileInfo info;
  info.frame = sensor_frame ? "os_sensor" : recording.frame;
  info.world = "odom";
  info.comment = comment;
  const std::vector<io::StampedPose> written =
      sensor_frame ? io::changePoseFrame(poses, recording.ouster->intrinsics.lidar_to_sensor) : poses;
  const fs::path output(kitti_path);
  if (!output.parent_path().empty()) fs::create_directories(output.parent_path());
  io::writeKittiPosesWithTimes(kitti_path, written, info);
  const std::string tum_path = siblingPath(kitti_path, "tum.txt");
  io::writeTumPoses(tum_path, written, info);
  return tum_path;
}

void writeMeshAtomically(const std::string& path, const TriangleMesh& mesh) {
  const fs::path destination(path);
  if (!destination.parent_path().empty()) fs::create_directories(destination.parent_path());
  const fs::path partial = destination.parent_path() / (destination.stem().string() + ".partial.ply");
  try {
    io::saveMeshFile(partial.string(), mesh);
  } catch (...) {
    fs::remove(partial);
    throw;
  }
  fs::rename(partial, destination);
}

namespace {

SurfaceEvaluation evaluateSamples(const std::string& mesh_path, const evaluation::SurfaceSample& estimate,
                                  const std::string& truth_path, const evaluation::SurfaceSample& truth,
                                  double voxel_m, double spacing_m) {
  const evaluation::SurfaceMetrics metrics =
      evaluation::compareSurfaces(estimate.points, truth.points, 3.0 * voxel_m);
  evaluation::SurfaceReportContext context;
  context.estimate = evaluation::describeSurface(mesh_path, estimate);
  context.ground_truth = evaluation::describeSurface(truth_path, truth);
  context.voxel_m = voxel_m;
  context.sample_spacing_m = spacing_m;
  SurfaceEvaluation result;
  std::istringstream text(evaluation::surfaceReportJson(metrics, context));
  std::string errors;
  Json::parseFromStream(Json::CharReaderBuilder(), text, &result.json, &errors);
  result.summary_line = evaluation::surfaceSummaryLine(metrics);
  result.f_score = metrics.f_score;
  return result;
}

evaluation::SurfaceSamplingOptions samplingFor(double voxel_m) {
  evaluation::SurfaceSamplingOptions sampling;
  sampling.spacing_m = 3.0 * voxel_m / 4.0;  // a quarter of the threshold, as rim eval mesh
  return sampling;
}

}  // namespace

SurfaceEvaluation evaluateMeshFile(const std::string& mesh_path, const std::string& truth_path, double voxel_m) {
  const evaluation::SurfaceSamplingOptions sampling = samplingFor(voxel_m);
  return evaluateSamples(mesh_path, evaluation::loadSurfaceSample(mesh_path, sampling), truth_path,
                         evaluation::loadSurfaceSample(truth_path, sampling), voxel_m, sampling.spacing_m);
}

SurfaceEvaluation evaluateMeshFileWithinRange(const std::string& mesh_path, const std::string& truth_path,
                                              double voxel_m, const std::vector<Eigen::Vector3f>& sensor_positions,
                                              double range_m) {
  const evaluation::SurfaceSamplingOptions sampling = samplingFor(voxel_m);
  evaluation::SurfaceSample truth = evaluation::loadSurfaceSample(truth_path, sampling);
  const std::vector<float> distances = evaluation::nearestDistances(truth.points, sensor_positions);
  std::size_t kept = 0;
  for (std::size_t i = 0; i < truth.points.size(); ++i)
    if (distances[i] <= range_m) truth.points[kept++] = truth.points[i];
  truth.points.resize(kept);
  SurfaceEvaluation result = evaluateSamples(mesh_path, evaluation::loadSurfaceSample(mesh_path, sampling),
                                             truth_path, truth, voxel_m, sampling.spacing_m);
  result.json["ground_truth_within_range_m"] = range_m;
  return result;
}

}  // namespace range_image_mapping::tool
