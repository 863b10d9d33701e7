// rim run over every simulated preset, full length, against the targets of
// the registration and mapping issues: the regression guard for the whole
// offline pipeline (simulate, odometry, TSDF, meshing, evaluation).
//   outdoor_car, kitti_like: KITTI RPE <= 0.8 % and <= 0.3 deg/100 m
//   indoor_cart: ATE <= 5 cm; mesh F >= 0.95 at 3 x 4 cm
//   outdoor_car: mesh F >= 0.93 at 3 x 10 cm
//   handheld_fast (150 deg/s): no frame diverges
#include "json_file.h"
#include "rim_command.h"

#include <gtest/gtest.h>
#include <json/json.h>

#include <iostream>
#include <sstream>

namespace range_image_mapping {
namespace {

class PresetAccuracy : public test::RimCommandTest {
 protected:
  Json::Value runPreset(const std::string& preset, const std::string& out) const;
};

Json::Value PresetAccuracy::runPreset(const std::string& preset, const std::string& out) const {
  const test::RunResult run = rim("run " + preset + " --no-plot --out " + out);
  EXPECT_EQ(run.exit_code, 0) << run.err;
  std::cout << preset << ":\n" << run.out;
  const Json::Value report = test::readJsonFile(out + "/report.json");
  EXPECT_EQ(report["odometry"]["resets"].asInt(), 0);
  EXPECT_EQ(report["mapping"]["scans_refused"].asInt(), 0);
  return report;
}

TEST_F(PresetAccuracy, OutdoorCar) {
  const Json::Value report = runPreset("outdoor_car", path("outdoor_car"));
  const Json::Value& truth = report["ground_truth"];
  ASSERT_TRUE(truth.isMember("rpe_translation_percent")) << "the run is shorter than 100 m";
  EXPECT_LE(truth["rpe_translation_percent"].asDouble(), 0.8);
  EXPECT_LE(truth["rpe_rotation_deg_per_100m"].asDouble(), 0.3);
  EXPECT_GE(truth["surface"]["f_score"].asDouble(), 0.93);
}

TEST_F(PresetAccuracy, KittiLike) {
  const Json::Value report = runPreset("kitti_like", path("kitti_like"));
  const Json::Value& truth = report["ground_truth"];
  ASSERT_TRUE(truth.isMember("rpe_translation_percent")) << "the run is shorter than 100 m";
  EXPECT_LE(truth["rpe_translation_percent"].asDouble(), 0.8);
  EXPECT_LE(truth["rpe_rotation_deg_per_100m"].asDouble(), 0.3);
}

TEST_F(PresetAccuracy, IndoorCart) {
  const Json::Value report = runPreset("indoor_cart", path("indoor_cart"));
  EXPECT_LE(report["ground_truth"]["ate_rmse_m"].asDouble(), 0.05);
  EXPECT_GE(report["ground_truth"]["surface"]["f_score"].asDouble(), 0.95);
}

TEST_F(PresetAccuracy, HandheldFast) {
  const Json::Value report = runPreset("handheld_fast", path("handheld_fast"));
  // Measured 1.9 cm; a diverged frame throws the ATE to metres.
  EXPECT_LE(report["ground_truth"]["ate_max_m"].asDouble(), 0.10);
  EXPECT_EQ(report["odometry"]["degenerate"].asInt(), 0);
}

}  // namespace
}  // namespace range_image_mapping
