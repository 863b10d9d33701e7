// Moving actors' tracks on disk (io::writeActorTracks / readActorTracks) and
// what a map keeps of them (evaluation::measureActorTrail).
#include "range_image_mapping/evaluation/actor_trail.h"
#include "range_image_mapping/io/actor_tracks.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <unistd.h>

namespace range_image_mapping::evaluation {
namespace {

io::ActorTrack truckTrack() {
  io::ActorTrack track;
  track.label = 3;
  track.kind = "truck";
  track.name = "truck_left";
  track.boxes.push_back({Eigen::Vector3d(0, 0, 2.5), Eigen::Vector3d(5, 1.25, 1.5)});  // z 1 .. 4
  for (int f = 0; f < 4; ++f) {
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() = Eigen::Vector3d(f < 2 ? 0.0 : 2.0 * (f - 1), 3.0, 0.0);  // stands, then drives
    pose.linear() = Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    track.times_s.push_back(1.0 + 0.1 * f);
    track.world_from_actor.push_back(pose);
  }
  return track;
}

std::string temporaryPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / (name + std::to_string(getpid()))).string();
}

TEST(ActorTracks, RoundTripAndMalformedFilesAreNamed) {
  const std::string path = temporaryPath("actors.txt");
  io::ActorTrack pedestrian;
  pedestrian.label = 1;
  pedestrian.kind = "pedestrian";
  pedestrian.name = "walker_1";
  pedestrian.boxes.push_back({Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(0.2, 0.25, 0.85)});
  pedestrian.times_s = {1.0};
  pedestrian.world_from_actor = {Eigen::Isometry3d::Identity()};
  io::writeActorTracks(path, {pedestrian, truckTrack()}, "test");
  const std::vector<io::ActorTrack> read = io::readActorTracks(path);
  ASSERT_EQ(read.size(), 2u);
  EXPECT_EQ(read[1].label, 3);
  EXPECT_EQ(read[1].kind, "truck");
  EXPECT_EQ(read[1].name, "truck_left");
  ASSERT_EQ(read[1].world_from_actor.size(), 4u);
  EXPECT_TRUE(read[1].world_from_actor[3].isApprox(truckTrack().world_from_actor[3], 1e-8));
  EXPECT_TRUE(read[1].boxes[0].half_size_m.isApprox(Eigen::Vector3d(5, 1.25, 1.5)));

  for (const char* bad : {"box 0 0 0 1 1 1\n", "actor 0 car a\n", "actor 1 car a\nbox 0 0 0 1 1\n",
                          "actor 1 car a\npose 1 0 0 0 0 0 0 2\n", "actor 1 car a\nactor 1 car b\n",
                          "actor 1 car a\nwheel 1\n"}) {
    std::ofstream(path) << bad;
    EXPECT_THROW(io::readActorTracks(path), io::ActorTracksError) << bad;
  }
  std::filesystem::remove(path);
}

TEST(ActorTrail, CountsWhatLiesInsideTheSweptBoxesButNotTheGroundUnderThem) {
  const std::vector<io::ActorTrack> tracks{truckTrack()};
  const Eigen::Isometry3d first = tracks[0].world_from_actor[0], last = tracks[0].world_from_actor[3];
  std::vector<Eigen::Vector3f> points{
      (first * Eigen::Vector3d(4.9, 0, 3)).cast<float>(),     // inside, standing
      (last * Eigen::Vector3d(4.9, 1.3, 3.9)).cast<float>(),  // inside the margin, driving
      (last * Eigen::Vector3d(0, 0, 0.0)).cast<float>(),      // the road under it
      (last * Eigen::Vector3d(0, 0, 1.05)).cast<float>(),     // below the raised bottom
      (last * Eigen::Vector3d(5.3, 0, 2)).cast<float>(),      // ahead of it, beyond the margin
      Eigen::Vector3f(50, 50, 2)};
  ActorTrail trail = measureActorTrail(points, tracks);
  EXPECT_EQ(trail.points, 6u);
  EXPECT_EQ(trail.points_inside, 2u);
  EXPECT_DOUBLE_EQ(trail.share, 2.0 / 6.0);
  ASSERT_EQ(trail.by_kind.size(), 1u);
  EXPECT_EQ(trail.by_kind[0].kind, "truck");
  EXPECT_EQ(trail.by_kind[0].points_inside, 2u);
  // Between the tracked poses (the truck drove 2 m per scan): the union of boxes covers it.
  points = {(Eigen::Translation3d(3.0, 0, 0) * first * Eigen::Vector3d(0, 0, 2)).cast<float>()};
  EXPECT_EQ(measureActorTrail(points, tracks).points_inside, 1u);
  ActorTrailOptions exact;
  exact.margin_m = 0.0;
  points = {(last * Eigen::Vector3d(4.9, 1.3, 3.9)).cast<float>()};
  EXPECT_EQ(measureActorTrail(points, tracks, exact).points_inside, 0u);
  exact.margin_m = -1.0;
  EXPECT_THROW(measureActorTrail(points, tracks, exact), std::invalid_argument);
}

}  // namespace
}  // namespace range_image_mapping::evaluation
