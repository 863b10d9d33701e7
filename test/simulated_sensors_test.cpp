// Issue 14's simulated drivers' sensors: rim run over an outdoor drive seen by
// a VLP-16, VLP-32C, HDL-32E and Pandar64 (the catalog's beam tables, with
// their uneven beams and per-beam azimuth offsets), written as a folder of
// plain PCD clouds (x, y, z, intensity, relative time; no ring) and read with
// no sensor option, so the model is the one rim estimates from the clouds.
// Targets of the Ouster presets:
//   KITTI RPE <= 0.8 % and <= 0.3 deg/100 m, mesh F >= 0.95 at 3 x 10 cm.
#include "json_file.h"
#include "rim_command.h"

#include <gtest/gtest.h>
#include <json/json.h>

#include <iostream>
#include <sstream>

namespace range_image_mapping {
namespace {

struct SimulatedSensor {
  const char* preset;
  const char* sensor;
  // Empty: the sensor meets every target. Otherwise what keeps it from them
  // (measured; see the README): the run must still succeed, and is reported
  // as skipped with its figures, so the miss stays visible; it fails once the
  // sensor meets them, to have this note removed.
  const char* known_miss = "";
  // 0: the preset's own drive (rim run PRESET). Otherwise another drive of
  // the preset (scene, motion and noise from this seed), simulated first,
  // so that the targets are checked on more than one route.
  unsigned seed = 0;
};

class SimulatedSensors : public test::RimCommandTest, public ::testing::WithParamInterface<SimulatedSensor> {};

// 20 s of the car preset: 145 m, four of KITTI's 100 m RPE segments.
constexpr int kFrames = 200;

TEST_P(SimulatedSensors, OutdoorDriveMeetsTheOusterPresetsTargetsWithAnEstimatedModel) {
  const SimulatedSensor& sensor = GetParam();
  const std::string out = path("run");
  std::string input = sensor.preset;
  if (sensor.seed) {
    // As rim run simulates a preset: the ground-truth surface clipped at the
    // outdoor map's 30 m range.
    input = path("sequence");
    const test::RunResult simulated = rim(std::string("simulate --preset ") + sensor.preset + " --seed " +
                                          std::to_string(sensor.seed) + " --frames " + std::to_string(kFrames) +
                                          " --surface-max-range 30 --out " + input);
    ASSERT_EQ(simulated.exit_code, 0) << simulated.err;
  }
  const test::RunResult run =
      rim("run " + input + " --frames " + std::to_string(kFrames) + " --no-plot --out " + out);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  std::cout << sensor.sensor << ":\n" << run.out;
  // Read as plain clouds: the model is estimated, not the catalog's.
  EXPECT_NE(run.err.find("sensor model estimated from the first"), std::string::npos) << run.err;
  EXPECT_EQ(run.err.find("warning: the sensor model"), std::string::npos) << run.err;
  const Json::Value report = test::readJsonFile(out + "/report.json");
  EXPECT_EQ(report["odometry"]["resets"].asInt(), 0);
  // A sparse sensor's stride-4 level may be passed over (a VLP-16's has four
  // rows), never the whole pyramid: stride 2 must still capture the motion.
  ASSERT_TRUE(report["odometry"].isMember("scans_with_every_coarse_level_passed_over"));
  EXPECT_EQ(report["odometry"]["scans_with_every_coarse_level_passed_over"].asInt(), 0);
  std::cout << sensor.sensor << ": a coarse level passed over in "
            << report["odometry"]["scans_with_coarse_levels_passed_over"].asInt() << " scans\n";
  EXPECT_EQ(report["mapping"]["scans_refused"].asInt(), 0);
  const Json::Value& truth = report["ground_truth"];
  ASSERT_TRUE(truth.isMember("rpe_translation_percent")) << sensor.sensor << ": the run is shorter than 100 m";
  const double rpe_percent = truth["rpe_translation_percent"].asDouble();
  const double rpe_deg = truth["rpe_rotation_deg_per_100m"].asDouble();
  const double f_score = truth["surface"]["f_score"].asDouble();
  std::ostringstream figures;
  figures << sensor.sensor << (sensor.seed ? " (seed " + std::to_string(sensor.seed) + ")" : std::string())
          << ": RPE " << rpe_percent << " %, " << rpe_deg << " deg/100 m, mesh F " << f_score;
  std::cout << figures.str() << "\n";
  const bool meets = rpe_percent <= 0.8 && rpe_deg <= 0.3 && f_score >= 0.95;
  if (*sensor.known_miss) {
    ASSERT_FALSE(meets) << figures.str() << ": now meets the targets; remove its known miss";
    GTEST_SKIP() << "TARGET NOT MET (issue 14): " << figures.str()
                 << " against RPE <= 0.8 %, <= 0.3 deg/100 m, F >= 0.95; " << sensor.known_miss;
  }
  EXPECT_LE(rpe_percent, 0.8) << sensor.sensor;
  EXPECT_LE(rpe_deg, 0.3) << sensor.sensor;
  EXPECT_GE(f_score, 0.95) << sensor.sensor;
}

INSTANTIATE_TEST_SUITE_P(Catalog, SimulatedSensors,
                         ::testing::Values(SimulatedSensor{"outdoor_vlp16", "VLP-16"},
                                           SimulatedSensor{"outdoor_vlp32c", "VLP-32C"},
                                           SimulatedSensor{"outdoor_hdl32", "HDL-32E"},
                                           SimulatedSensor{"outdoor_pandar64", "Pandar64"},
                                           SimulatedSensor{"outdoor_vlp16", "VLP-16", "", 7},
                                           SimulatedSensor{"outdoor_hdl32", "HDL-32E", "", 3}),
                         [](const ::testing::TestParamInfo<SimulatedSensor>& info) {
                           return std::string(info.param.preset) +
                                  (info.param.seed ? "_seed" + std::to_string(info.param.seed) : std::string());
                         });

}  // namespace
}  // namespace range_image_mapping
