// Evaluation reports: JSON for machines, one line for people, PNG plots drawn
// by gnuplot, and distance-coloured PLY clouds for precision/recall maps.
#pragma once

#include "range_image_mapping/evaluation/actor_trail.h"
#include "range_image_mapping/evaluation/surface_metrics.h"
#include "range_image_mapping/evaluation/trajectory_metrics.h"

#include <Eigen/Core>

#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::evaluation {

// Files written next to the report and problems worth a warning, both listed in the JSON.
struct ReportNotes {
  std::vector<std::string> outputs;
  std::vector<std::string> warnings;
};

struct TrajectoryReportContext {
  std::string estimate_path, ground_truth_path;
  std::size_t estimate_poses = 0, ground_truth_poses = 0;
  bool by_timestamp = false;
  double max_time_difference_s = 0;  // used when by_timestamp
  ReportNotes notes;
};

// Where a compared surface came from.
struct SurfaceSource {
  std::string path;
  bool from_mesh = false;
  std::size_t vertex_count = 0, triangle_count = 0, points = 0;
  double area_m2 = 0;
};
SurfaceSource describeSurface(const std::string& path, const SurfaceSample& sample);

struct SurfaceReportContext {
  SurfaceSource estimate, ground_truth;
  double voxel_m = 0;            // 0 when the threshold was given directly
  double sample_spacing_m = 0;   // for meshes
  uint32_t seed = 0;
  ReportNotes notes;
  // What the estimate kept of moving actors (measured on its samples), when
  // their tracks were given; actors_path empty otherwise.
  std::string actors_path;
  ActorTrail actor_trail;
  double actor_trail_margin_m = 0;
};

// Pretty-printed JSON text (statistics as count/rmse/mean/std/min/q1/median/q3/max).
std::string trajectoryReportJson(const TrajectoryEvaluation& evaluation,
                                 const TrajectoryReportContext& context);
std::string surfaceReportJson(const SurfaceMetrics& metrics, const SurfaceReportContext& context);

// One line, no trailing newline.
std::string trajectorySummaryLine(const TrajectoryEvaluation& evaluation);
std::string surfaceSummaryLine(const SurfaceMetrics& metrics);
// "moving-actor trail: ..." for SurfaceReportContext::actor_trail.
std::string actorTrailSummaryLine(const SurfaceReportContext& context);

// gnuplot missing, or failing; what() says which and how to get it.
class PlotError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The gnuplot executable found on PATH, or "" when there is none.
std::string findGnuplot();

// The plotted ranges of a top view drawn at equal scales on both axes: the
// points' extent, the shorter axis widened about its middle to at least
// least_aspect of the longer one (a straight drive would otherwise be drawn as
// a strip a few pixels high). Empty ranges (no finite point) stay empty.
struct TopViewRanges {
  Eigen::Vector2d minimum = Eigen::Vector2d::Zero(), maximum = Eigen::Vector2d::Zero();
  bool empty = true;
};
TopViewRanges topViewRanges(const std::vector<Eigen::Vector2d>& points, double least_aspect = 1.0 / 3.0);

// Top view (x-y) of the ground truth and the aligned estimate, the estimate
// coloured by its position error.
void plotTrajectoryTopView(const TrajectoryEvaluation& evaluation, const std::string& png_path);
// The paper's Fig. 6: one box per frame distance, rotation and translation panels.
void plotPairwiseErrors(const TrajectoryEvaluation& evaluation, const std::string& png_path);

// What rim run draws in report.png.
struct RunPlotData {
  std::vector<Eigen::Isometry3d> estimate;      // aligned to the ground truth when there is one
  std::vector<Eigen::Isometry3d> ground_truth;  // empty, or one per estimate pose
  std::vector<double> position_errors_m;        // empty, or one per estimate pose
  std::vector<double> odometry_ms, integrate_ms;  // per used scan
  // The odometry's health per used scan (empty: no panel): shares of the
  // pixels paired and found moving (0-1), and the scans that were degenerate
  // (the motion prior used) or suspect.
  std::vector<double> inlier_share, moving_share;
  std::vector<uint8_t> degenerate, suspect;
};
// Up to four panels: the trajectory top view (x-y: lidar frames are z up; with the ground truth), the time
// per scan of odometry and integration, the position error per scan (with the ground truth), and the
// odometry's health per scan (when given): 1500 x 600 pixels for up to three, 1500 x 1000 for four.
void plotRunReport(const RunPlotData& data, const std::string& png_path);

// uint8 red/green/blue per point from its distance: blue (0) through green to
// yellow (just under threshold), red at or beyond the threshold; the distance
// itself as a float property "distance".
void writeDistanceColouredCloud(const std::string& path, const std::vector<Eigen::Vector3f>& points,
                                const std::vector<float>& distances, double threshold_m);

}  // namespace range_image_mapping::evaluation
