// Runs the built rim binary: `rim eval traj` and `rim eval mesh` on files
// written here, checking exit codes, the JSON report and the error messages.
#include "range_image_mapping/evaluation/report.h"
#include "range_image_mapping/evaluation/trajectory_metrics.h"
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/ply.h"
#include "range_image_mapping/io/pose_file.h"
#include "range_image_mapping/simulation/mesh_primitives.h"
#include "range_image_mapping/surface_sampling.h"
#include "rim_command.h"
#include "test_data.h"

#include <gtest/gtest.h>
// The core links jsoncpp privately; its headers live in a jsoncpp/ folder.
#include <jsoncpp/json/json.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>

namespace range_image_mapping::evaluation {
namespace {

using test::readText;
using test::RunResult;

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

Json::Value parseJson(const std::string& text) {
  Json::Value value;
  std::string errors;
  std::istringstream stream(text);
  Json::CharReaderBuilder builder;
  EXPECT_TRUE(Json::parseFromStream(builder, stream, &value, &errors)) << errors << "\n" << text;
  return value;
}

// A fresh folder per test, removed afterwards (test/rim_command.h).
using EvalCommand = test::RimCommandTest;

// A drive with turns and some climb, 1 m per frame.
std::vector<Eigen::Isometry3d> wavyTrajectory(int count) {
  std::vector<Eigen::Isometry3d> poses;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  for (int i = 0; i < count; ++i) {
    const double heading = 1.2 * std::sin(0.02 * i);
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.linear() = Eigen::AngleAxisd(heading, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    pose.translation() = position;
    poses.push_back(pose);
    position += Eigen::Vector3d(std::cos(heading), std::sin(heading), 0.05 * std::cos(0.05 * i));
  }
  return poses;
}

std::vector<Eigen::Isometry3d> offset(const std::vector<Eigen::Isometry3d>& poses,
                                      const Eigen::Vector3d& shift) {
  std::vector<Eigen::Isometry3d> moved;
  for (const Eigen::Isometry3d& pose : poses) moved.push_back(Eigen::Translation3d(shift) * pose);
  return moved;
}

void writeQuad(const std::string& path, float width, float depth, float height) {
  const TriangleMesh quad = simulation::makeQuad(
      Eigen::Vector3f(0, 0, height), Eigen::Vector3f(width, 0, 0), Eigen::Vector3f(0, depth, 0));
  io::writePlyMesh(path, quad.vertices, {}, quad.triangles);
}

bool isPng(const std::string& path) {
  const std::string bytes = readText(path);
  return bytes.size() > 1000 && bytes.compare(0, 8, "\x89PNG\r\n\x1a\n") == 0;
}

// ---------------------------------------------------------------- traj

TEST_F(EvalCommand, TrajectoryWithAConstantOffset) {
  const std::vector<Eigen::Isometry3d> truth = wavyTrajectory(300);
  io::writeKittiPoses(path("truth.txt"), truth);
  io::writeKittiPoses(path("estimate.txt"), offset(truth, Eigen::Vector3d(0.3, -0.4, 1.2)));

  const RunResult aligned = rim("eval traj '" + path("estimate.txt") + "' '" + path("truth.txt") + "' --json -");
  ASSERT_EQ(aligned.exit_code, 0) << aligned.err;
  const Json::Value report = parseJson(aligned.out);
  EXPECT_EQ(report["kind"].asString(), "trajectory");
  EXPECT_EQ(report["association"]["method"].asString(), "index");
  EXPECT_EQ(report["association"]["pairs"].asUInt(), 300u);
  EXPECT_EQ(report["alignment"]["method"].asString(), "se3");
  EXPECT_LT(report["ate"]["translation_m"]["rmse"].asDouble(), 1e-6);
  EXPECT_NEAR(report["alignment"]["translation"][2].asDouble(), -1.2, 1e-6);
  EXPECT_EQ(report["ate"]["per_pose_m"].size(), 300u);
  EXPECT_GT(report["kitti_rpe"]["segments"].asUInt(), 0u);  // 299 m: the 100 and 200 m lengths fit
  EXPECT_EQ(report["kitti_rpe"]["lengths"].size(), 2u);
  ASSERT_EQ(report["pairwise"].size(), 10u);
  EXPECT_EQ(report["pairwise"][9]["frame_distance"].asInt(), 10);
  EXPECT_EQ(report["pairwise"][9]["pairs"].asUInt(), 50u);
  EXPECT_EQ(report["pairwise"][9]["rotation_deg_samples"].size(), 50u);
  EXPECT_TRUE(contains(aligned.err, "ATE 0.0000 m RMSE (se3, 300 poses"));  // the summary, on stderr with --json -

  const RunResult raw = rim("eval traj '" + path("estimate.txt") + "' '" + path("truth.txt") +
                            "' --no-align --json '" + path("report.json") + "'");
  ASSERT_EQ(raw.exit_code, 0) << raw.err;
  EXPECT_EQ(raw.out.rfind("ATE 1.3000 m RMSE (none", 0), 0u) << raw.out;
  const Json::Value raw_report = parseJson(readText(path("report.json")));
  // The KITTI files hold about 9 significant digits.
  EXPECT_NEAR(raw_report["ate"]["translation_m"]["rmse"].asDouble(), 1.3, 1e-6);
  EXPECT_NEAR(raw_report["ate"]["translation_m"]["max"].asDouble(), 1.3, 1e-6);
  EXPECT_LT(raw_report["frame_to_frame"]["translation_m"]["max"].asDouble(), 1e-6);
}

TEST_F(EvalCommand, TumTrajectoriesAreAssociatedByTime) {
  const std::vector<Eigen::Isometry3d> poses = wavyTrajectory(200);
  std::vector<io::StampedPose> truth, estimate;
  for (std::size_t i = 0; i < poses.size(); ++i) truth.push_back({100.0 + 0.1 * i, poses[i]});
  // Every other pose, 4 ms late: 100 associated.
  for (std::size_t i = 0; i < poses.size(); i += 2) estimate.push_back({truth[i].time_s + 0.004, poses[i]});
  io::writeTumPoses(path("truth.tum"), truth);
  io::writeTumPoses(path("estimate.tum"), estimate);
  const RunResult run = rim("eval traj '" + path("estimate.tum") + "' '" + path("truth.tum") + "' --json -");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const Json::Value report = parseJson(run.out);
  EXPECT_EQ(report["association"]["method"].asString(), "timestamp");
  EXPECT_EQ(report["association"]["pairs"].asUInt(), 100u);
  EXPECT_LT(report["ate"]["translation_m"]["max"].asDouble(), 1e-6);

  // 4 ms apart is beyond a 3 ms tolerance: nothing to compare.
  const RunResult strict = rim("eval traj '" + path("estimate.tum") + "' '" + path("truth.tum") +
                               "' --max-time-difference 0.003");
  EXPECT_EQ(strict.exit_code, 1);
  EXPECT_TRUE(contains(strict.err, "no estimate time")) << strict.err;
}

TEST_F(EvalCommand, TrajectoryPlotsArePngs) {
  const std::vector<Eigen::Isometry3d> truth = wavyTrajectory(120);
  io::writeKittiPoses(path("truth.txt"), truth);
  std::vector<Eigen::Isometry3d> estimate = truth;
  for (std::size_t i = 0; i < estimate.size(); ++i) estimate[i].translation().y() += 0.002 * i;
  io::writeKittiPoses(path("estimate.txt"), estimate);
  const RunResult run = rim("eval traj '" + path("estimate.txt") + "' '" + path("truth.txt") +
                            "' --plots '" + path("plots") + "' --json '" + path("report.json") + "'");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const Json::Value report = parseJson(readText(path("report.json")));
  if (findGnuplot().empty()) {
    EXPECT_TRUE(contains(run.err, "gnuplot not found")) << run.err;
    return;
  }
  EXPECT_TRUE(isPng(path("plots/trajectory_top_view.png")));
  EXPECT_TRUE(isPng(path("plots/pairwise_errors.png")));
  ASSERT_EQ(report["outputs"].size(), 2u);
  EXPECT_EQ(report["outputs"][0].asString(), path("plots") + "/trajectory_top_view.png");
  EXPECT_EQ(report["warnings"].size(), 0u);

  // A straight drive far from the origin: the top view's ranges are widened
  // around it, and the colour range of the errors must still be found.
  std::vector<Eigen::Isometry3d> straight(60, Eigen::Isometry3d::Identity()), drifting;
  for (std::size_t i = 0; i < straight.size(); ++i) {
    straight[i].translation() = Eigen::Vector3d(500.0 + 0.8 * double(i), -300.0, 0.0);
    drifting.push_back(straight[i]);
    drifting.back().translation().y() += 0.001 * double(i);
  }
  io::writeKittiPoses(path("straight.txt"), straight);
  io::writeKittiPoses(path("drifting.txt"), drifting);
  const RunResult far = rim("eval traj '" + path("drifting.txt") + "' '" + path("straight.txt") + "' --plots '" +
                            path("far_plots") + "' --json '" + path("far.json") + "'");
  ASSERT_EQ(far.exit_code, 0) << far.err;
  const Json::Value far_report = parseJson(readText(path("far.json")));
  EXPECT_TRUE(isPng(path("far_plots/trajectory_top_view.png")));
  EXPECT_EQ(far_report["warnings"].size(), 0u) << far.err;
}

TEST_F(EvalCommand, WithoutGnuplotTheJsonIsStillWritten) {
  const std::vector<Eigen::Isometry3d> truth = wavyTrajectory(50);
  io::writeKittiPoses(path("truth.txt"), truth);
  const RunResult run = rim("eval traj '" + path("truth.txt") + "' '" + path("truth.txt") + "' --plots '" +
                                path("plots") + "' --json '" + path("report.json") + "'",
                            "PATH=/nonexistent");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_TRUE(contains(run.err, "gnuplot not found on PATH (Debian package gnuplot-nox)")) << run.err;
  EXPECT_FALSE(std::filesystem::exists(path("plots/trajectory_top_view.png")));
  const Json::Value report = parseJson(readText(path("report.json")));
  EXPECT_EQ(report["outputs"].size(), 0u);
  ASSERT_GE(report["warnings"].size(), 1u);
  EXPECT_TRUE(contains(report["warnings"][0].asString(), "gnuplot not found"));
  EXPECT_LT(report["ate"]["translation_m"]["rmse"].asDouble(), 1e-9);
}

TEST_F(EvalCommand, KittiGroundTruthAgainstItself) {
  RIM_REQUIRE_DATA(poses_path, "kitti00/poses_00_full_evo.txt");
  const RunResult run = rim("eval traj '" + poses_path + "' '" + poses_path + "' --json -");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const Json::Value report = parseJson(run.out);
  EXPECT_EQ(report["association"]["pairs"].asUInt(), 4541u);  // SOURCE.md: frames 0..4540
  EXPECT_LT(report["ate"]["translation_m"]["max"].asDouble(), 1e-9);
  EXPECT_GT(report["kitti_rpe"]["segments"].asUInt(), 1000u);
  EXPECT_LT(report["kitti_rpe"]["translation_percent"].asDouble(), 1e-9);
  EXPECT_LT(report["kitti_rpe"]["rotation_deg_per_m"].asDouble(), 1e-9);
}

TEST_F(EvalCommand, BadTrajectoryInputFailsWithANamedError) {
  std::ofstream(path("seven.txt")) << "1 2 3 4 5 6 7\n";
  io::writeKittiPoses(path("five.txt"), wavyTrajectory(5));
  io::writeKittiPoses(path("six.txt"), wavyTrajectory(6));

  const RunResult malformed = rim("eval traj '" + path("seven.txt") + "' '" + path("six.txt") + "'");
  EXPECT_EQ(malformed.exit_code, 1);
  EXPECT_TRUE(contains(malformed.err, path("seven.txt") + " line 1 has 7 values")) << malformed.err;

  const RunResult counts = rim("eval traj '" + path("five.txt") + "' '" + path("six.txt") + "'");
  EXPECT_EQ(counts.exit_code, 1);
  EXPECT_TRUE(contains(counts.err, "the estimate has 5 poses and the ground truth 6")) << counts.err;

  const RunResult missing = rim("eval traj '" + path("absent.txt") + "' '" + path("six.txt") + "'");
  EXPECT_NE(missing.exit_code, 0);
  EXPECT_TRUE(contains(missing.err + missing.out, path("absent.txt"))) << missing.err;

  const RunResult both = rim("eval traj '" + path("six.txt") + "' '" + path("six.txt") + "' --no-align --align-scale");
  EXPECT_NE(both.exit_code, 0);
  EXPECT_TRUE(contains(both.err + both.out, "excludes")) << both.err;

  const RunResult nothing = rim("eval");
  EXPECT_NE(nothing.exit_code, 0);
}

// ---------------------------------------------------------------- mesh

TEST_F(EvalCommand, MeshAgainstItselfAndShifted) {
  writeQuad(path("truth.ply"), 3, 2, 0);
  writeQuad(path("near.ply"), 3, 2, 0.05f);
  writeQuad(path("far.ply"), 3, 2, 0.12f);

  const RunResult itself = rim("eval mesh '" + path("truth.ply") + "' '" + path("truth.ply") + "' --voxel 0.03 --json -");
  ASSERT_EQ(itself.exit_code, 0) << itself.err;
  const Json::Value same = parseJson(itself.out);
  EXPECT_EQ(same["kind"].asString(), "surface");
  EXPECT_NEAR(same["threshold_m"].asDouble(), 0.09, 1e-12);
  EXPECT_NEAR(same["sample_spacing_m"].asDouble(), 0.0225, 1e-12);
  EXPECT_EQ(same["estimate"]["type"].asString(), "mesh");
  EXPECT_EQ(same["precision"].asDouble(), 1.0);
  EXPECT_EQ(same["recall"].asDouble(), 1.0);
  EXPECT_EQ(same["f_score"].asDouble(), 1.0);
  EXPECT_EQ(same["f_score_paper"].asDouble(), 0.5);
  EXPECT_EQ(same["chamfer_m"].asDouble(), 0.0);
  EXPECT_TRUE(contains(itself.err, "F-score 1.0000"));

  const RunResult near = rim("eval mesh '" + path("near.ply") + "' '" + path("truth.ply") + "' --voxel 0.03 --json -");
  ASSERT_EQ(near.exit_code, 0) << near.err;
  const Json::Value near_report = parseJson(near.out);
  EXPECT_EQ(near_report["precision"].asDouble(), 1.0);
  EXPECT_EQ(near_report["recall"].asDouble(), 1.0);
  EXPECT_NEAR(near_report["chamfer_m"].asDouble(), 0.05, 1e-6);  // the same sample positions, shifted

  const RunResult far = rim("eval mesh '" + path("far.ply") + "' '" + path("truth.ply") + "' --threshold 0.09");
  ASSERT_EQ(far.exit_code, 0) << far.err;
  EXPECT_EQ(far.out.rfind("F-score 0.0000 (precision 0.0000, recall 0.0000", 0), 0u) << far.out;
  EXPECT_TRUE(contains(far.out, "Chamfer 0.12 m"));
}

TEST_F(EvalCommand, CloudMissingHalfOfTheGroundTruthAndItsMaps) {
  writeQuad(path("truth.ply"), 2, 1, 0);
  const TriangleMesh half =
      simulation::makeQuad(Eigen::Vector3f::Zero(), Eigen::Vector3f(1, 0, 0), Eigen::Vector3f(0, 1, 0));
  SurfaceSampleOptions sampling;
  sampling.spacing_m = 0.005;
  const std::vector<Eigen::Vector3f> cloud = sampleSurface(half, sampling);
  io::writePlyPointCloud(path("half_cloud.ply"), cloud);
  const RunResult run = rim("eval mesh '" + path("half_cloud.ply") + "' '" + path("truth.ply") +
                            "' --threshold 0.02 --plots '" + path("maps") + "' --json -");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const Json::Value report = parseJson(run.out);
  EXPECT_EQ(report["estimate"]["type"].asString(), "point_cloud");
  EXPECT_EQ(report["estimate"]["points"].asUInt64(), cloud.size());
  EXPECT_EQ(report["ground_truth"]["type"].asString(), "mesh");
  EXPECT_NEAR(report["ground_truth"]["area_m2"].asDouble(), 2.0, 1e-6);
  EXPECT_EQ(report["precision"].asDouble(), 1.0);
  EXPECT_NEAR(report["recall"].asDouble(), 0.5, 0.02);
  ASSERT_EQ(report["outputs"].size(), 2u);
  EXPECT_EQ(io::readPlyPoints(path("maps/precision_map.ply")), cloud);
  const std::string recall_map = readText(path("maps/recall_map.ply"));
  EXPECT_TRUE(contains(recall_map, "property uchar red\nproperty uchar green\nproperty uchar blue\n"));
  EXPECT_EQ(io::readPlyPoints(path("maps/recall_map.ply")).size(), report["ground_truth"]["points"].asUInt64());
}

TEST_F(EvalCommand, BadMeshInputFailsWithANamedError) {
  writeQuad(path("truth.ply"), 1, 1, 0);
  const RunResult no_threshold = rim("eval mesh '" + path("truth.ply") + "' '" + path("truth.ply") + "'");
  EXPECT_NE(no_threshold.exit_code, 0);
  EXPECT_TRUE(contains(no_threshold.err, "give --voxel (threshold 3 x voxel) or --threshold")) << no_threshold.err;

  const RunResult both = rim("eval mesh '" + path("truth.ply") + "' '" + path("truth.ply") + "' --voxel 0.1 --threshold 0.3");
  EXPECT_NE(both.exit_code, 0);
  EXPECT_TRUE(contains(both.err, "excludes")) << both.err;

  std::ofstream(path("broken.ply")) << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n";
  const RunResult broken = rim("eval mesh '" + path("broken.ply") + "' '" + path("truth.ply") + "' --voxel 0.1");
  EXPECT_EQ(broken.exit_code, 1);
  EXPECT_TRUE(contains(broken.err, "PLY: " + path("broken.ply"))) << broken.err;

  std::ofstream(path("points.xyz")) << "0 0 0\n";
  const RunResult unknown = rim("eval mesh '" + path("points.xyz") + "' '" + path("truth.ply") + "' --voxel 0.1");
  EXPECT_EQ(unknown.exit_code, 1);
  EXPECT_TRUE(contains(unknown.err, "unknown surface file type \".xyz\"")) << unknown.err;

  const RunResult huge = rim("eval mesh '" + path("truth.ply") + "' '" + path("truth.ply") +
                             "' --threshold 0.001 --max-samples 1000");
  EXPECT_EQ(huge.exit_code, 1);
  EXPECT_TRUE(contains(huge.err, "choose a larger spacing")) << huge.err;
}

}  // namespace
}  // namespace range_image_mapping::evaluation
