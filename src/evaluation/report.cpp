#include "range_image_mapping/evaluation/report.h"

#include "range_image_mapping/io/ply.h"

#include <json/json.h>

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <sstream>

extern char** environ;

namespace range_image_mapping::evaluation {
namespace {

// ---------------------------------------------------------------- JSON

Json::Value toJson(const ErrorStatistics& statistics) {
  Json::Value value(Json::objectValue);
  value["count"] = Json::UInt64(statistics.count);
  value["rmse"] = statistics.rmse;
  value["mean"] = statistics.mean;
  value["std"] = statistics.standard_deviation;
  value["min"] = statistics.minimum;
  value["q1"] = statistics.first_quartile;
  value["median"] = statistics.median;
  value["q3"] = statistics.third_quartile;
  value["max"] = statistics.maximum;
  return value;
}

template <typename Values>
Json::Value toJsonArray(const Values& values) {
  Json::Value array(Json::arrayValue);
  for (const auto& value : values) array.append(value);
  return array;
}

Json::Value toJson(const std::vector<std::size_t>& values) {
  Json::Value array(Json::arrayValue);
  for (const std::size_t value : values) array.append(Json::UInt64(value));
  return array;
}

const char* alignmentName(Alignment alignment) {
  switch (alignment) {
    case Alignment::kNone:
      return "none";
    case Alignment::kSE3:
      return "se3";
    case Alignment::kSim3:
      return "sim3";
  }
  return "?";
}

Json::Value toJson(const SimilarityTransform& transform, Alignment alignment) {
  Json::Value value(Json::objectValue);
  value["method"] = alignmentName(alignment);
  Json::Value rotation(Json::arrayValue);
  for (int row = 0; row < 3; ++row)
    rotation.append(toJsonArray(std::array<double, 3>{transform.rotation(row, 0),
                                                      transform.rotation(row, 1),
                                                      transform.rotation(row, 2)}));
  value["rotation"] = rotation;
  value["translation"] = toJsonArray(std::array<double, 3>{
      transform.translation.x(), transform.translation.y(), transform.translation.z()});
  value["scale"] = transform.scale;
  return value;
}

Json::Value toJson(const ReportNotes& notes, Json::Value report) {
  report["outputs"] = toJsonArray(notes.outputs);
  report["warnings"] = toJsonArray(notes.warnings);
  return report;
}

Json::Value toJson(const SurfaceSource& source) {
  Json::Value value(Json::objectValue);
  value["path"] = source.path;
  value["type"] = source.from_mesh ? "mesh" : "point_cloud";
  value["vertices"] = Json::UInt64(source.vertex_count);
  value["triangles"] = Json::UInt64(source.triangle_count);
  value["area_m2"] = source.area_m2;
  value["points"] = Json::UInt64(source.points);
  return value;
}

std::string writeJson(const Json::Value& value) {
  Json::StreamWriterBuilder builder;
  builder["indentation"] = "  ";
  builder["precision"] = 12;
  return Json::writeString(builder, value) + "\n";
}

std::string formatted(const char* format, double value) {
  std::array<char, 64> text{};
  std::snprintf(text.data(), text.size(), format, value);
  return text.data();
}

// ---------------------------------------------------------------- gnuplot

// A gnuplot single-quoted string: only the quote itself needs doubling.
std::string quoted(const std::string& text) {
  std::string result = "'";
  for (const char c : text) result += c == '\'' ? std::string("''") : std::string(1, c);
  return result + "'";
}

// A private folder for the data and script, removed when done.
class TemporaryDirectory {
 public:
  TemporaryDirectory() {
    std::string pattern = (std::filesystem::temp_directory_path() / "rim_plot_XXXXXX").string();
    if (!mkdtemp(pattern.data())) throw PlotError("cannot create a temporary folder for gnuplot");
    path_ = pattern;
  }
  ~TemporaryDirectory() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  TemporaryDirectory(const TemporaryDirectory&) = delete;
  TemporaryDirectory& operator=(const TemporaryDirectory&) = delete;
  std::string file(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

std::string readText(const std::string& path) {
  std::ifstream file(path);
  return std::string((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
}

// Runs gnuplot on the script (no shell: paths need no escaping); its output
// goes to a log that becomes the error message when it fails.
void runGnuplot(const TemporaryDirectory& directory, const std::string& script,
                const std::string& png_path) {
  const std::string gnuplot = findGnuplot();
  if (gnuplot.empty())
    throw PlotError("gnuplot not found on PATH (Debian package gnuplot-nox): no " + png_path);
  const std::string script_path = directory.file("plot.gp");
  const std::string log_path = directory.file("gnuplot.log");
  {
    std::ofstream file(script_path);
    file << script;
    if (!file) throw PlotError("cannot write the gnuplot script " + script_path);
  }
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log_path.c_str(),
                                   O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  std::array<char*, 3> arguments{const_cast<char*>(gnuplot.c_str()),
                                 const_cast<char*>(script_path.c_str()), nullptr};
  pid_t child = 0;
  const int spawned =
      posix_spawn(&child, gnuplot.c_str(), &actions, nullptr, arguments.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawned != 0) throw PlotError("cannot start " + gnuplot + " for " + png_path);
  int status = 0;
  while (waitpid(child, &status, 0) < 0 && errno == EINTR) {
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0 || !std::filesystem::exists(png_path)) {
    std::error_code ignored;
    std::filesystem::remove(png_path, ignored);  // gnuplot opens the output before it fails
    throw PlotError("gnuplot failed to draw " + png_path + ": " + readText(log_path));
  }
}

// Shared look: PNG of a fixed size, light grid.
std::string scriptHeader(const std::string& png_path, int width, int height) {
  std::ostringstream script;
  script << "set terminal pngcairo size " << width << "," << height << " font 'sans,11'\n"
         << "set output " << quoted(png_path) << "\n"
         << "set grid lc rgb '#dddddd'\n";
  return script.str();
}

// The two axes the ground truth spreads over most, in x-y-z order: x-y for a
// lidar or body frame (z up), x-z for KITTI's camera frame (y down), as evo plots them.
std::array<int, 2> topViewAxes(const std::vector<Eigen::Isometry3d>& poses) {
  Eigen::Vector3d minimum = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d maximum = -minimum;
  for (const Eigen::Isometry3d& pose : poses) {
    minimum = minimum.cwiseMin(pose.translation());
    maximum = maximum.cwiseMax(pose.translation());
  }
  int flattest = 2;  // z unless another axis spreads clearly less
  const Eigen::Vector3d extent = maximum - minimum;
  for (int axis = 0; axis < 2; ++axis)
    if (extent[axis] < 0.5 * extent[flattest]) flattest = axis;
  if (flattest == 0) return {1, 2};
  if (flattest == 1) return {0, 2};
  return {0, 1};
}

// gnuplot's ranges for a top view of these points (nothing where none is finite).
std::string topViewRangeCommands(const std::vector<Eigen::Vector2d>& points) {
  const TopViewRanges ranges = topViewRanges(points);
  if (ranges.empty) return {};
  std::ostringstream text;
  text.precision(10);
  text << "set xrange [" << ranges.minimum.x() << ":" << ranges.maximum.x() << "]\nset yrange ["
       << ranges.minimum.y() << ":" << ranges.maximum.y() << "]\n";
  return text.str();
}

// ---------------------------------------------------------------- colours

using Colour = std::array<uint8_t, 3>;

// Blue through cyan and green to yellow over [0, 1); red at 1 and beyond.
Colour distanceColour(double fraction) {
  if (!(fraction < 1.0)) return {255, 0, 0};
  static constexpr std::array<std::array<double, 3>, 4> kStops{
      {{40, 60, 220}, {0, 190, 220}, {40, 200, 60}, {240, 220, 0}}};
  const double position = std::max(0.0, fraction) * (kStops.size() - 1);
  const auto below = std::min(static_cast<std::size_t>(position), kStops.size() - 2);
  const double weight = position - static_cast<double>(below);
  Colour colour;
  for (int channel = 0; channel < 3; ++channel)
    colour[channel] = static_cast<uint8_t>(
        kStops[below][channel] + weight * (kStops[below + 1][channel] - kStops[below][channel]) + 0.5);
  return colour;
}

}  // namespace

// ---------------------------------------------------------------- reports

SurfaceSource describeSurface(const std::string& path, const SurfaceSample& sample) {
  SurfaceSource source;
  source.path = path;
  source.from_mesh = sample.from_mesh;
  source.vertex_count = sample.vertex_count;
  source.triangle_count = sample.triangle_count;
  source.points = sample.points.size();
  source.area_m2 = sample.area_m2;
  return source;
}

std::string trajectoryReportJson(const TrajectoryEvaluation& evaluation,
                                 const TrajectoryReportContext& context) {
  Json::Value report(Json::objectValue);
  report["kind"] = "trajectory";
  report["estimate"]["path"] = context.estimate_path;
  report["estimate"]["poses"] = Json::UInt64(context.estimate_poses);
  report["ground_truth"]["path"] = context.ground_truth_path;
  report["ground_truth"]["poses"] = Json::UInt64(context.ground_truth_poses);
  report["association"]["method"] = context.by_timestamp ? "timestamp" : "index";
  if (context.by_timestamp) report["association"]["max_time_difference_s"] = context.max_time_difference_s;
  report["association"]["pairs"] = Json::UInt64(evaluation.ground_truth.size());
  report["alignment"] = toJson(evaluation.alignment_transform, evaluation.alignment);
  report["ground_truth_length_m"] = evaluation.ground_truth_length_m;

  Json::Value& ate = report["ate"];
  ate["translation_m"] = toJson(evaluation.absolute_translation_m);
  ate["rotation_deg"] = toJson(evaluation.absolute_rotation_deg);
  ate["per_pose_m"] = toJsonArray(evaluation.position_errors_m);

  Json::Value& kitti = report["kitti_rpe"];
  kitti["segments"] = Json::UInt64(evaluation.kitti.segments);
  kitti["translation_percent"] = evaluation.kitti.translation_percent;
  kitti["rotation_deg_per_m"] = evaluation.kitti.rotation_deg_per_m;
  kitti["lengths"] = Json::Value(Json::arrayValue);
  for (const KittiLengthError& length : evaluation.kitti.per_length) {
    Json::Value entry(Json::objectValue);
    entry["length_m"] = length.length_m;
    entry["segments"] = Json::UInt64(length.segments);
    entry["translation_percent"] = length.translation_percent;
    entry["rotation_deg_per_m"] = length.rotation_deg_per_m;
    kitti["lengths"].append(entry);
  }

  Json::Value& frame = report["frame_to_frame"];
  frame["translation_m"] = toJson(evaluation.frame_to_frame.translation_m);
  frame["rotation_deg"] = toJson(evaluation.frame_to_frame.rotation_deg);
  frame["translation_percent"] = evaluation.frame_to_frame.translation_percent;
  frame["rotation_deg_per_m"] = evaluation.frame_to_frame.rotation_deg_per_m;

  report["pairwise"] = Json::Value(Json::arrayValue);
  for (const PairwiseErrors& errors : evaluation.pairwise) {
    Json::Value entry(Json::objectValue);
    entry["frame_distance"] = errors.frame_distance;
    entry["pairs"] = Json::UInt64(errors.first_frames.size());
    entry["rotation_deg"] = toJson(errors.rotation_statistics);
    entry["translation_m"] = toJson(errors.translation_statistics);
    entry["first_frames"] = toJson(errors.first_frames);
    entry["rotation_deg_samples"] = toJsonArray(errors.rotation_deg);
    entry["translation_m_samples"] = toJsonArray(errors.translation_m);
    report["pairwise"].append(entry);
  }
  return writeJson(toJson(context.notes, report));
}

std::string surfaceReportJson(const SurfaceMetrics& metrics, const SurfaceReportContext& context) {
  Json::Value report(Json::objectValue);
  report["kind"] = "surface";
  report["estimate"] = toJson(context.estimate);
  report["ground_truth"] = toJson(context.ground_truth);
  report["threshold_m"] = metrics.threshold_m;
  if (context.voxel_m > 0) report["voxel_m"] = context.voxel_m;
  report["sample_spacing_m"] = context.sample_spacing_m;
  report["seed"] = context.seed;
  report["precision"] = metrics.precision;
  report["recall"] = metrics.recall;
  report["f_score"] = metrics.f_score;
  report["f_score_paper"] = metrics.f_score_paper;
  report["chamfer_m"] = metrics.chamfer_m;
  report["accuracy"]["mean_m"] = metrics.accuracy_mean_m;
  report["accuracy"]["median_m"] = metrics.accuracy_median_m;
  report["completeness"]["mean_m"] = metrics.completeness_mean_m;
  report["completeness"]["median_m"] = metrics.completeness_median_m;
  if (!context.actors_path.empty()) {
    Json::Value& trail = report["moving_actor_trail"];
    trail["actors"] = context.actors_path;
    trail["margin_m"] = context.actor_trail_margin_m;
    trail["estimate_points_inside"] = Json::UInt64(context.actor_trail.points_inside);
    trail["share"] = context.actor_trail.share;
    // Mesh area inside the swept volumes: each area sample stands for area / samples.
    if (context.estimate.from_mesh && context.estimate.points > 0)
      trail["area_m2"] = context.estimate.area_m2 * context.actor_trail.share;
    for (const ActorTrail::PerKind& kind : context.actor_trail.by_kind)
      trail["points_inside_by_kind"][kind.kind] = Json::UInt64(kind.points_inside);
  }
  return writeJson(toJson(context.notes, report));
}

TopViewRanges topViewRanges(const std::vector<Eigen::Vector2d>& points, double least_aspect) {
  TopViewRanges ranges;
  ranges.minimum.setConstant(std::numeric_limits<double>::infinity());
  ranges.maximum = -ranges.minimum;
  for (const Eigen::Vector2d& point : points) {
    if (!point.allFinite()) continue;
    ranges.minimum = ranges.minimum.cwiseMin(point);
    ranges.maximum = ranges.maximum.cwiseMax(point);
    ranges.empty = false;
  }
  if (ranges.empty) return TopViewRanges{};
  // A single point (or a sensor standing still) still gets a range gnuplot can draw.
  constexpr double kLeastSpan_m = 1.0;
  const Eigen::Vector2d extent = ranges.maximum - ranges.minimum;
  const double least = std::max(kLeastSpan_m, std::max(0.0, least_aspect) * extent.maxCoeff());
  for (int axis = 0; axis < 2; ++axis) {
    if (extent[axis] >= least) continue;
    const double middle = 0.5 * (ranges.minimum[axis] + ranges.maximum[axis]);
    ranges.minimum[axis] = middle - 0.5 * least;
    ranges.maximum[axis] = middle + 0.5 * least;
  }
  return ranges;
}

std::string trajectorySummaryLine(const TrajectoryEvaluation& evaluation) {
  std::string line = "ATE " + formatted("%.4f", evaluation.absolute_translation_m.rmse) + " m RMSE (" +
                     alignmentName(evaluation.alignment) + ", " +
                     std::to_string(evaluation.ground_truth.size()) + " poses, " +
                     formatted("%.1f", evaluation.ground_truth_length_m) + " m)";
  if (evaluation.kitti.segments > 0)
    line += " | KITTI RPE " + formatted("%.3f", evaluation.kitti.translation_percent) + " % " +
            formatted("%.5f", evaluation.kitti.rotation_deg_per_m) + " deg/m (" +
            std::to_string(evaluation.kitti.segments) + " segments)";
  else
    line += " | KITTI RPE n/a (path shorter than the shortest segment)";
  if (evaluation.frame_to_frame.translation_m.count > 0)
    line += " | frame-to-frame " + formatted("%.4f", evaluation.frame_to_frame.translation_m.rmse) +
            " m " + formatted("%.4f", evaluation.frame_to_frame.rotation_deg.rmse) + " deg RMSE";
  if (!evaluation.pairwise.empty()) {
    const PairwiseErrors& farthest = evaluation.pairwise.back();
    line += " | d=" + std::to_string(farthest.frame_distance) + " median " +
            formatted("%.4f", farthest.rotation_statistics.median) + " deg " +
            formatted("%.4f", farthest.translation_statistics.median) + " m";
  }
  return line;
}

std::string surfaceSummaryLine(const SurfaceMetrics& metrics) {
  return "F-score " + formatted("%.4f", metrics.f_score) + " (precision " +
         formatted("%.4f", metrics.precision) + ", recall " + formatted("%.4f", metrics.recall) +
         ", paper PR/(P+R) " + formatted("%.4f", metrics.f_score_paper) + ") at " +
         formatted("%.4g", metrics.threshold_m) + " m | Chamfer " +
         formatted("%.4g", metrics.chamfer_m) + " m | " + std::to_string(metrics.estimate_points) +
         " estimate / " + std::to_string(metrics.ground_truth_points) + " ground-truth points";
}

std::string actorTrailSummaryLine(const SurfaceReportContext& context) {
  const ActorTrail& trail = context.actor_trail;
  std::string line = "moving-actor trail: " + std::to_string(trail.points_inside) + " of " +
                     std::to_string(trail.points) + " estimate points (" + formatted("%.3f", 100.0 * trail.share) +
                     " %)";
  if (context.estimate.from_mesh)
    line += ", " + formatted("%.2f", context.estimate.area_m2 * trail.share) + " m2 of mesh";
  line += " inside the volumes the actors swept";
  std::string kinds;
  for (const ActorTrail::PerKind& kind : trail.by_kind)
    kinds += (kinds.empty() ? "" : ", ") + kind.kind + " " + std::to_string(kind.points_inside);
  return line + (kinds.empty() ? "" : " (" + kinds + ")");
}

// ---------------------------------------------------------------- plots

std::string findGnuplot() {
  const char* path = std::getenv("PATH");
  if (!path) return "";
  std::istringstream directories(path);
  for (std::string directory; std::getline(directories, directory, ':');) {
    if (directory.empty()) continue;
    const std::string candidate = directory + "/gnuplot";
    if (access(candidate.c_str(), X_OK) == 0 && !std::filesystem::is_directory(candidate))
      return candidate;
  }
  return "";
}

void plotTrajectoryTopView(const TrajectoryEvaluation& evaluation, const std::string& png_path) {
  const std::array<int, 2> axes = topViewAxes(evaluation.ground_truth);
  static constexpr std::array<const char*, 3> kAxisNames{"x", "y", "z"};
  TemporaryDirectory directory;
  const std::string data_path = directory.file("trajectory.dat");
  std::vector<Eigen::Vector2d> plotted;  // for the ranges
  {
    std::ofstream data(data_path);
    data << "# ground truth " << kAxisNames[axes[0]] << ' ' << kAxisNames[axes[1]]
         << ", aligned estimate the same, position error m\n";
    for (std::size_t i = 0; i < evaluation.ground_truth.size(); ++i) {
      const Eigen::Vector3d& truth = evaluation.ground_truth[i].translation();
      const Eigen::Vector3d& estimate = evaluation.aligned_estimate[i].translation();
      data << truth[axes[0]] << ' ' << truth[axes[1]] << ' ' << estimate[axes[0]] << ' '
           << estimate[axes[1]] << ' ' << evaluation.position_errors_m[i] << '\n';
      plotted.emplace_back(truth[axes[0]], truth[axes[1]]);
      plotted.emplace_back(estimate[axes[0]], estimate[axes[1]]);
    }
  }
  std::ostringstream script;
  script << scriptHeader(png_path, 1000, 900)
         << "set title 'Trajectory top view: ATE RMSE "
         << formatted("%.4f", evaluation.absolute_translation_m.rmse) << " m ("
         << alignmentName(evaluation.alignment) << " alignment)'\n"
         << "set xlabel '" << kAxisNames[axes[0]] << " [m]'\nset ylabel '" << kAxisNames[axes[1]]
         << " [m]'\nset size ratio -1\n"
         << "set cblabel 'position error [m]'\n"
         << "set palette defined (0 '#283cdc', 1 '#00bedc', 2 '#28c83c', 3 '#f0dc00', 4 '#ff0000')\n"
         << "set key below\n"
         // A constant error (e.g. zero) gives no colour range of its own.
         << "stats " << quoted(data_path) << " using 5 nooutput\n"
         << "if (STATS_max <= STATS_min) { set cbrange [STATS_min:STATS_min + 1e-3] }\n"
         // After stats, which would filter the errors column by the x range.
         << topViewRangeCommands(plotted) << "plot " << quoted(data_path)
         << " using 1:2 with lines lw 3 lc rgb '#999999' title 'ground truth', \\\n"
         << "     " << quoted(data_path) << " using 3:4:5 with lines lw 2 palette title 'estimate (aligned)'\n";
  runGnuplot(directory, script.str(), png_path);
}

void plotPairwiseErrors(const TrajectoryEvaluation& evaluation, const std::string& png_path) {
  if (evaluation.pairwise.empty())
    throw PlotError("no pairwise errors to plot for " + png_path + " (fewer than two poses)");
  TemporaryDirectory directory;
  const std::string data_path = directory.file("pairwise.dat");
  {
    std::ofstream data(data_path);
    data << "# frame distance, rotation error deg, translation error m\n";
    for (const PairwiseErrors& errors : evaluation.pairwise)
      for (std::size_t k = 0; k < errors.rotation_deg.size(); ++k)
        data << errors.frame_distance << ' ' << errors.rotation_deg[k] << ' '
             << errors.translation_m[k] << '\n';
  }
  const int largest = evaluation.pairwise.back().frame_distance;
  std::ostringstream script;
  script << scriptHeader(png_path, 1000, 900)
         << "set multiplot layout 2,1 title 'Relative pose error by frame distance (up to "
         << evaluation.pairwise.front().first_frames.size() << " pairs each)'\n"
         << "set style data boxplot\nset style boxplot outliers pointtype 7\nset pointsize 0.5\n"
         << "set style fill solid 0.35 border -1\nset boxwidth 0.5\n"
         << "set xrange [0.4:" << largest << ".6]\nset xtics 1\nset yrange [0:*]\n"
         << "set xlabel 'frame distance'\n"
         << "set ylabel 'rotation error [deg]'\n"
         << "plot for [d=1:" << largest << "] " << quoted(data_path)
         << " using (d):($1 == d ? $2 : 1/0) notitle lc rgb '#4477aa'\n"
         << "set ylabel 'translation error [m]'\n"
         << "plot for [d=1:" << largest << "] " << quoted(data_path)
         << " using (d):($1 == d ? $3 : 1/0) notitle lc rgb '#cc6677'\n"
         << "unset multiplot\n";
  runGnuplot(directory, script.str(), png_path);
}

void plotRunReport(const RunPlotData& data, const std::string& png_path) {
  if (data.estimate.empty()) throw PlotError("no poses to plot for " + png_path);
  const bool truth = data.ground_truth.size() == data.estimate.size();
  const bool errors = data.position_errors_m.size() == data.estimate.size();
  const std::size_t health_scans = data.inlier_share.size();
  const bool health = health_scans > 0 && data.moving_share.size() == health_scans &&
                      data.degenerate.size() == health_scans && data.suspect.size() == health_scans;
  const int panels = 2 + int(errors) + int(health);
  // rim run's poses are of a lidar frame, z up: the top view is x-y.
  const std::array<int, 2> axes{0, 1};
  static constexpr std::array<const char*, 3> kAxisNames{"x", "y", "z"};
  TemporaryDirectory directory;
  const std::string poses_path = directory.file("poses.dat"), timing_path = directory.file("timing.dat");
  const std::string health_path = directory.file("health.dat");
  std::vector<Eigen::Vector2d> plotted;  // for the ranges
  {
    std::ofstream poses(poses_path), timing(timing_path), health_file(health_path);
    health_file << "# scan, pixels paired %, moving %, degenerate, suspect\n";
    for (std::size_t i = 0; health && i < health_scans; ++i)
      health_file << i << ' ' << 100.0 * data.inlier_share[i] << ' ' << 100.0 * data.moving_share[i] << ' '
                  << int(data.degenerate[i]) << ' ' << int(data.suspect[i]) << '\n';
    poses << "# scan, estimate " << kAxisNames[axes[0]] << ' ' << kAxisNames[axes[1]]
          << ", ground truth the same, position error m\n";
    for (std::size_t i = 0; i < data.estimate.size(); ++i) {
      const Eigen::Vector3d& estimate = data.estimate[i].translation();
      const Eigen::Vector3d truth_position = truth ? data.ground_truth[i].translation() : estimate;
      poses << i << ' ' << estimate[axes[0]] << ' ' << estimate[axes[1]] << ' ' << truth_position[axes[0]] << ' '
            << truth_position[axes[1]] << ' ' << (errors ? data.position_errors_m[i] : 0.0) << '\n';
      plotted.emplace_back(estimate[axes[0]], estimate[axes[1]]);
      plotted.emplace_back(truth_position[axes[0]], truth_position[axes[1]]);
    }
    timing << "# scan, odometry ms, integration ms\n";
    for (std::size_t i = 0; i < std::min(data.odometry_ms.size(), data.integrate_ms.size()); ++i)
      timing << i << ' ' << data.odometry_ms[i] << ' ' << data.integrate_ms[i] << '\n';
  }
  std::ostringstream script;
  script << scriptHeader(png_path, 1500, panels == 4 ? 1000 : 600) << "set multiplot layout "
         << (panels == 4 ? "2,2" : "1," + std::to_string(panels)) << "\n"
         << topViewRangeCommands(plotted) << "set title 'Trajectory (top view)'\nset xlabel '" << kAxisNames[axes[0]]
         << " [m]'\nset ylabel '" << kAxisNames[axes[1]] << " [m]'\nset size ratio -1\nset key below\n"
         << "plot " << (truth ? quoted(poses_path) + " using 4:5 with lines lw 3 lc rgb '#999999' title "
                                "'ground truth', \\\n     "
                              : std::string())
         << quoted(poses_path) << " using 2:3 with lines lw 2 lc rgb '#1f77b4' title 'estimate"
         << (truth ? " (aligned)" : "") << "'\n"
         << "set size noratio\nset autoscale xy\nset title 'Time per scan'\nset xlabel 'scan'\nset ylabel 'ms'\n"
         << "plot " << quoted(timing_path) << " using 1:2 with lines lc rgb '#1f77b4' title 'odometry', \\\n     "
         << quoted(timing_path) << " using 1:3 with lines lc rgb '#d62728' title 'TSDF integration'\n";
  if (errors)
    script << "set title 'Position error (ATE)'\nset ylabel 'm'\n"
           << "plot " << quoted(poses_path) << " using 1:6 with lines lc rgb '#2ca02c' title 'error'\n";
  // Degenerate scans marked at the bottom, suspect ones a little above.
  if (health)
    script << "set title 'Odometry health'\nset ylabel '% of the pixels it may pair'\nset yrange [-8:105]\n"
           << "plot " << quoted(health_path) << " using 1:2 with lines lc rgb '#1f77b4' title 'paired', \\\n     "
           << quoted(health_path) << " using 1:3 with lines lc rgb '#ff7f0e' title 'moving', \\\n     "
           << quoted(health_path) << " using 1:($4 > 0 ? -5 : 1/0) with points pt 2 ps 1.5 lc rgb '#d62728' "
           << "title 'degenerate (motion prior)', \\\n     "
           << quoted(health_path) << " using 1:($5 > 0 ? -2 : 1/0) with points pt 9 ps 1.2 lc rgb '#9467bd' "
           << "title 'suspect'\n";
  script << "unset multiplot\n";
  runGnuplot(directory, script.str(), png_path);
}

void writeDistanceColouredCloud(const std::string& path, const std::vector<Eigen::Vector3f>& points,
                                const std::vector<float>& distances, double threshold_m) {
  if (points.size() != distances.size())
    throw std::invalid_argument("writeDistanceColouredCloud: " + std::to_string(distances.size()) +
                                " distances for " + std::to_string(points.size()) + " points");
  if (!(threshold_m > 0))
    throw std::invalid_argument("writeDistanceColouredCloud: the threshold must be positive");
  std::vector<uint8_t> red(points.size()), green(points.size()), blue(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Colour colour = distanceColour(distances[i] / threshold_m);
    red[i] = colour[0], green[i] = colour[1], blue[i] = colour[2];
  }
  io::writePlyPointCloud(path, points,
                         {{"red", std::move(red)}, {"green", std::move(green)},
                          {"blue", std::move(blue)}, {"distance", distances}});
}

}  // namespace range_image_mapping::evaluation
