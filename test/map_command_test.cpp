// rim map end to end: a simulated indoor sequence mapped at its ground-truth
// poses matches the simulator's surface, a fast handheld one needs the
// deskew, the real lb_n3 frames at their reference poses land on Ouster's
// reference map, and bad requests fail with a named error and no mesh.
#include "range_image_mapping/evaluation/surface_metrics.h"
#include "range_image_mapping/io/ply.h"
#include "range_image_mapping/io/pose_file.h"
#include "rim_command.h"
#include "test_data.h"

#include <gtest/gtest.h>
#include <json/json.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

namespace range_image_mapping {
namespace {

using MapCommand = test::RimCommandTest;

Json::Value readJson(const std::string& path) {
  std::istringstream text(test::readText(path));
  Json::Value root;
  std::string errors;
  EXPECT_TRUE(Json::parseFromStream(Json::CharReaderBuilder(), text, &root, &errors)) << path << ": " << errors;
  return root;
}

double fScoreOf(const Json::Value& report) { return report["evaluation"]["f_score"].asDouble(); }

TEST_F(MapCommand, IndoorCartAtGroundTruthPosesMatchesTheSimulatedSurface) {
  ASSERT_EQ(rim("simulate --preset indoor_cart --frames 30 --out " + path("ic")).exit_code, 0);
  // --poses defaults to the folder's ground truth.
  const test::RunResult run = rim("map " + path("ic") + " --voxel 0.04 --out " + path("ic/mesh.ply") + " --eval " +
                                  path("ic/surface.ply") + " --json " + path("ic/report.json"));
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_NE(run.err.find("30/30 frames"), std::string::npos) << run.err;  // the progress bar
  std::printf("%s", run.out.c_str());
  const Json::Value report = readJson(path("ic/report.json"));
  EXPECT_EQ(report["scans_integrated"].asInt(), 30);
  EXPECT_EQ(report["scans_refused"].asInt(), 0);
  EXPECT_EQ(report["poses_frame"].asString(), "lidar");
  const double f_score = fScoreOf(report);
  std::printf("indoor_cart 30 frames at 4 cm: precision %.4f recall %.4f F %.4f; integrate %.1f ms/scan\n",
              report["evaluation"]["precision"].asDouble(),
              report["evaluation"]["recall"].asDouble(), f_score,
              report["timing"]["integrate_ms_per_scan_mean"].asDouble());
  // Measured 0.984 (precision 0.990, recall 0.977; the surface is what these
  // 30 frames saw). The issue asks 0.95 of a full run; 0.97 leaves room for
  // integrator changes while a wrong pose frame or a missing deskew (F 0.21 on
  // lb_n3, 0.66 handheld, measured below) cannot pass.
  EXPECT_GT(f_score, 0.97);

  const TriangleMesh mesh = io::readPlyMesh(path("ic/mesh.ply"));
  EXPECT_EQ(mesh.vertices.size(), report["vertices"].asUInt64());
  EXPECT_EQ(mesh.triangles.size(), report["triangles"].asUInt64());
  EXPECT_GT(mesh.triangles.size(), 10000u);

  // The same motion given as Ouster sensor poses (the sidecar says os_sensor)
  // is converted back to the lidar frame: the same map.
  const test::RunResult sensor = rim("map " + path("ic") + " --frames 5 --voxel 0.04 --poses " +
                                     path("ic/poses_sensor_kitti.txt") + " --out " + path("ic/sensor.ply") +
                                     " --json " + path("ic/sensor.json"));
  ASSERT_EQ(sensor.exit_code, 0) << sensor.err;
  const test::RunResult lidar = rim("map " + path("ic") + " --frames 5 --voxel 0.04 --out " + path("ic/lidar.ply") +
                                    " --json " + path("ic/lidar.json"));
  ASSERT_EQ(lidar.exit_code, 0) << lidar.err;
  const Json::Value sensor_report = readJson(path("ic/sensor.json")), lidar_report = readJson(path("ic/lidar.json"));
  EXPECT_EQ(sensor_report["poses_frame"].asString(), "sensor");
  EXPECT_EQ(sensor_report["scans_integrated"].asInt(), 5);
  EXPECT_NEAR(sensor_report["triangles"].asDouble(), lidar_report["triangles"].asDouble(),
              1e-3 * lidar_report["triangles"].asDouble());

  // A memory radius drops blocks behind the cart; their mesh is kept, so the
  // written mesh is the unbounded one but for seams at the archived blocks.
  const std::string bounded = "map " + path("ic") + " --frames 15 --voxel 0.04 --max-range 8 --eval " +
                              path("ic/surface.ply");
  ASSERT_EQ(rim(bounded + " --out " + path("ic/all.ply") + " --json " + path("ic/all.json")).exit_code, 0);
  const test::RunResult radius = rim(bounded + " --memory-radius 9 --out " + path("ic/radius.ply") + " --json " +
                                     path("ic/radius.json"));
  ASSERT_EQ(radius.exit_code, 0) << radius.err;
  const Json::Value all = readJson(path("ic/all.json")), kept = readJson(path("ic/radius.json"));
  std::printf("memory radius 9 m: %d blocks dropped, %d of %d blocks kept, F %.4f (unbounded %.4f)\n",
              kept["blocks_dropped"].asInt(), kept["blocks"].asInt(), all["blocks"].asInt(), fScoreOf(kept),
              fScoreOf(all));
  EXPECT_GT(kept["blocks_dropped"].asInt(), 0);
  EXPECT_LT(kept["blocks"].asInt(), all["blocks"].asInt());
  EXPECT_NEAR(kept["triangles"].asDouble(), all["triangles"].asDouble(), 0.01 * all["triangles"].asDouble());
  EXPECT_NEAR(fScoreOf(kept), fScoreOf(all), 0.002);
}

TEST_F(MapCommand, DeskewSharpensAFastHandheldSweep) {
  ASSERT_EQ(rim("simulate --preset handheld_fast --frames 12 --noise 0 --out " + path("hh")).exit_code, 0);
  const std::string common = "map " + path("hh") + " --voxel 0.04 --eval " + path("hh/surface.ply");
  const test::RunResult deskewed = rim(common + " --out " + path("hh/a.ply") + " --json " + path("hh/a.json"));
  ASSERT_EQ(deskewed.exit_code, 0) << deskewed.err;
  const test::RunResult raw =
      rim(common + " --no-deskew --out " + path("hh/b.ply") + " --json " + path("hh/b.json"));
  ASSERT_EQ(raw.exit_code, 0) << raw.err;
  const Json::Value a = readJson(path("hh/a.json")), b = readJson(path("hh/b.json"));
  const double precision_deskewed = a["evaluation"]["precision"].asDouble();
  const double precision_raw = b["evaluation"]["precision"].asDouble();
  std::printf("handheld_fast 12 frames at 4 cm: precision %.4f deskewed, %.4f as measured; F %.4f / %.4f\n",
              precision_deskewed, precision_raw, fScoreOf(a), fScoreOf(b));
  // Measured 0.978 and 0.547: the twist from the poses undoes a 180 deg/s
  // sweep. (The ground truth is the surface within 2 cm of a noise-free hit,
  // so mesh spanning the gaps between far hits counts against precision.)
  EXPECT_GT(precision_deskewed, 0.96);
  EXPECT_LT(precision_raw, precision_deskewed - 0.1);
  EXPECT_GT(fScoreOf(a), fScoreOf(b));
}

TEST_F(MapCommand, RealLbN3FramesLandOnTheReferenceMap) {
  RIM_REQUIRE_DATA(pcap, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3.pcap");
  RIM_REQUIRE_DATA(metadata, "ouster-pcaps/OS-1-128_v2.3.0_1024x10.json");
  RIM_REQUIRE_DATA(poses, "ouster-pcaps/OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt");
  RIM_REQUIRE_DATA(reference_path, "ouster-extra/OS-1-128_v2.3.0_1024x10_lb_n3_map-000.ply");
  // The reference poses are of the Ouster sensor frame and have no times file.
  const test::RunResult run = rim("map " + pcap + " --metadata " + metadata + " --poses " + poses +
                                  " --poses-frame sensor --voxel 0.1 --out " + path("lb.ply") + " --json " +
                                  path("lb.json"));
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const Json::Value report = readJson(path("lb.json"));
  EXPECT_EQ(report["scans_integrated"].asInt(), 3);
  const TriangleMesh mesh = io::readPlyMesh(path("lb.ply"));
  ASSERT_GT(mesh.vertices.size(), 1000u);
  const std::vector<float> distances =
      evaluation::nearestDistances(mesh.vertices, io::readPlyPoints(reference_path));
  const double within = double(std::count_if(distances.begin(), distances.end(), [](float d) { return d < 0.3f; })) /
                        double(distances.size());
  std::printf("lb_n3 at 10 cm: %zu vertices, %.2f %% within 30 cm of the reference map; integrate %.1f ms/scan\n",
              mesh.vertices.size(), 100.0 * within, report["timing"]["integrate_ms_per_scan_mean"].asDouble());
  EXPECT_GE(within, 0.90);  // measured 98.1 %; with lidar-frame poses (no conversion) about 20 %
}

// A failed run leaves neither the mesh nor a partial file behind.
bool noMeshIn(const std::filesystem::path& directory) {
  for (const auto& entry : std::filesystem::directory_iterator(directory))
    if (entry.path().extension() == ".ply") return false;
  return true;
}

TEST_F(MapCommand, BadRequestsNameTheProblemAndWriteNoMesh) {
  ASSERT_EQ(rim("simulate --preset indoor_cart --frames 3 --out " + path("ic")).exit_code, 0);
  const auto truth = io::readKittiPosesWithTimes(path("ic/poses_kitti.txt"));
  ASSERT_EQ(truth.size(), 3u);
  std::filesystem::create_directories(path("out"));
  const std::string out = " --out " + path("out/mesh.ply");

  // Two poses for three scans: told before any work from a folder ...
  io::writeTumPoses(path("two.txt"), {truth[0], truth[1]});
  test::RunResult run = rim("map " + path("ic") + " --poses " + path("two.txt") + out);
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("pose count mismatch"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("2 poses"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("3 scans"), std::string::npos) << run.err;
  // ... and after reading from a pcap, whose scan count is unknown up front.
  run = rim("map " + path("ic/capture.pcap") + " --metadata " + path("ic/metadata.json") + " --poses " +
            path("two.txt") + out);
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("2 poses"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("3 scans"), std::string::npos) << run.err;
  // Four poses for three scans.
  io::writeTumPoses(path("four.txt"), {truth[0], truth[1], truth[2], truth[2]});
  run = rim("map " + path("ic") + " --poses " + path("four.txt") + out);
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("4 poses"), std::string::npos) << run.err;
  // ... which --frames may leave over.
  run = rim("map " + path("ic") + " --frames 2 --poses " + path("four.txt") + " --out " + path("two_frames.ply"));
  EXPECT_EQ(run.exit_code, 0) << run.err;
  EXPECT_TRUE(std::filesystem::exists(path("two_frames.ply")));

  // A NaN in the pose file: named with its line.
  std::string text = test::readText(path("ic/poses_tum.txt"));
  const std::size_t last_line = text.rfind('\n', text.size() - 2) + 1;
  const std::size_t x_begin = text.find(' ', last_line) + 1;
  text.replace(x_begin, text.find(' ', x_begin) - x_begin, "nan");  // tx of the last pose
  std::ofstream(path("nan.txt")) << text;
  run = rim("map " + path("ic") + " --poses " + path("nan.txt") + out);
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("nan.txt line"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("finite"), std::string::npos) << run.err;

  const struct {
    const char* arguments;
    const char* message;
  } cases[] = {
      {" --voxel 0", "voxel"},
      {" --block-edge 12", "block"},
      {" --max-range 0.2", "range"},
      {" --poses /nonexistent/poses.txt", "does not exist"},
      {" --kitti", "no KITTI scans"},
  };
  for (const auto& c : cases) {
    run = rim("map " + path("ic") + c.arguments + out);
    EXPECT_NE(run.exit_code, 0) << c.arguments;
    EXPECT_NE(run.err.find(c.message), std::string::npos) << c.arguments << "\n" << run.err;
  }
  // Without --poses, only a rim simulate folder has poses to use.
  run = rim("map " + path("ic/capture.pcap") + " --metadata " + path("ic/metadata.json") + out);
  EXPECT_NE(run.exit_code, 0);
  EXPECT_NE(run.err.find("give --poses"), std::string::npos) << run.err;
  EXPECT_TRUE(noMeshIn(path("out")));
}

}  // namespace
}  // namespace range_image_mapping
