// Trajectory accuracy: an estimated trajectory against ground truth, with the
// metrics of the usual tools (ATE after Umeyama alignment as in evo, the KITTI
// devkit's RPE) and the paper's pairwise errors at frame distances 1..10.
#pragma once

#include <Eigen/Geometry>

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping::evaluation {

// A trajectory file that is missing or malformed; what() names the file and the problem.
class TrajectoryFormatError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Poses T_world_frame, with their times in seconds when the file has them
// (TUM); KITTI files have no times, so times_s stays empty.
struct StampedTrajectory {
  std::vector<double> times_s;
  std::vector<Eigen::Isometry3d> poses;
  bool hasTimes() const { return !times_s.empty(); }
};

enum class PoseFileFormat {
  kAutomatic,  // from the first data line: 12 numbers KITTI, 8 numbers TUM
  kKitti,      // 12 numbers per line, row-major 3x4 [R | t]
  kTum,        // "t x y z qx qy qz qw"; lines starting with '#' are comments
};

// KITTI (io::readKittiPoses, no times: associated by index) or TUM
// (io::readTumPoses). Throws TrajectoryFormatError, naming the file and line,
// for an empty file, a line that fits neither format, or TUM times that do not
// increase.
StampedTrajectory readTrajectory(const std::string& path,
                                 PoseFileFormat format = PoseFileFormat::kAutomatic);

// Pairs of poses that describe the same instant.
struct AssociatedPoses {
  std::vector<Eigen::Isometry3d> estimate;
  std::vector<Eigen::Isometry3d> ground_truth;
  std::vector<std::size_t> estimate_index, ground_truth_index;  // into the input trajectories
  std::vector<double> times_s;  // ground-truth times; empty for index association
  bool by_timestamp = false;
};

// Pose i with pose i; throws std::invalid_argument when the counts differ.
AssociatedPoses associateByIndex(const StampedTrajectory& estimate,
                                 const StampedTrajectory& ground_truth);
// Each estimate pose with the ground-truth pose nearest in time, when no more
// than max_time_difference_s apart; each ground-truth pose is used once (the
// nearer estimate wins). Throws std::invalid_argument when a trajectory has no
// times or nothing is associated.
AssociatedPoses associateByTimestamp(const StampedTrajectory& estimate,
                                     const StampedTrajectory& ground_truth,
                                     double max_time_difference_s);

// target ≈ scale * rotation * source + translation.
struct SimilarityTransform {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  double scale = 1.0;

  Eigen::Vector3d apply(const Eigen::Vector3d& point) const {
    return scale * (rotation * point) + translation;
  }
  // The pose moved by this transform: rotation composed, position mapped.
  Eigen::Isometry3d apply(const Eigen::Isometry3d& pose) const;
};

// Least-squares alignment of corresponding points (Umeyama 1991), with or
// without scale. Throws std::invalid_argument for empty or unequal inputs.
SimilarityTransform umeyamaAlignment(const std::vector<Eigen::Vector3d>& source,
                                     const std::vector<Eigen::Vector3d>& target, bool with_scale);

enum class Alignment {
  kNone,  // compare as given (both trajectories in the same world frame)
  kSE3,   // rotation + translation (evo -a)
  kSim3,  // rotation + translation + scale (evo -as), for monocular-like estimates
};

// Order statistics with linear interpolation between ranks (numpy's default).
struct ErrorStatistics {
  std::size_t count = 0;
  double rmse = 0, mean = 0, standard_deviation = 0;
  double minimum = 0, first_quartile = 0, median = 0, third_quartile = 0, maximum = 0;
};
ErrorStatistics summarize(std::vector<double> values);

// KITTI devkit relative pose error over one segment length: segments start
// every rpe_start_step-th frame and end at the first frame more than
// length_m further along the ground truth; errors divided by the length.
struct KittiLengthError {
  double length_m = 0;
  std::size_t segments = 0;
  double translation_percent = 0;
  double rotation_deg_per_m = 0;
};
struct KittiRelativeError {
  std::size_t segments = 0;  // 0 when the run is shorter than every length
  double translation_percent = 0;  // mean over all segments of all lengths, as the devkit
  double rotation_deg_per_m = 0;
  std::vector<KittiLengthError> per_length;
};

// Relative pose error between consecutive frames, for runs too short for the
// devkit's lengths.
struct FrameToFrameError {
  ErrorStatistics translation_m, rotation_deg;
  double translation_percent = 0;  // sum of translation errors / ground-truth path length
  double rotation_deg_per_m = 0;
};

// The paper's errors between frames i and i + frame_distance: rotation
// arccos((tr(R Rgt^T) - 1) / 2) in degrees and translation ||t - tgt|| in
// metres (the norm; the paper's text squares it) of the relative poses.
struct PairwiseErrors {
  int frame_distance = 0;
  std::vector<std::size_t> first_frames;  // the sampled i
  std::vector<double> rotation_deg, translation_m;
  ErrorStatistics rotation_statistics, translation_statistics;
};

struct TrajectoryEvaluationOptions {
  Alignment alignment = Alignment::kSE3;
  std::vector<double> rpe_lengths_m{100, 200, 300, 400, 500, 600, 700, 800};
  int rpe_start_step = 10;        // the devkit starts a segment every 10th frame
  int max_frame_distance = 10;    // pairwise errors at 1..max_frame_distance
  int pairs_per_distance = 50;    // the paper samples M = 50; all pairs when fewer exist
  uint32_t seed = 0;              // for the pair sample
};

struct TrajectoryEvaluation {
  Alignment alignment = Alignment::kSE3;
  SimilarityTransform alignment_transform;      // applied to the estimate
  std::vector<Eigen::Isometry3d> ground_truth;  // associated poses
  std::vector<Eigen::Isometry3d> aligned_estimate;
  double ground_truth_length_m = 0;

  std::vector<double> position_errors_m;  // per pose, after alignment
  ErrorStatistics absolute_translation_m;  // ATE
  ErrorStatistics absolute_rotation_deg;   // angle of R_gt^T R per pose, after alignment
  KittiRelativeError kitti;
  FrameToFrameError frame_to_frame;
  std::vector<PairwiseErrors> pairwise;   // frame distances 1..max_frame_distance that fit
};

// Throws std::invalid_argument for unequal or empty inputs or bad options.
TrajectoryEvaluation evaluateTrajectory(const std::vector<Eigen::Isometry3d>& estimate,
                                        const std::vector<Eigen::Isometry3d>& ground_truth,
                                        const TrajectoryEvaluationOptions& options = {});

// Angle of a rotation in radians, robust to rounding (trace clamped to [-1, 3]).
double rotationAngle(const Eigen::Matrix3d& rotation);

// Cumulative path length along the poses, one entry per pose (first is 0).
std::vector<double> pathDistances(const std::vector<Eigen::Isometry3d>& poses);

}  // namespace range_image_mapping::evaluation
