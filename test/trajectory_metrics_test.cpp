#include "range_image_mapping/evaluation/trajectory_metrics.h"

#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/pose_file.h"
#include "error_text.h"
#include "test_data.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>

namespace range_image_mapping::evaluation {
namespace {

constexpr double kDegree = M_PI / 180.0;

std::string temporaryPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("rim_trajectory_metrics_test_" + name)).string();
}

void writeFile(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

using test::contains;
using test::errorOf;

Eigen::Isometry3d pose(double yaw, const Eigen::Vector3d& position) {
  Eigen::Isometry3d result = Eigen::Isometry3d::Identity();
  result.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  result.translation() = position;
  return result;
}

// A wavy drive with some climb and roll: 1 m steps, heading changing, not planar.
std::vector<Eigen::Isometry3d> wavyTrajectory(int count) {
  std::vector<Eigen::Isometry3d> poses;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  for (int i = 0; i < count; ++i) {
    const double heading = 0.8 * std::sin(0.01 * i);
    Eigen::Isometry3d current = pose(heading, position);
    current.linear() = current.linear() * Eigen::AngleAxisd(0.05 * std::sin(0.1 * i), Eigen::Vector3d::UnitX()).toRotationMatrix();
    poses.push_back(current);
    position += Eigen::Vector3d(std::cos(heading), std::sin(heading), 0.02 * std::cos(0.03 * i));
  }
  return poses;
}

// Straight along x, 1 m per frame.
std::vector<Eigen::Isometry3d> straightLine(int count) {
  std::vector<Eigen::Isometry3d> poses;
  for (int i = 0; i < count; ++i) poses.push_back(pose(0.0, Eigen::Vector3d(i, 0, 0)));
  return poses;
}

// Segments of the devkit on a 1 m-per-frame line of `frames` frames: starts
// every 10th frame, ending at the first frame more than `length` further on.
std::size_t devkitSegments(int frames, int length) {
  return static_cast<std::size_t>((frames - 1 - (length + 1)) / 10 + 1);
}

// ---------------------------------------------------------------- statistics, angles

TEST(ErrorStatistics, MatchesHandComputedValues) {
  const ErrorStatistics statistics = summarize({4, 1, 3, 2});
  EXPECT_EQ(statistics.count, 4u);
  EXPECT_DOUBLE_EQ(statistics.mean, 2.5);
  EXPECT_DOUBLE_EQ(statistics.rmse, std::sqrt(7.5));
  EXPECT_DOUBLE_EQ(statistics.standard_deviation, std::sqrt(1.25));
  EXPECT_DOUBLE_EQ(statistics.minimum, 1);
  EXPECT_DOUBLE_EQ(statistics.first_quartile, 1.75);  // numpy.percentile([1,2,3,4], 25)
  EXPECT_DOUBLE_EQ(statistics.median, 2.5);
  EXPECT_DOUBLE_EQ(statistics.third_quartile, 3.25);
  EXPECT_DOUBLE_EQ(statistics.maximum, 4);
  EXPECT_EQ(summarize({}).count, 0u);
}

TEST(RotationAngle, IsTheAngleOfTheRotation) {
  for (const double angle : {1e-9, 1e-4, 0.5, M_PI / 2, 3.0}) {
    const Eigen::Matrix3d rotation =
        Eigen::AngleAxisd(angle, Eigen::Vector3d(1, -2, 0.5).normalized()).toRotationMatrix();
    EXPECT_NEAR(rotationAngle(rotation), angle, 1e-15 + 1e-12 * angle) << angle;
  }
  EXPECT_EQ(rotationAngle(Eigen::Matrix3d::Identity()), 0.0);
}

// ---------------------------------------------------------------- Umeyama

TEST(Umeyama, RecoversARandomRigidMotionExactly) {
  std::mt19937 generator(7);
  std::normal_distribution<double> normal(0.0, 10.0);
  for (int trial = 0; trial < 5; ++trial) {
    const Eigen::Quaterniond rotation = Eigen::Quaterniond::UnitRandom();
    const Eigen::Vector3d translation(normal(generator), normal(generator), normal(generator));
    std::vector<Eigen::Vector3d> source, target;
    for (int i = 0; i < 50; ++i) {
      source.emplace_back(normal(generator), normal(generator), normal(generator));
      target.push_back(rotation * source.back() + translation);
    }
    const SimilarityTransform found = umeyamaAlignment(source, target, false);
    EXPECT_LT((found.rotation - rotation.toRotationMatrix()).norm(), 1e-12);
    EXPECT_LT((found.translation - translation).norm(), 1e-10);
    EXPECT_EQ(found.scale, 1.0);
    const SimilarityTransform with_scale = umeyamaAlignment(source, target, true);
    EXPECT_NEAR(with_scale.scale, 1.0, 1e-12);
  }
}

TEST(Umeyama, RecoversAScaleWhenAsked) {
  std::mt19937 generator(3);
  std::uniform_real_distribution<double> uniform(-5.0, 5.0);
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(0.3, 0.4, 1).normalized()).toRotationMatrix();
  std::vector<Eigen::Vector3d> source, target;
  for (int i = 0; i < 20; ++i) {
    source.emplace_back(uniform(generator), uniform(generator), uniform(generator));
    target.push_back(2.5 * (rotation * source.back()) + Eigen::Vector3d(1, 2, 3));
  }
  const SimilarityTransform found = umeyamaAlignment(source, target, true);
  EXPECT_NEAR(found.scale, 2.5, 1e-12);
  EXPECT_LT((found.rotation - rotation).norm(), 1e-12);
  for (std::size_t i = 0; i < source.size(); ++i) EXPECT_LT((found.apply(source[i]) - target[i]).norm(), 1e-10);
}

TEST(Umeyama, RejectsUnequalInputsAndHandlesOnePoint) {
  EXPECT_TRUE(contains(errorOf([] { umeyamaAlignment({Eigen::Vector3d::Zero()}, {}, false); }), "equally many"));
  const SimilarityTransform single = umeyamaAlignment({Eigen::Vector3d(1, 2, 3)}, {Eigen::Vector3d(2, 2, 2)}, true);
  EXPECT_EQ(single.scale, 1.0);
  EXPECT_LT((single.apply(Eigen::Vector3d(1, 2, 3)) - Eigen::Vector3d(2, 2, 2)).norm(), 1e-12);
}

// ---------------------------------------------------------------- ATE

TEST(TrajectoryEvaluation, ATrajectoryAgainstItselfIsZeroEverywhere) {
  const std::vector<Eigen::Isometry3d> poses = wavyTrajectory(1000);
  const TrajectoryEvaluation evaluation = evaluateTrajectory(poses, poses);
  EXPECT_LT(evaluation.absolute_translation_m.maximum, 1e-9);
  EXPECT_LT(evaluation.absolute_rotation_deg.maximum, 1e-9);
  ASSERT_GT(evaluation.kitti.segments, 0u);
  EXPECT_EQ(evaluation.kitti.per_length.size(), 8u);
  EXPECT_LT(evaluation.kitti.translation_percent, 1e-9);
  EXPECT_LT(evaluation.kitti.rotation_deg_per_m, 1e-9);
  EXPECT_LT(evaluation.frame_to_frame.translation_m.maximum, 1e-12);
  EXPECT_LT(evaluation.frame_to_frame.rotation_deg.maximum, 1e-9);
  ASSERT_EQ(evaluation.pairwise.size(), 10u);
  for (const PairwiseErrors& errors : evaluation.pairwise) {
    EXPECT_EQ(errors.rotation_deg.size(), 50u);
    EXPECT_LT(errors.translation_statistics.maximum, 1e-12);
    EXPECT_LT(errors.rotation_statistics.maximum, 1e-9);
  }
  EXPECT_NEAR(evaluation.ground_truth_length_m, 999.0, 1.0);
}

TEST(TrajectoryEvaluation, AConstantOffsetIsRemovedByAlignmentAndMeasuredWithout) {
  const std::vector<Eigen::Isometry3d> truth = wavyTrajectory(300);
  const Eigen::Vector3d offset(0.3, -0.4, 1.2);  // |offset| = 1.3
  std::vector<Eigen::Isometry3d> estimate;
  for (const Eigen::Isometry3d& pose : truth) estimate.push_back(Eigen::Translation3d(offset) * pose);

  const TrajectoryEvaluation aligned = evaluateTrajectory(estimate, truth);
  EXPECT_LT(aligned.absolute_translation_m.rmse, 1e-9);
  EXPECT_LT((aligned.alignment_transform.translation + offset).norm(), 1e-9);

  TrajectoryEvaluationOptions options;
  options.alignment = Alignment::kNone;
  const TrajectoryEvaluation raw = evaluateTrajectory(estimate, truth, options);
  EXPECT_NEAR(raw.absolute_translation_m.rmse, 1.3, 1e-12);
  EXPECT_NEAR(raw.absolute_translation_m.mean, 1.3, 1e-12);
  EXPECT_NEAR(raw.absolute_translation_m.median, 1.3, 1e-12);
  EXPECT_NEAR(raw.absolute_translation_m.maximum, 1.3, 1e-12);
  // A world offset leaves every relative pose as it was.
  EXPECT_LT(raw.frame_to_frame.translation_m.maximum, 1e-9);
  for (const PairwiseErrors& errors : raw.pairwise) EXPECT_LT(errors.translation_statistics.maximum, 1e-9);
}

TEST(TrajectoryEvaluation, ScaleAlignmentUndoesAScaledEstimate) {
  const std::vector<Eigen::Isometry3d> truth = wavyTrajectory(200);
  std::vector<Eigen::Isometry3d> estimate = truth;
  for (Eigen::Isometry3d& pose : estimate) pose.translation() *= 0.5;
  TrajectoryEvaluationOptions options;
  options.alignment = Alignment::kSim3;
  const TrajectoryEvaluation evaluation = evaluateTrajectory(estimate, truth, options);
  EXPECT_NEAR(evaluation.alignment_transform.scale, 2.0, 1e-9);
  EXPECT_LT(evaluation.absolute_translation_m.rmse, 1e-8);
  EXPECT_LT(evaluation.frame_to_frame.translation_m.maximum, 1e-8);
  options.alignment = Alignment::kSE3;
  EXPECT_GT(evaluateTrajectory(estimate, truth, options).absolute_translation_m.rmse, 1.0);
}

// ---------------------------------------------------------------- RPE

TEST(TrajectoryEvaluation, ARotationDriftGivesTheExpectedDegreesPerMetre) {
  const int frames = 1001;
  const double drift = 0.01 * kDegree;  // per frame, i.e. per metre
  const std::vector<Eigen::Isometry3d> truth = straightLine(frames);
  std::vector<Eigen::Isometry3d> estimate;
  for (int i = 0; i < frames; ++i) estimate.push_back(pose(i * drift, truth[i].translation()));

  TrajectoryEvaluationOptions options;
  options.alignment = Alignment::kNone;
  const TrajectoryEvaluation evaluation = evaluateTrajectory(estimate, truth, options);
  ASSERT_EQ(evaluation.kitti.per_length.size(), 8u);
  std::size_t segments = 0;
  for (const KittiLengthError& length : evaluation.kitti.per_length) {
    const int metres = static_cast<int>(length.length_m);
    // A segment of `metres` ends metres + 1 frames on: the first frame *more* than the length away.
    EXPECT_NEAR(length.rotation_deg_per_m, 0.01 * (metres + 1) / metres, 1e-9) << metres;
    EXPECT_EQ(length.segments, devkitSegments(frames, metres)) << metres;
    segments += length.segments;
  }
  EXPECT_EQ(evaluation.kitti.segments, segments);
  EXPECT_NEAR(evaluation.frame_to_frame.rotation_deg_per_m, 0.01, 1e-9);
  EXPECT_NEAR(evaluation.frame_to_frame.rotation_deg.median, 0.01, 1e-9);
  for (const PairwiseErrors& errors : evaluation.pairwise) {
    EXPECT_NEAR(errors.rotation_statistics.minimum, 0.01 * errors.frame_distance, 1e-9);
    EXPECT_NEAR(errors.rotation_statistics.maximum, 0.01 * errors.frame_distance, 1e-9);
  }
}

TEST(TrajectoryEvaluation, AScaleDriftGivesTheExpectedTranslationPercent) {
  const int frames = 901;
  const std::vector<Eigen::Isometry3d> truth = straightLine(frames);
  std::vector<Eigen::Isometry3d> estimate;  // 1 % too far every step
  for (int i = 0; i < frames; ++i) estimate.push_back(pose(0.0, Eigen::Vector3d(1.01 * i, 0, 0)));
  TrajectoryEvaluationOptions options;
  options.alignment = Alignment::kNone;
  const TrajectoryEvaluation evaluation = evaluateTrajectory(estimate, truth, options);
  ASSERT_EQ(evaluation.kitti.per_length.size(), 8u);
  for (const KittiLengthError& length : evaluation.kitti.per_length)
    EXPECT_NEAR(length.translation_percent, 1.0 * (length.length_m + 1) / length.length_m, 1e-9);
  EXPECT_NEAR(evaluation.frame_to_frame.translation_percent, 1.0, 1e-9);
  EXPECT_NEAR(evaluation.pairwise[4].translation_statistics.median, 0.05, 1e-9);
}

TEST(TrajectoryEvaluation, AShortRunHasNoKittiSegmentsButFrameToFrameErrors) {
  const std::vector<Eigen::Isometry3d> truth = straightLine(30);
  const TrajectoryEvaluation evaluation = evaluateTrajectory(truth, truth);
  EXPECT_EQ(evaluation.kitti.segments, 0u);
  EXPECT_TRUE(evaluation.kitti.per_length.empty());
  EXPECT_EQ(evaluation.frame_to_frame.translation_m.count, 29u);
  // Fewer pairs than the sample size: all of them.
  ASSERT_EQ(evaluation.pairwise.size(), 10u);
  EXPECT_EQ(evaluation.pairwise[0].first_frames.size(), 29u);
  EXPECT_EQ(evaluation.pairwise[9].first_frames.size(), 20u);
  // Two poses: one frame distance only.
  const std::vector<Eigen::Isometry3d> two(truth.begin(), truth.begin() + 2);
  EXPECT_EQ(evaluateTrajectory(two, two).pairwise.size(), 1u);
}

TEST(TrajectoryEvaluation, PairsAreASeededSampleWithoutRepeats) {
  const std::vector<Eigen::Isometry3d> truth = wavyTrajectory(500);
  TrajectoryEvaluationOptions options;
  options.pairs_per_distance = 40;
  const TrajectoryEvaluation first = evaluateTrajectory(truth, truth, options);
  const TrajectoryEvaluation again = evaluateTrajectory(truth, truth, options);
  options.seed = 5;
  const TrajectoryEvaluation other = evaluateTrajectory(truth, truth, options);
  for (std::size_t d = 0; d < first.pairwise.size(); ++d) {
    const std::vector<std::size_t>& frames = first.pairwise[d].first_frames;
    ASSERT_EQ(frames.size(), 40u);
    EXPECT_EQ(std::set<std::size_t>(frames.begin(), frames.end()).size(), 40u);
    EXPECT_LT(frames.back() + first.pairwise[d].frame_distance, truth.size());
    EXPECT_EQ(frames, again.pairwise[d].first_frames);
    EXPECT_NE(frames, other.pairwise[d].first_frames);
  }
}

TEST(TrajectoryEvaluation, RejectsBadInput) {
  const std::vector<Eigen::Isometry3d> truth = straightLine(10);
  const std::vector<Eigen::Isometry3d> shorter(truth.begin(), truth.begin() + 9);
  EXPECT_TRUE(contains(errorOf([&] { evaluateTrajectory(shorter, truth); }), "9 and 10"));
  EXPECT_TRUE(contains(errorOf([&] { evaluateTrajectory({}, {}); }), "at least one"));
  TrajectoryEvaluationOptions options;
  options.pairs_per_distance = 0;
  EXPECT_TRUE(contains(errorOf([&] { evaluateTrajectory(truth, truth, options); }), "pairs_per_distance"));
}

// ---------------------------------------------------------------- files, association

TEST(TrajectoryFiles, TumIsDetectedAndHasTimes) {
  std::vector<io::StampedPose> written;
  const std::vector<Eigen::Isometry3d> poses = wavyTrajectory(20);
  for (std::size_t i = 0; i < poses.size(); ++i) written.push_back({1e9 + 0.1 * i, poses[i]});
  const std::string path = temporaryPath("round_trip.tum");
  io::writeTumPoses(path, written);
  const StampedTrajectory read = readTrajectory(path);
  ASSERT_EQ(read.poses.size(), poses.size());
  ASSERT_TRUE(read.hasTimes());
  for (std::size_t i = 0; i < poses.size(); ++i) {
    EXPECT_NEAR(read.times_s[i], written[i].time_s, 1e-6);
    EXPECT_LT((read.poses[i].matrix() - poses[i].matrix()).norm(), 1e-8);
  }
  std::filesystem::remove(path);
}

TEST(TrajectoryFiles, KittiIsDetectedAndHasNoTimes) {
  const std::string path = temporaryPath("poses.txt");
  io::writeKittiPoses(path, wavyTrajectory(5));
  const StampedTrajectory read = readTrajectory(path);
  EXPECT_EQ(read.poses.size(), 5u);
  EXPECT_FALSE(read.hasTimes());
  EXPECT_EQ(readTrajectory(path, PoseFileFormat::kKitti).poses.size(), 5u);
  EXPECT_TRUE(contains(errorOf([&] { readTrajectory(path, PoseFileFormat::kTum); }), "has 12 numbers, not 8"));
  std::filesystem::remove(path);
}

TEST(TrajectoryFiles, BadFilesGiveNamedErrors) {
  const std::string path = temporaryPath("bad.txt");
  writeFile(path, "# comment\n1 2 3 4 5 6 7\n");
  EXPECT_TRUE(contains(errorOf([&] { readTrajectory(path); }), "line 2 has 7 values"));
  writeFile(path, "\n# only a comment\n");
  EXPECT_TRUE(contains(errorOf([&] { readTrajectory(path); }), "holds no pose"));
  writeFile(path, "0 1 2 3 0 0 0 0\n");
  EXPECT_TRUE(contains(errorOf([&] { readTrajectory(path); }), "line 1 has a quaternion of norm 0"));
  writeFile(path, "1 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n");
  EXPECT_TRUE(contains(errorOf([&] { readTrajectory(path); }), "pose 2 has time 1 s, not after the previous"));
  writeFile(path, "0 1 2 3 0 0 0 1\n0.1 1 2 x 0 0 0 1\n");
  EXPECT_TRUE(contains(errorOf([&] { readTrajectory(path); }), "line 2"));
  writeFile(path, "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n");
  const std::string kitti_error = errorOf([&] { readTrajectory(path); });
  EXPECT_TRUE(contains(kitti_error, "line 2")) << kitti_error;
  EXPECT_THROW(readTrajectory(path), TrajectoryFormatError);
  EXPECT_TRUE(contains(errorOf([] { readTrajectory("/nonexistent/poses.txt"); }), "cannot open /nonexistent/poses.txt"));
  std::filesystem::remove(path);
}

StampedTrajectory stamped(const std::vector<double>& times) {
  StampedTrajectory trajectory;
  trajectory.times_s = times;
  for (const double time : times) trajectory.poses.push_back(pose(0, Eigen::Vector3d(time, 0, 0)));
  return trajectory;
}

TEST(Association, ByTimestampTakesTheNearestWithinTolerance) {
  const StampedTrajectory truth = stamped({0.0, 0.1, 0.2, 0.3, 0.4});
  // 0.203 and 0.198 both want 0.2: the nearer one wins; 0.35 is too far from anything.
  const StampedTrajectory estimate = stamped({0.004, 0.098, 0.198, 0.203, 0.35, 0.401});
  const AssociatedPoses associated = associateByTimestamp(estimate, truth, 0.01);
  EXPECT_TRUE(associated.by_timestamp);
  EXPECT_EQ(associated.estimate_index, (std::vector<std::size_t>{0, 1, 2, 5}));
  EXPECT_EQ(associated.ground_truth_index, (std::vector<std::size_t>{0, 1, 2, 4}));
  EXPECT_EQ(associated.times_s, (std::vector<double>{0.0, 0.1, 0.2, 0.4}));
  EXPECT_TRUE(contains(errorOf([&] { associateByTimestamp(stamped({5.0}), truth, 0.01); }),
                       "no estimate time"));
  StampedTrajectory no_times = truth;
  no_times.times_s.clear();
  EXPECT_TRUE(contains(errorOf([&] { associateByTimestamp(truth, no_times, 0.01); }),
                       "the ground truth has no timestamps"));
}

TEST(Association, ByIndexNeedsEqualCounts) {
  const StampedTrajectory truth = stamped({0.0, 0.1, 0.2});
  EXPECT_EQ(associateByIndex(truth, truth).estimate.size(), 3u);
  EXPECT_TRUE(contains(errorOf([&] { associateByIndex(stamped({0.0, 0.1}), truth); }),
                       "the estimate has 2 poses and the ground truth 3"));
}

// ---------------------------------------------------------------- real data

TEST(TrajectoryEvaluation, KittiGroundTruthAgainstItselfIsZero) {
  RIM_REQUIRE_DATA(poses_path, "kitti00/poses_00_full_evo.txt");
  const StampedTrajectory truth = readTrajectory(poses_path);
  ASSERT_EQ(truth.poses.size(), 4541u);  // frames 0..4540 (SOURCE.md)
  const TrajectoryEvaluation evaluation = evaluateTrajectory(truth.poses, truth.poses);
  EXPECT_LT(evaluation.absolute_translation_m.maximum, 1e-9);
  EXPECT_GT(evaluation.kitti.segments, 1000u);
  EXPECT_EQ(evaluation.kitti.per_length.size(), 8u);
  EXPECT_LT(evaluation.kitti.translation_percent, 1e-9);
  EXPECT_LT(evaluation.kitti.rotation_deg_per_m, 1e-9);
  for (const PairwiseErrors& errors : evaluation.pairwise) {
    EXPECT_LT(errors.translation_statistics.maximum, 1e-9);
    EXPECT_LT(errors.rotation_statistics.maximum, 1e-9);
  }
}

}  // namespace
}  // namespace range_image_mapping::evaluation
