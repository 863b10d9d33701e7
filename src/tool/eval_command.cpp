// rim eval traj / rim eval mesh: an estimated trajectory or reconstruction
// against ground truth; JSON for machines, one summary line, PNG plots and
// distance-coloured PLY maps.
#include "commands.h"

#include "range_image_mapping/evaluation/actor_trail.h"
#include "range_image_mapping/evaluation/report.h"
#include "range_image_mapping/io/actor_tracks.h"

#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>

namespace range_image_mapping::tool {
namespace {

using namespace range_image_mapping::evaluation;

struct OutputOptions {
  std::string json_path;        // "-": standard output
  std::string plots_directory;  // empty: no plots or maps
};

struct TrajectoryOptions {
  std::string estimate, ground_truth;
  std::string format = "auto";
  double max_time_difference_s = 0.01;
  bool no_align = false, align_scale = false;
  std::vector<double> rpe_lengths_m{100, 200, 300, 400, 500, 600, 700, 800};
  int max_frame_distance = 10;
  int pairs_per_distance = 50;
  uint32_t seed = 0;
  OutputOptions output;
};

struct SurfaceOptions {
  std::string estimate, ground_truth;
  double voxel_m = 0, threshold_m = 0;
  double sample_spacing_m = 0;  // 0: a quarter of the threshold
  uint32_t seed = 0;
  std::size_t max_samples = 50'000'000;
  std::string actors;  // moving actors' tracks; default: actors.txt next to the ground truth, if there
  double actor_margin_m = 0.1;
  OutputOptions output;
};

void addOutputOptions(Command& command, OutputOptions& output) {
  command.option("--json", output.json_path, "write the JSON report to this file ('-': standard output)");
  command.option("--plots", output.plots_directory, "write plots and maps into this folder");
}

// The summary goes to standard output, unless the JSON does: then to standard error.
void writeReport(const OutputOptions& output, const std::string& json, const std::string& summary) {
  if (output.json_path == "-") {
    std::cout << json << std::flush;
    std::cerr << summary << "\n";
    return;
  }
  if (!output.json_path.empty()) {
    std::ofstream file(output.json_path);
    file << json;
    file.close();
    if (!file) throw std::runtime_error("cannot write the JSON report " + output.json_path);
  }
  std::cout << summary << "\n";
}

// Plots are a by-product: a missing gnuplot is a warning, and the JSON is still written.
template <typename Draw>
void drawPlot(const std::string& png_path, ReportNotes& notes, Draw&& draw) {
  try {
    draw(png_path);
    notes.outputs.push_back(png_path);
  } catch (const PlotError& error) {
    notes.warnings.push_back(error.what());
    std::cerr << "warning: " << error.what() << "\n";
  }
}

void prepareDirectory(const std::string& directory) {
  std::error_code error;
  std::filesystem::create_directories(directory, error);
  if (error) throw std::runtime_error("cannot create the plot folder " + directory + ": " + error.message());
}

PoseFileFormat poseFileFormat(const std::string& name) {
  if (name == "kitti") return PoseFileFormat::kKitti;
  if (name == "tum") return PoseFileFormat::kTum;
  return PoseFileFormat::kAutomatic;
}

void runTrajectoryEvaluation(const TrajectoryOptions& options) {
  const PoseFileFormat format = poseFileFormat(options.format);
  const StampedTrajectory estimate = readTrajectory(options.estimate, format);
  const StampedTrajectory ground_truth = readTrajectory(options.ground_truth, format);
  // Times when both files have them (TUM), else the KITTI convention: line i with line i.
  const bool by_timestamp = estimate.hasTimes() && ground_truth.hasTimes();
  const AssociatedPoses associated =
      by_timestamp ? associateByTimestamp(estimate, ground_truth, options.max_time_difference_s)
                   : associateByIndex(estimate, ground_truth);

  TrajectoryEvaluationOptions evaluation_options;
  evaluation_options.alignment =
      options.no_align ? Alignment::kNone : options.align_scale ? Alignment::kSim3 : Alignment::kSE3;
  evaluation_options.rpe_lengths_m = options.rpe_lengths_m;
  evaluation_options.max_frame_distance = options.max_frame_distance;
  evaluation_options.pairs_per_distance = options.pairs_per_distance;
  evaluation_options.seed = options.seed;
  const TrajectoryEvaluation evaluation =
      evaluateTrajectory(associated.estimate, associated.ground_truth, evaluation_options);

  TrajectoryReportContext context;
  context.estimate_path = options.estimate;
  context.ground_truth_path = options.ground_truth;
  context.estimate_poses = estimate.poses.size();
  context.ground_truth_poses = ground_truth.poses.size();
  context.by_timestamp = by_timestamp;
  context.max_time_difference_s = options.max_time_difference_s;
  if (estimate.hasTimes() != ground_truth.hasTimes())
    context.notes.warnings.push_back("only one file has timestamps: associated by index");
  if (by_timestamp && associated.estimate.size() < estimate.poses.size())
    context.notes.warnings.push_back(std::to_string(estimate.poses.size() - associated.estimate.size()) +
                                     " estimate poses have no ground-truth pose within the time tolerance");
  for (const std::string& warning : context.notes.warnings) std::cerr << "warning: " << warning << "\n";

  const std::string& directory = options.output.plots_directory;
  if (!directory.empty()) {
    prepareDirectory(directory);
    drawPlot(directory + "/trajectory_top_view.png", context.notes,
             [&](const std::string& png) { plotTrajectoryTopView(evaluation, png); });
    if (!evaluation.pairwise.empty())
      drawPlot(directory + "/pairwise_errors.png", context.notes,
               [&](const std::string& png) { plotPairwiseErrors(evaluation, png); });
  }
  writeReport(options.output, trajectoryReportJson(evaluation, context), trajectorySummaryLine(evaluation));
}

void runSurfaceEvaluation(const SurfaceOptions& options) {
  const double threshold = options.threshold_m > 0 ? options.threshold_m : 3.0 * options.voxel_m;
  if (!(threshold > 0)) throw std::invalid_argument("give --voxel (threshold 3 x voxel) or --threshold");
  SurfaceSamplingOptions sampling;
  sampling.spacing_m = options.sample_spacing_m > 0 ? options.sample_spacing_m : threshold / 4.0;
  sampling.seed = options.seed;
  sampling.max_points = options.max_samples;
  const SurfaceSample estimate = loadSurfaceSample(options.estimate, sampling);
  const SurfaceSample ground_truth = loadSurfaceSample(options.ground_truth, sampling);
  const SurfaceMetrics metrics = compareSurfaces(estimate.points, ground_truth.points, threshold);

  SurfaceReportContext context;
  context.estimate = describeSurface(options.estimate, estimate);
  context.ground_truth = describeSurface(options.ground_truth, ground_truth);
  context.voxel_m = options.threshold_m > 0 ? 0.0 : options.voxel_m;
  context.sample_spacing_m = sampling.spacing_m;
  context.seed = sampling.seed;
  if (sampling.spacing_m > 0.5 * threshold)
    context.notes.warnings.push_back("the sample spacing is more than half the threshold: holes between "
                                     "samples lower precision and recall");
  for (const std::string& warning : context.notes.warnings) std::cerr << "warning: " << warning << "\n";
  // Simulated sequences with moving actors: what the estimate kept of them.
  std::string actors_path = options.actors;
  if (actors_path.empty()) {
    const auto beside = std::filesystem::path(options.ground_truth).parent_path() / "actors.txt";
    if (std::filesystem::exists(beside)) actors_path = beside.string();
  }
  if (!actors_path.empty()) {
    ActorTrailOptions trail_options;
    trail_options.margin_m = options.actor_margin_m;
    context.actors_path = actors_path;
    context.actor_trail_margin_m = trail_options.margin_m;
    context.actor_trail = measureActorTrail(estimate.points, io::readActorTracks(actors_path), trail_options);
  }

  const std::string& directory = options.output.plots_directory;
  if (!directory.empty()) {
    prepareDirectory(directory);
    // Precision map: the estimate coloured by its distance to the ground
    // truth; recall map: the ground truth coloured by its distance to the estimate.
    writeDistanceColouredCloud(directory + "/precision_map.ply", estimate.points,
                               metrics.estimate_to_truth_m, threshold);
    writeDistanceColouredCloud(directory + "/recall_map.ply", ground_truth.points,
                               metrics.truth_to_estimate_m, threshold);
    context.notes.outputs.push_back(directory + "/precision_map.ply");
    context.notes.outputs.push_back(directory + "/recall_map.ply");
  }
  writeReport(options.output, surfaceReportJson(metrics, context),
              surfaceSummaryLine(metrics) + (context.actors_path.empty() ? "" : "\n" + actorTrailSummaryLine(context)));
}

void addTrajectoryCommand(Command& eval) {
  auto options = std::make_shared<TrajectoryOptions>();
  Command& command = eval.subcommand(
      "traj", "Trajectory against ground truth: ATE after Umeyama alignment, KITTI-devkit RPE, "
              "frame-to-frame RPE, and the paper's pairwise errors at frame distances 1..10");
  command.option("estimate", options->estimate, "estimated poses (KITTI 3x4 or TUM)").required().check(existingFile());
  command.option("ground_truth", options->ground_truth, "ground-truth poses (KITTI 3x4 or TUM)")
      .required()
      .check(existingFile());
  command.option("--format", options->format, "pose file format of both files")
      .check(oneOf({"auto", "kitti", "tum"}))
      .showDefault();
  command.option("--max-time-difference", options->max_time_difference_s,
                 "TUM: largest time difference of associated poses, s")
      .check(nonNegative())
      .showDefault();
  command.flag("--no-align", options->no_align, "compare as given, without Umeyama alignment");
  command.flag("--align-scale", options->align_scale, "align with scale (Sim(3)) instead of SE(3)")
      .excludes("--no-align");
  command.option("--rpe-lengths", options->rpe_lengths_m, "KITTI RPE segment lengths, m").check(positive());
  command.option("--max-frame-distance", options->max_frame_distance, "pairwise errors at frame distances 1..this")
      .check(inRange(1, 1000))
      .showDefault();
  command.option("--pairs", options->pairs_per_distance,
                 "pairs sampled per frame distance (all when fewer exist; the paper's M = 50)")
      .check(inRange(1, 1'000'000))
      .showDefault();
  command.option("--seed", options->seed, "seed of the pair sample").showDefault();
  addOutputOptions(command, options->output);
  command.callback([options] { runTrajectoryEvaluation(*options); });
}

void addSurfaceCommand(Command& eval) {
  auto options = std::make_shared<SurfaceOptions>();
  Command& command = eval.subcommand(
      "mesh", "Reconstruction against ground truth (PLY mesh or cloud, OBJ mesh): precision, recall, "
              "F-score at a threshold, Chamfer distance; meshes are sampled over their area");
  command.option("estimate", options->estimate, "reconstruction: PLY mesh or point cloud, or OBJ")
      .required()
      .check(existingFile());
  command.option("ground_truth", options->ground_truth, "ground truth: PLY mesh or point cloud, or OBJ")
      .required()
      .check(existingFile());
  command.option("--voxel", options->voxel_m, "voxel size, m: threshold = 3 x voxel").check(positive());
  command.option("--threshold", options->threshold_m, "distance threshold of precision and recall, m")
      .check(positive())
      .excludes("--voxel");
  command.option("--sample-spacing", options->sample_spacing_m, "mean spacing of mesh samples, m (default: threshold / 4)")
      .check(positive());
  command.option("--seed", options->seed, "seed of the mesh samples").showDefault();
  command.option("--max-samples", options->max_samples, "refuse meshes that need more samples")
      .check(positive())
      .showDefault();
  command.option("--actors", options->actors,
                 "moving actors' tracks (rim simulate's actors.txt; default: the one next to the ground truth): "
                 "report what the estimate kept inside the volumes they swept")
      .check(existingFile());
  command.option("--actor-margin", options->actor_margin_m,
                 "swept boxes grow by this sideways and upward and their bottoms rise by it, m")
      .check(nonNegative())
      .showDefault();
  addOutputOptions(command, options->output);
  command.callback([options, &command] {
    if (!command.given("--voxel") && !command.given("--threshold"))
      throw UsageError("rim eval mesh: give --voxel (threshold 3 x voxel) or --threshold");
    runSurfaceEvaluation(*options);
  });
}

}  // namespace

void addEvalCommand(Command& rim) {
  Command& eval = rim.subcommand("eval", "Evaluate trajectories and reconstructions against ground truth");
  addTrajectoryCommand(eval);
  addSurfaceCommand(eval);
}

}  // namespace range_image_mapping::tool
