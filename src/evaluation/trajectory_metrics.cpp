#include "range_image_mapping/evaluation/trajectory_metrics.h"

#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pose_file.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <numeric>
#include <random>
#include <sstream>

namespace range_image_mapping::evaluation {
namespace {

constexpr double kDegreesPerRadian = 180.0 / M_PI;

bool isCommentOrBlank(const std::string& line) {
  const std::size_t first = line.find_first_not_of(" \t\r");
  return first == std::string::npos || line[first] == '#';
}

// Counts the numbers on the first data line, to tell KITTI (12) from TUM (8).
PoseFileFormat detectFormat(const std::string& path) {
  std::ifstream file(path);
  if (!file) throw TrajectoryFormatError("trajectory: cannot open " + path);
  std::string line;
  for (int line_number = 1; std::getline(file, line); ++line_number) {
    if (isCommentOrBlank(line)) continue;
    std::istringstream words(line);
    std::size_t count = 0;
    for (std::string word; words >> word;) ++count;
    if (count == 12) return PoseFileFormat::kKitti;
    if (count == 8) return PoseFileFormat::kTum;
    throw TrajectoryFormatError("trajectory: " + path + " line " + std::to_string(line_number) +
                                " has " + std::to_string(count) +
                                " values; expected 12 (KITTI 3x4) or 8 (TUM t x y z qx qy qz qw)");
  }
  throw TrajectoryFormatError("trajectory: " + path + " holds no pose");
}

// numpy's default (linear) quantile of sorted values.
double quantile(const std::vector<double>& sorted, double fraction) {
  const double position = fraction * static_cast<double>(sorted.size() - 1);
  const auto below = static_cast<std::size_t>(std::floor(position));
  const std::size_t above = std::min(below + 1, sorted.size() - 1);
  return sorted[below] + (position - static_cast<double>(below)) * (sorted[above] - sorted[below]);
}

Eigen::Isometry3d relativePose(const std::vector<Eigen::Isometry3d>& poses, std::size_t from,
                               std::size_t to) {
  return poses[from].inverse() * poses[to];
}

// The devkit's segments: from every rpe_start_step-th frame to the first frame
// more than `length` further along the ground-truth path.
KittiRelativeError kittiRelativeError(const std::vector<Eigen::Isometry3d>& estimate,
                                      const std::vector<Eigen::Isometry3d>& ground_truth,
                                      const std::vector<double>& distances,
                                      const TrajectoryEvaluationOptions& options) {
  KittiRelativeError result;
  double translation_sum = 0, rotation_sum = 0;
  for (const double length : options.rpe_lengths_m) {
    KittiLengthError per_length;
    per_length.length_m = length;
    for (std::size_t first = 0; first < ground_truth.size();
         first += static_cast<std::size_t>(options.rpe_start_step)) {
      const auto last_iterator =
          std::upper_bound(distances.begin() + static_cast<std::ptrdiff_t>(first), distances.end(),
                           distances[first] + length);
      if (last_iterator == distances.end()) continue;
      const auto last = static_cast<std::size_t>(last_iterator - distances.begin());
      const Eigen::Isometry3d error =
          relativePose(estimate, first, last).inverse() * relativePose(ground_truth, first, last);
      per_length.translation_percent += 100.0 * error.translation().norm() / length;
      per_length.rotation_deg_per_m += kDegreesPerRadian * rotationAngle(error.linear()) / length;
      ++per_length.segments;
    }
    if (per_length.segments == 0) continue;
    translation_sum += per_length.translation_percent;
    rotation_sum += per_length.rotation_deg_per_m;
    result.segments += per_length.segments;
    per_length.translation_percent /= static_cast<double>(per_length.segments);
    per_length.rotation_deg_per_m /= static_cast<double>(per_length.segments);
    result.per_length.push_back(per_length);
  }
  if (result.segments > 0) {
    result.translation_percent = translation_sum / static_cast<double>(result.segments);
    result.rotation_deg_per_m = rotation_sum / static_cast<double>(result.segments);
  }
  return result;
}

// Translation and rotation error of the relative pose between frames i and j.
void relativeErrors(const std::vector<Eigen::Isometry3d>& estimate,
                    const std::vector<Eigen::Isometry3d>& ground_truth, std::size_t i,
                    std::size_t j, double& translation_m, double& rotation_deg) {
  const Eigen::Isometry3d estimated = relativePose(estimate, i, j);
  const Eigen::Isometry3d truth = relativePose(ground_truth, i, j);
  translation_m = (estimated.translation() - truth.translation()).norm();
  rotation_deg = kDegreesPerRadian * rotationAngle(estimated.linear() * truth.linear().transpose());
}

FrameToFrameError frameToFrameError(const std::vector<Eigen::Isometry3d>& estimate,
                                    const std::vector<Eigen::Isometry3d>& ground_truth,
                                    const std::vector<double>& distances) {
  FrameToFrameError result;
  std::vector<double> translations, rotations;
  for (std::size_t i = 0; i + 1 < ground_truth.size(); ++i) {
    double translation, rotation;
    relativeErrors(estimate, ground_truth, i, i + 1, translation, rotation);
    translations.push_back(translation);
    rotations.push_back(rotation);
  }
  const double path_length = distances.back();
  if (path_length > 0) {
    result.translation_percent =
        100.0 * std::accumulate(translations.begin(), translations.end(), 0.0) / path_length;
    result.rotation_deg_per_m =
        std::accumulate(rotations.begin(), rotations.end(), 0.0) / path_length;
  }
  result.translation_m = summarize(std::move(translations));
  result.rotation_deg = summarize(std::move(rotations));
  return result;
}

// All first frames when at most pairs_per_distance exist, else a seeded sample
// without replacement, in increasing order.
std::vector<std::size_t> sampleFirstFrames(std::size_t candidates, int frame_distance,
                                           const TrajectoryEvaluationOptions& options) {
  std::vector<std::size_t> frames(candidates);
  std::iota(frames.begin(), frames.end(), std::size_t{0});
  const auto wanted = static_cast<std::size_t>(options.pairs_per_distance);
  if (candidates <= wanted) return frames;
  std::seed_seq seed{options.seed, static_cast<uint32_t>(frame_distance)};
  std::mt19937 generator(seed);
  for (std::size_t k = 0; k < wanted; ++k) {  // partial Fisher-Yates
    std::uniform_int_distribution<std::size_t> pick(k, candidates - 1);
    std::swap(frames[k], frames[pick(generator)]);
  }
  frames.resize(wanted);
  std::sort(frames.begin(), frames.end());
  return frames;
}

std::vector<PairwiseErrors> pairwiseErrors(const std::vector<Eigen::Isometry3d>& estimate,
                                           const std::vector<Eigen::Isometry3d>& ground_truth,
                                           const TrajectoryEvaluationOptions& options) {
  std::vector<PairwiseErrors> result;
  for (int distance = 1; distance <= options.max_frame_distance; ++distance) {
    if (static_cast<std::size_t>(distance) >= ground_truth.size()) break;
    PairwiseErrors errors;
    errors.frame_distance = distance;
    errors.first_frames =
        sampleFirstFrames(ground_truth.size() - static_cast<std::size_t>(distance), distance, options);
    for (const std::size_t first : errors.first_frames) {
      double translation, rotation;
      relativeErrors(estimate, ground_truth, first, first + static_cast<std::size_t>(distance),
                     translation, rotation);
      errors.translation_m.push_back(translation);
      errors.rotation_deg.push_back(rotation);
    }
    errors.translation_statistics = summarize(errors.translation_m);
    errors.rotation_statistics = summarize(errors.rotation_deg);
    result.push_back(std::move(errors));
  }
  return result;
}

void checkOptions(const TrajectoryEvaluationOptions& options) {
  if (options.rpe_start_step < 1)
    throw std::invalid_argument("evaluateTrajectory: rpe_start_step must be at least 1, not " +
                                std::to_string(options.rpe_start_step));
  for (const double length : options.rpe_lengths_m)
    if (!(length > 0))
      throw std::invalid_argument("evaluateTrajectory: RPE segment lengths must be positive");
  if (options.max_frame_distance < 0)
    throw std::invalid_argument("evaluateTrajectory: max_frame_distance must not be negative");
  if (options.pairs_per_distance < 1)
    throw std::invalid_argument("evaluateTrajectory: pairs_per_distance must be at least 1, not " +
                                std::to_string(options.pairs_per_distance));
}

}  // namespace

// ---------------------------------------------------------------- files

StampedTrajectory readTrajectory(const std::string& path, PoseFileFormat format) {
  if (format == PoseFileFormat::kAutomatic) format = detectFormat(path);
  StampedTrajectory trajectory;
  try {
    if (format == PoseFileFormat::kTum) {
      for (const io::StampedPose& stamped : io::readTumPoses(path)) {
        trajectory.times_s.push_back(stamped.time_s);
        trajectory.poses.push_back(stamped.pose);
      }
    } else {
      trajectory.poses = io::readKittiPoses(path);
    }
  } catch (const io::PoseFileError& error) {
    throw TrajectoryFormatError(error.what());
  } catch (const io::KittiFormatError& error) {
    throw TrajectoryFormatError(error.what());
  }
  if (trajectory.poses.empty()) throw TrajectoryFormatError("trajectory: " + path + " holds no pose");
  // Association looks times up by bisection.
  for (std::size_t i = 1; i < trajectory.times_s.size(); ++i)
    if (!(trajectory.times_s[i] > trajectory.times_s[i - 1])) {
      std::ostringstream message;
      message << std::setprecision(15) << "trajectory: " << path << " pose " << i + 1 << " has time "
              << trajectory.times_s[i] << " s, not after the previous pose's " << trajectory.times_s[i - 1];
      throw TrajectoryFormatError(message.str());
    }
  return trajectory;
}

// ---------------------------------------------------------------- association

AssociatedPoses associateByIndex(const StampedTrajectory& estimate,
                                 const StampedTrajectory& ground_truth) {
  if (estimate.poses.size() != ground_truth.poses.size())
    throw std::invalid_argument(
        "association by index: the estimate has " + std::to_string(estimate.poses.size()) +
        " poses and the ground truth " + std::to_string(ground_truth.poses.size()) +
        "; they must be equal (or give both trajectories with timestamps, TUM)");
  if (estimate.poses.empty()) throw std::invalid_argument("association by index: no poses");
  AssociatedPoses associated;
  associated.estimate = estimate.poses;
  associated.ground_truth = ground_truth.poses;
  associated.estimate_index.resize(estimate.poses.size());
  std::iota(associated.estimate_index.begin(), associated.estimate_index.end(), std::size_t{0});
  associated.ground_truth_index = associated.estimate_index;
  return associated;
}

AssociatedPoses associateByTimestamp(const StampedTrajectory& estimate,
                                     const StampedTrajectory& ground_truth,
                                     double max_time_difference_s) {
  if (!estimate.hasTimes() || !ground_truth.hasTimes())
    throw std::invalid_argument("association by timestamp: " +
                                std::string(estimate.hasTimes() ? "the ground truth" : "the estimate") +
                                " has no timestamps");
  if (!(max_time_difference_s >= 0))
    throw std::invalid_argument("association by timestamp: the time tolerance must not be negative");
  const std::vector<double>& truth_times = ground_truth.times_s;
  // For each ground-truth pose the nearest estimate within tolerance.
  std::vector<std::ptrdiff_t> best_estimate(truth_times.size(), -1);
  std::vector<double> best_difference(truth_times.size(), 0.0);
  for (std::size_t i = 0; i < estimate.times_s.size(); ++i) {
    const double time = estimate.times_s[i];
    const auto after = std::lower_bound(truth_times.begin(), truth_times.end(), time);
    std::size_t nearest = static_cast<std::size_t>(after - truth_times.begin());
    if (after == truth_times.end() ||
        (after != truth_times.begin() && time - *(after - 1) < *after - time))
      --nearest;
    const double difference = std::abs(truth_times[nearest] - time);
    if (difference > max_time_difference_s) continue;
    if (best_estimate[nearest] < 0 || difference < best_difference[nearest]) {
      best_estimate[nearest] = static_cast<std::ptrdiff_t>(i);
      best_difference[nearest] = difference;
    }
  }
  AssociatedPoses associated;
  associated.by_timestamp = true;
  for (std::size_t j = 0; j < truth_times.size(); ++j) {
    if (best_estimate[j] < 0) continue;
    const auto i = static_cast<std::size_t>(best_estimate[j]);
    associated.estimate.push_back(estimate.poses[i]);
    associated.ground_truth.push_back(ground_truth.poses[j]);
    associated.estimate_index.push_back(i);
    associated.ground_truth_index.push_back(j);
    associated.times_s.push_back(truth_times[j]);
  }
  if (associated.estimate.empty()) {
    std::ostringstream message;
    message << std::setprecision(12) << "association by timestamp: no estimate time (from "
            << estimate.times_s.front() << " to " << estimate.times_s.back()
            << " s) lies within " << max_time_difference_s << " s of a ground-truth time (from "
            << truth_times.front() << " to " << truth_times.back() << " s)";
    throw std::invalid_argument(message.str());
  }
  return associated;
}

// ---------------------------------------------------------------- alignment

Eigen::Isometry3d SimilarityTransform::apply(const Eigen::Isometry3d& pose) const {
  Eigen::Isometry3d moved = Eigen::Isometry3d::Identity();
  moved.linear() = rotation * pose.linear();
  moved.translation() = apply(Eigen::Vector3d(pose.translation()));
  return moved;
}

SimilarityTransform umeyamaAlignment(const std::vector<Eigen::Vector3d>& source,
                                     const std::vector<Eigen::Vector3d>& target, bool with_scale) {
  if (source.size() != target.size() || source.empty())
    throw std::invalid_argument("umeyamaAlignment: needs equally many points, at least one (got " +
                                std::to_string(source.size()) + " and " +
                                std::to_string(target.size()) + ")");
  Eigen::Matrix3Xd from(3, source.size()), to(3, target.size());
  for (std::size_t i = 0; i < source.size(); ++i) {
    from.col(static_cast<Eigen::Index>(i)) = source[i];
    to.col(static_cast<Eigen::Index>(i)) = target[i];
  }
  Eigen::Matrix4d transform = Eigen::umeyama(from, to, with_scale);
  SimilarityTransform result;
  // Eigen returns [s R | t]. Points without spread (one point, or all equal)
  // define no scale: align rigidly then.
  result.scale = with_scale ? transform.topLeftCorner<3, 3>().col(0).norm() : 1.0;
  if (!std::isfinite(result.scale) || !(result.scale > 0)) {
    transform = Eigen::umeyama(from, to, false);
    result.scale = 1.0;
  }
  result.rotation = transform.topLeftCorner<3, 3>() / result.scale;
  result.translation = transform.topRightCorner<3, 1>();
  return result;
}

// ---------------------------------------------------------------- metrics

ErrorStatistics summarize(std::vector<double> values) {
  ErrorStatistics statistics;
  statistics.count = values.size();
  if (values.empty()) return statistics;
  std::sort(values.begin(), values.end());
  const std::vector<double>& sorted = values;
  const double count = static_cast<double>(sorted.size());
  double sum = 0, sum_of_squares = 0;
  for (const double value : sorted) sum += value, sum_of_squares += value * value;
  statistics.mean = sum / count;
  statistics.rmse = std::sqrt(sum_of_squares / count);
  double variance = 0;
  for (const double value : sorted) variance += (value - statistics.mean) * (value - statistics.mean);
  statistics.standard_deviation = std::sqrt(variance / count);
  statistics.minimum = sorted.front();
  statistics.maximum = sorted.back();
  statistics.first_quartile = quantile(sorted, 0.25);
  statistics.median = quantile(sorted, 0.5);
  statistics.third_quartile = quantile(sorted, 0.75);
  return statistics;
}

double rotationAngle(const Eigen::Matrix3d& rotation) {
  // atan2 of sine and cosine is the same angle as arccos((tr R - 1) / 2), but
  // keeps its precision near zero, where arccos loses half the digits.
  const Eigen::Vector3d twice_sine_axis(rotation(2, 1) - rotation(1, 2), rotation(0, 2) - rotation(2, 0),
                                        rotation(1, 0) - rotation(0, 1));
  const double cosine = std::clamp(0.5 * (rotation.trace() - 1.0), -1.0, 1.0);
  return std::atan2(0.5 * twice_sine_axis.norm(), cosine);
}

std::vector<double> pathDistances(const std::vector<Eigen::Isometry3d>& poses) {
  std::vector<double> distances(poses.size(), 0.0);
  for (std::size_t i = 1; i < poses.size(); ++i)
    distances[i] = distances[i - 1] + (poses[i].translation() - poses[i - 1].translation()).norm();
  return distances;
}

TrajectoryEvaluation evaluateTrajectory(const std::vector<Eigen::Isometry3d>& estimate,
                                        const std::vector<Eigen::Isometry3d>& ground_truth,
                                        const TrajectoryEvaluationOptions& options) {
  if (estimate.size() != ground_truth.size() || estimate.empty())
    throw std::invalid_argument("evaluateTrajectory: needs equally many associated poses, at least one (got " +
                                std::to_string(estimate.size()) + " and " +
                                std::to_string(ground_truth.size()) + ")");
  checkOptions(options);
  TrajectoryEvaluation result;
  result.alignment = options.alignment;
  result.ground_truth = ground_truth;
  if (options.alignment != Alignment::kNone) {
    std::vector<Eigen::Vector3d> from, to;
    for (std::size_t i = 0; i < estimate.size(); ++i) {
      from.push_back(estimate[i].translation());
      to.push_back(ground_truth[i].translation());
    }
    result.alignment_transform = umeyamaAlignment(from, to, options.alignment == Alignment::kSim3);
  }
  for (const Eigen::Isometry3d& pose : estimate)
    result.aligned_estimate.push_back(result.alignment_transform.apply(pose));

  std::vector<double> rotation_errors;
  for (std::size_t i = 0; i < estimate.size(); ++i) {
    result.position_errors_m.push_back(
        (result.aligned_estimate[i].translation() - ground_truth[i].translation()).norm());
    rotation_errors.push_back(kDegreesPerRadian *
                              rotationAngle(ground_truth[i].linear().transpose() *
                                            result.aligned_estimate[i].linear()));
  }
  result.absolute_translation_m = summarize(result.position_errors_m);
  result.absolute_rotation_deg = summarize(std::move(rotation_errors));

  const std::vector<double> distances = pathDistances(ground_truth);
  result.ground_truth_length_m = distances.back();
  // Relative metrics use the aligned estimate: the same as the raw one for
  // SE(3), and scale-corrected for Sim(3).
  result.kitti = kittiRelativeError(result.aligned_estimate, ground_truth, distances, options);
  result.frame_to_frame = frameToFrameError(result.aligned_estimate, ground_truth, distances);
  result.pairwise = pairwiseErrors(result.aligned_estimate, ground_truth, options);
  return result;
}

}  // namespace range_image_mapping::evaluation
