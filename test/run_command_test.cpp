// rim run end to end on a short simulated sequence: every output is written,
// the report agrees with the files, the poses are exactly rim odometry's (one
// implementation of each step), Ctrl-C saves what there is, and bad requests
// fail with a named error.
#include "range_image_mapping/io/pose_file.h"
#include "rim_command.h"

#include <gtest/gtest.h>
#include <json/json.h>

#include <filesystem>
#include <fstream>
#include <sstream>

namespace range_image_mapping {
namespace {

using RunCommand = test::RimCommandTest;

Json::Value readJson(const std::string& path) {
  Json::Value root;
  std::istringstream text(test::readText(path));
  std::string errors;
  EXPECT_TRUE(Json::parseFromStream(Json::CharReaderBuilder(), text, &root, &errors)) << path << ": " << errors;
  return root;
}

TEST_F(RunCommand, IndoorPresetGivesTrajectoryMeshAndReportAgainstGroundTruth) {
  const test::RunResult run = rim("run indoor_cart --frames 30 --out " + path("run"));
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_NE(run.err.find("30/30 frames"), std::string::npos) << run.err;  // the progress bar
  for (const char* file : {"trajectory.txt", "trajectory_tum.txt", "mesh.ply", "report.json", "odometry_frames.csv",
                           "sequence/capture.pcap"})
    EXPECT_TRUE(std::filesystem::exists(path("run/") + file)) << file;
  const Json::Value report = readJson(path("run/report.json"));
  EXPECT_EQ(report["frames"].asInt(), 30);
  EXPECT_EQ(report["environment"].asString(), "indoor");
  EXPECT_DOUBLE_EQ(report["mapping"]["voxel_m"].asDouble(), 0.04);
  EXPECT_FALSE(report["interrupted"].asBool());
  EXPECT_GT(report["timing"]["odometry_frames_per_second"].asDouble(), 0.0);
  EXPECT_GT(report["timing"]["mapping_frames_per_second"].asDouble(), 0.0);
  EXPECT_GT(report["mapping"]["triangles"].asUInt64(), 10000u);
  // Measured: ATE about 5 mm, F 0.97 at 3 voxels against the surface seen within the clip.
  EXPECT_LT(report["ground_truth"]["ate_rmse_m"].asDouble(), 0.02);
  EXPECT_GT(report["ground_truth"]["surface"]["f_score"].asDouble(), 0.93) << run.out;
  EXPECT_NE(run.out.find("ATE"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("F-score"), std::string::npos) << run.out;
  if (report["outputs"].isMember("report_png")) {
    // Four panels (top view, time, error, the odometry's health): 1500 x 1000
    // pixels, three would be 1500 x 600. The PNG's IHDR holds both, big-endian.
    std::ifstream png(path("run/report.png"), std::ios::binary);
    unsigned char header[24] = {};
    ASSERT_TRUE(png.read(reinterpret_cast<char*>(header), sizeof header)) << "report.png";
    const auto bigEndian = [&](int at) {
      return (uint32_t(header[at]) << 24) | (uint32_t(header[at + 1]) << 16) | (uint32_t(header[at + 2]) << 8) |
             uint32_t(header[at + 3]);
    };
    EXPECT_EQ(bigEndian(16), 1500u);
    EXPECT_EQ(bigEndian(20), 1000u);
  }

  // rim odometry on the same scans with the same settings: the very same poses.
  const test::RunResult odometry =
      rim("odometry " + path("run/sequence") + " --kernel-scale 0.2 --out " + path("odometry/traj.txt"));
  ASSERT_EQ(odometry.exit_code, 0) << odometry.err;
  const auto offline = io::readKittiPosesWithTimes(path("odometry/traj.txt"));
  const auto pipeline = io::readKittiPosesWithTimes(path("run/trajectory.txt"));
  ASSERT_EQ(offline.size(), pipeline.size());
  for (std::size_t k = 0; k < offline.size(); ++k) {
    EXPECT_DOUBLE_EQ(offline[k].time_s, pipeline[k].time_s);
    // The same code; only the order of TBB's parallel sums may differ between runs.
    EXPECT_LT((offline[k].pose.translation() - pipeline[k].pose.translation()).norm(), 1e-6) << "pose " << k;
    EXPECT_TRUE(offline[k].pose.linear().isApprox(pipeline[k].pose.linear(), 1e-6)) << "pose " << k;
  }
}

TEST_F(RunCommand, InterruptSavesWhatThereIs) {
  ASSERT_EQ(rim("simulate --preset indoor_cart --frames 150 --out " + path("sequence")).exit_code, 0);
  // SIGINT two seconds in, as Ctrl-C would send it.
  const test::RunResult run =
      rim("run " + path("sequence") + " --environment indoor --no-plot --out " + path("run"), "timeout --preserve-status -s INT 2");
  const Json::Value report = readJson(path("run/report.json"));
  if (!report["interrupted"].asBool()) GTEST_SKIP() << "the run finished within two seconds; nothing to interrupt";
  EXPECT_EQ(run.exit_code, 0) << run.err;
  EXPECT_NE(run.err.find("interrupted after"), std::string::npos) << run.err;
  EXPECT_LT(report["frames"].asInt(), 150);
  EXPECT_EQ(io::readKittiPosesWithTimes(path("run/trajectory.txt")).size(), report["poses"].asUInt64());
  EXPECT_TRUE(std::filesystem::exists(path("run/mesh.ply")));
}

TEST_F(RunCommand, BadRequestsNameTheProblem) {
  test::RunResult run = rim("run " + path("missing") + " --out " + path("run"));
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("does not exist"), std::string::npos) << run.err;
  run = rim("run indoor_cart --frames 2 --voxel 0 --out " + path("run"));
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("voxel_size_m"), std::string::npos) << run.err;
  run = rim("run indoor_cart --environment underwater --out " + path("run"));
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("underwater"), std::string::npos) << run.err;
}

}  // namespace
}  // namespace range_image_mapping
