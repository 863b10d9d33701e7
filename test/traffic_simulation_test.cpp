// Moving actors in the simulator and the traffic scenario: deterministic per
// seed, exact (actor returns lie on the analytic boxes at their column's
// time), no actor in the ground-truth surface, and the trucks alongside really
// fill the view.
#include "range_image_mapping/io/actor_tracks.h"
#include "range_image_mapping/io/kitti.h"
#include "range_image_mapping/io/ply.h"
#include "range_image_mapping/io/png.h"
#include "range_image_mapping/simulation/lidar_simulator.h"
#include "range_image_mapping/simulation/sensor_presets.h"
#include "range_image_mapping/simulation/traffic.h"
#include "rim_command.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <cstring>
#include <fstream>
#include <iostream>
#include <map>

namespace range_image_mapping::simulation {
namespace {

LidarModelConstPtr os1Model() {
  const OusterMetadata metadata =
      parseOusterMetadata(ousterLikeMetadataJson("OS-1-128", UdpProfile::kRng19Rfl8Sig16Nir16));
  return std::make_shared<const LidarModel>(metadata.intrinsics);
}

// Signed distance from a point to a box surface in the box's frame (negative inside).
double boxSignedDistance(const Eigen::Vector3d& point, const ActorBox& box) {
  const Eigen::Vector3d outside = (point - box.centre_m).cwiseAbs() - box.half_size_m;
  return outside.cwiseMax(0.0).norm() + std::min(outside.maxCoeff(), 0.0);
}

double actorSurfaceDistance(const MovingActor& actor, double time_s, const Eigen::Vector3d& point_world) {
  const Eigen::Vector3d point = actor.worldFromActor(time_s).inverse() * point_world;
  double nearest = std::numeric_limits<double>::infinity();
  for (const ActorBox& box : actor.boxes) nearest = std::min(nearest, boxSignedDistance(point, box));
  return nearest;
}

TEST(SpeedProfile, SmoothStopAndGoWithExactDistances) {
  SpeedProfile profile(1.0, 5.0, 0.0);
  profile.hold(2.0).changeSpeed(6.0, 9.0).hold(2.0).changeSpeed(5.0, 0.0);
  EXPECT_DOUBLE_EQ(profile.distance(0.0), 5.0);
  EXPECT_DOUBLE_EQ(profile.distance(3.0), 5.0);
  EXPECT_NEAR(profile.distance(16.0), 5.0 + 27.0 + 18.0 + 22.5, 1e-9);  // mean speed is half the change
  EXPECT_NEAR(profile.distance(20.0), 72.5, 1e-9);                      // standing after the last phase
  EXPECT_DOUBLE_EQ(profile.speed(12.0), 0.0 + profile.speed(12.0));
  for (double t = 0.5; t < 17.0; t += 0.37) {  // speed and acceleration are the derivatives
    const double h = 1e-5;
    EXPECT_NEAR(profile.speed(t), (profile.distance(t + h) - profile.distance(t - h)) / (2 * h), 1e-6) << t;
    EXPECT_NEAR(profile.acceleration(t), (profile.speed(t + h) - profile.speed(t - h)) / (2 * h), 1e-5) << t;
    EXPECT_LE(std::abs(profile.acceleration(t)), 1.5 * 9.0 / 5.0 + 1e-9);
  }
  EXPECT_THROW(profile.changeSpeed(0.0, 1.0), std::invalid_argument);
}

TEST(MovingActors, RayBoxDistanceIsExact) {
  const ActorBox box{Eigen::Vector3d(5, 0, 1), Eigen::Vector3d(1, 2, 1)};
  int axis = -1;
  EXPECT_DOUBLE_EQ(rayBoxDistance(Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(1, 0, 0), box, 0, 100, &axis), 4.0);
  EXPECT_EQ(axis, 0);
  const Eigen::Vector3d diagonal = Eigen::Vector3d(4, 1, 0).normalized();
  EXPECT_NEAR(rayBoxDistance(Eigen::Vector3d(0, 0, 1), diagonal, box, 0, 100), std::sqrt(17.0), 1e-12);
  EXPECT_LT(rayBoxDistance(Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(1, 0, 0), box, 0, 3.9), 0.0);  // beyond far
  EXPECT_LT(rayBoxDistance(Eigen::Vector3d(0, 0, 3), Eigen::Vector3d(1, 0, 0), box, 0, 100), 0.0);  // above it
  EXPECT_LT(rayBoxDistance(Eigen::Vector3d(5, 0, 1), Eigen::Vector3d(1, 0, 0), box, 0, 100), 0.0);  // from inside

  // A moving actor: the snapshot at a time sees it where worldFromActor puts it.
  MovingActor actor;
  actor.boxes = {box};
  actor.start_m = Eigen::Vector3d(0, 10, 0);
  actor.heading_rad = -M_PI / 2;  // driving toward -y
  actor.motion = SpeedProfile(0.0, 0.0, 2.0);
  const std::vector<MovingActor> actors{actor};
  const ActorSnapshot snapshot(actors, 1.0);  // origin at (0, 8, 0), box centre at (0, 3, 1)
  const ActorHit hit = snapshot.intersect(Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0, 1, 0), 0, 100);
  EXPECT_EQ(hit.actor, 0);
  EXPECT_NEAR(hit.distance_m, 2.0, 1e-12);
  EXPECT_NEAR((hit.normal_world - Eigen::Vector3d(0, -1, 0)).norm(), 0.0, 1e-12);
}

TEST(TrafficScenario, SameSeedSameWorldAndNoActorEverOverlapsAnother) {
  TrafficOptions options;
  options.seed = 7;
  const TrafficScenario first = makeTrafficScenario(options);
  const TrafficScenario second = makeTrafficScenario(options);
  ASSERT_EQ(first.scene.mesh.vertices.size(), second.scene.mesh.vertices.size());
  EXPECT_TRUE(first.scene.mesh.vertices == second.scene.mesh.vertices);
  ASSERT_EQ(first.actors.size(), second.actors.size());
  std::map<ActorKind, int> kinds;
  for (std::size_t k = 0; k < first.actors.size(); ++k) {
    EXPECT_EQ(first.actors[k].name, second.actors[k].name);
    ++kinds[first.actors[k].kind];
    for (const double t : {0.0, 9.3, 17.0, 33.3})
      EXPECT_TRUE(first.actors[k].worldFromActor(t).isApprox(second.actors[k].worldFromActor(t), 0.0));
  }
  EXPECT_GE(kinds[ActorKind::kTruck], 3);       // two alongside, one crossing
  EXPECT_GE(kinds[ActorKind::kCar], 5);         // ahead, behind, crossing, oncoming
  EXPECT_GE(kinds[ActorKind::kPedestrian], 4);  // crossing and walking
  EXPECT_FALSE(makeTrafficScenario(TrafficOptions{8}).scene.mesh.vertices == first.scene.mesh.vertices);

  // Finer than the check the scenario ran, with no gap.
  for (std::size_t a = 0; a < first.actors.size(); ++a) {
    EXPECT_FALSE(actorsOverlap(first.actors[a], first.ego_body, 0.0, 40.0, 0.01, 0.0)) << first.actors[a].name;
    for (std::size_t b = a + 1; b < first.actors.size(); ++b)
      EXPECT_FALSE(actorsOverlap(first.actors[a], first.actors[b], 0.0, 40.0, 0.01, 0.0))
          << first.actors[a].name << " " << first.actors[b].name;
  }
  // The ego stops and goes: standing at the start and at both stops, 8-10 m/s between.
  const Eigen::Vector3d stop = first.ego->pose(17.0).translation();
  EXPECT_NEAR(stop.x(), first.layout.first_stop_x, 1e-9);
  EXPECT_NEAR((first.ego->pose(19.0).translation() - stop).norm(), 0.0, 1e-12);
  EXPECT_NEAR(first.ego->pose(10.0).translation().x() - first.ego->pose(9.9).translation().x(), 0.9, 0.05);
}

// Simulated scans of the traffic scenario at a few instants: moving,
// standing while traffic crosses, standing at the second stop.
class TrafficScans : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scenario_ = new TrafficScenario(makeTrafficScenario(TrafficOptions{}));
    caster_ = new RayCaster(scenario_->scene.mesh);
  }
  static void TearDownTestSuite() {
    delete caster_;
    delete scenario_;
  }
  static SensorEffects effects() {
    SensorEffects effects;
    effects.range_noise_sigma_m = 0.01;
    return effects;
  }
  static TrafficScenario* scenario_;
  static RayCaster* caster_;
};
TrafficScenario* TrafficScans::scenario_ = nullptr;
RayCaster* TrafficScans::caster_ = nullptr;

TEST_F(TrafficScans, SameSeedGivesIdenticalScans) {
  LidarSimulator first(os1Model(), *caster_, effects(), 5);
  LidarSimulator second(os1Model(), *caster_, effects(), 5);
  first.setActors(&scenario_->actors);
  second.setActors(&scenario_->actors);
  for (const double start : {8.0, 16.5}) {
    const SimulatedScan a = first.simulate(*scenario_->ego, start, 3);
    const SimulatedScan b = second.simulate(*scenario_->ego, start, 3);
    EXPECT_TRUE(a.raw.range == b.raw.range);
    EXPECT_TRUE(a.raw.reflectivity == b.raw.reflectivity);
    EXPECT_TRUE(a.true_actor == b.true_actor);
    EXPECT_GT(std::count_if(a.true_actor.begin(), a.true_actor.end(), [](uint16_t l) { return l > 0; }), 1000);
  }
  // Without actors the simulator is the one it always was, pixel for pixel.
  LidarSimulator plain(os1Model(), *caster_, effects(), 5);
  LidarSimulator emptied(os1Model(), *caster_, effects(), 5);
  const std::vector<MovingActor> none;
  emptied.setActors(&none);
  const SimulatedScan p = plain.simulate(*scenario_->ego, 8.0, 3), e = emptied.simulate(*scenario_->ego, 8.0, 3);
  EXPECT_TRUE(p.raw.range == e.raw.range);
  EXPECT_TRUE(std::all_of(e.true_actor.begin(), e.true_actor.end(), [](uint16_t l) { return l == 0; }));
}

// Every labelled pixel's noise-free return lies on its actor's boxes posed at
// the column's time (a pose a scan earlier or later would be metres off); the
// measured range is within the noise of it; unlabelled returns are on no actor.
TEST_F(TrafficScans, ActorReturnsLieOnTheActorAtTheirColumnTime) {
  LidarSimulator simulator(os1Model(), *caster_, effects(), 5);
  simulator.setActors(&scenario_->actors);
  const LidarModel& model = *simulator.model();
  for (const double start : {8.0, 16.5, 30.0}) {
    SCOPED_TRACE(start);
    const SimulatedScan scan = simulator.simulate(*scenario_->ego, start, 1);
    std::size_t labelled = 0, static_returns = 0;
    double worst = 0.0, worst_noise = 0.0;
    for (int v = 0; v < model.rows(); ++v)
      for (int u = 0; u < model.columns(); ++u) {
        const std::size_t pixel = static_cast<std::size_t>(v) * model.columns() + u;
        const float range = scan.true_range[pixel];
        if (!std::isfinite(range)) continue;
        const Eigen::Vector3d point = scan.column_poses[u] * model.unproject(u, v, range).cast<double>();
        const double time = simulator.columnTime(start, u);
        const uint16_t label = scan.true_actor[pixel];
        if (label == 0) {
          ++static_returns;
          if (static_returns % 7 == 0)  // a sample: none inside or on an actor
            for (const MovingActor& actor : scenario_->actors)
              ASSERT_GT(actorSurfaceDistance(actor, time, point), 1e-3) << actor.name << " pixel " << v << "," << u;
          continue;
        }
        ++labelled;
        const MovingActor& actor = scenario_->actors.at(label - 1);
        worst = std::max(worst, std::abs(actorSurfaceDistance(actor, time, point)));
        if (scan.raw.range[pixel] > 0)
          worst_noise = std::max(worst_noise, std::abs(scan.raw.range[pixel] * 1e-3 - range));
      }
    EXPECT_GT(labelled, 2000u);
    EXPECT_LT(worst, 2e-3) << "metres off the actor's surface";
    EXPECT_LT(worst_noise, 6 * 0.01 + 5e-4);
  }
}

// The point of the scenario: the trucks alongside fill much of the view, in
// every phase of the drive.
TEST_F(TrafficScans, TheTrucksAlongsideFillMuchOfTheView) {
  LidarSimulator simulator(os1Model(), *caster_, SensorEffects{}, 5);
  simulator.setActors(&scenario_->actors);
  int trucks[2] = {-1, -1};
  for (std::size_t k = 0; k < scenario_->actors.size(); ++k) {
    if (scenario_->actors[k].name == "truck_left") trucks[0] = static_cast<int>(k + 1);
    if (scenario_->actors[k].name == "truck_right") trucks[1] = static_cast<int>(k + 1);
  }
  double lowest = 1.0, sum = 0.0;
  int scans = 0;
  for (double start = 1.0; start < 31.0; start += 2.0) {
    const SimulatedScan scan = simulator.simulate(*scenario_->ego, start, 0);
    std::size_t returns = 0, on_trucks = 0;
    for (std::size_t pixel = 0; pixel < scan.true_actor.size(); ++pixel) {
      if (!std::isfinite(scan.true_range[pixel])) continue;
      ++returns;
      on_trucks += scan.true_actor[pixel] == trucks[0] || scan.true_actor[pixel] == trucks[1];
    }
    const double share = double(on_trucks) / returns;
    lowest = std::min(lowest, share);
    sum += share;
    ++scans;
  }
  std::cout << "[ figures  ] share of the returns on the two trucks alongside: mean " << sum / scans
            << ", lowest " << lowest << " over " << scans << " scans\n";
  EXPECT_GT(sum / scans, 0.35);
  EXPECT_GT(lowest, 0.2);
}

// rim simulate --preset traffic end to end: actors.txt and labels written and
// consistent with the scans; no ground-truth surface sample on an actor.
using TrafficPreset = test::RimCommandTest;

TEST_F(TrafficPreset, WritesTracksAndLabelsAndKeepsActorsOutOfTheSurface) {
  const auto started = std::chrono::steady_clock::now();
  const test::RunResult result = rim("simulate --preset traffic_hdl64 --frames 6 --out '" + path("seq") + "'");
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  ASSERT_EQ(result.exit_code, 0) << result.err;
  std::cout << "[ figures  ] rim simulate --preset traffic_hdl64, 6 frames: " << seconds << " s; " << result.out;
  const std::vector<io::ActorTrack> tracks = io::readActorTracks(path("seq/actors.txt"));
  ASSERT_GE(tracks.size(), 10u);
  for (const io::ActorTrack& track : tracks) ASSERT_EQ(track.times_s.size(), 6u) << track.name;

  // Labels: one uint32 per point of the .bin, naming actors that exist.
  for (int frame = 0; frame < 6; ++frame) {
    char name[32];
    std::snprintf(name, sizeof name, "%06d", frame);
    const PointCloudInput cloud = io::readKittiVelodyne(path("seq/velodyne/") + name + ".bin");
    const std::string labels = test::readText(path("seq/labels/") + name + ".label");
    ASSERT_EQ(labels.size(), cloud.points.size() * 4);
    const io::GreyPng image = io::readGreyPng(path("seq/labels/") + name + ".png");
    EXPECT_EQ(image.width, 2048);
    EXPECT_EQ(image.height, 64);
    std::size_t on_actors = 0;
    for (std::size_t i = 0; i < cloud.points.size(); ++i) {
      uint32_t label;
      std::memcpy(&label, labels.data() + 4 * i, 4);
      ASSERT_LE(label, tracks.size());
      on_actors += label > 0;
    }
    EXPECT_GT(on_actors, cloud.points.size() / 5);
  }

  // Surface samples: none within 5 mm of an actor box at any scan's time
  // (the sidewalk is 1 cm below a pedestrian's feet, the road 5 cm below a truck's wheels).
  const std::vector<Eigen::Vector3f> surface = io::readPlyPoints(path("seq/surface.ply"));
  ASSERT_GT(surface.size(), 10000u);
  std::size_t near_actor_path = 0;
  for (const io::ActorTrack& track : tracks)
    for (std::size_t f = 0; f < track.times_s.size(); ++f) {
      const Eigen::Isometry3d actor_from_world = track.world_from_actor[f].inverse();
      for (const Eigen::Vector3f& sample : surface) {
        const Eigen::Vector3d point = actor_from_world * sample.cast<double>();
        for (const io::ActorTrackBox& box : track.boxes) {
          const Eigen::Vector3d outside = (point - box.centre_m).cwiseAbs() - box.half_size_m;
          ASSERT_GT(outside.maxCoeff(), 5e-3) << track.name << " at " << sample.transpose();
          near_actor_path += outside.x() < 0 && outside.y() < 0;  // under or over an actor
        }
      }
    }
  EXPECT_GT(near_actor_path, 0u);  // the road under the actors is there, and was checked
}

TEST_F(TrafficPreset, NoActorsAndBadCombinationsAreNamed) {
  test::RunResult result = rim("simulate --preset traffic --frames 2 --no-actors --out '" + path("plain") + "'");
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_FALSE(std::filesystem::exists(path("plain/actors.txt")));
  EXPECT_TRUE(std::filesystem::exists(path("plain/capture.pcap")));
  result = rim("simulate --sensor hdl64 --scene outdoor --motion traffic --frames 1 --out '" + path("bad") + "'");
  EXPECT_NE(result.exit_code, 0);
  EXPECT_NE(result.err.find("give --scene traffic"), std::string::npos) << result.err;
}

}  // namespace
}  // namespace range_image_mapping::simulation
