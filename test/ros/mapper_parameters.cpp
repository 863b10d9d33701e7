// readMapperParameters: defaults, values read into the core's TsdfMapOptions,
// bad values rejected with an error naming the parameter; and a Mapper nodelet
// with a bad parameter fails to load instead of running without a map. Needs
// a master only for the parameter server.
#include "error_text.h"
#include "nodelet_loading.h"
#include "range_image_mapping/ros/parameters.h"

#include <gtest/gtest.h>
#include <nodelet/loader.h>
#include <ros/ros.h>

#include <string>
#include <vector>

namespace range_image_mapping {
namespace {

using test::errorOf;

TEST(MapperParameters, DefaultsWhenNothingIsSet) {
  const MapperParameters parameters = readMapperParameters(ros::NodeHandle("~empty"));
  const mapping::TsdfMapOptions core;
  EXPECT_EQ(parameters.world_frame, "odom");
  EXPECT_EQ(parameters.pose_source, PoseSourceType::kTf);
  EXPECT_TRUE(parameters.deskew);
  EXPECT_EQ(parameters.color_mode, MeshColorMode::kHeight);
  // The core's own defaults, untouched.
  EXPECT_EQ(parameters.map.grid.voxel_size_m, core.grid.voxel_size_m);
  EXPECT_EQ(parameters.map.grid.block_edge, core.grid.block_edge);
  EXPECT_EQ(parameters.map.grid.max_blocks, core.grid.max_blocks);
  EXPECT_FALSE(parameters.map.grid.store_intensity);
  EXPECT_EQ(parameters.map.integrator.truncation_m, core.integrator.truncation_m);
  EXPECT_EQ(parameters.map.integrator.min_range_m, core.integrator.min_range_m);
  EXPECT_EQ(parameters.map.integrator.max_range_m, core.integrator.max_range_m);
  EXPECT_EQ(parameters.map.integrator.point_stride, core.integrator.point_stride);
  EXPECT_EQ(parameters.map.integrator.max_weight, core.integrator.max_weight);
  EXPECT_EQ(parameters.map.mesh.min_weight, core.mesh.min_weight);
  EXPECT_EQ(parameters.map.integrator.mesh_min_weight, core.integrator.mesh_min_weight);
  EXPECT_EQ(parameters.map.integrator.signed_distance, core.integrator.signed_distance);
  EXPECT_EQ(parameters.map.integrator.mesh_tolerance_voxels, core.integrator.mesh_tolerance_voxels);
  EXPECT_EQ(parameters.map.integrator.free_space_weight, core.integrator.free_space_weight);
  EXPECT_EQ(parameters.map.integrator.plane_fill_m, core.integrator.plane_fill_m);
  EXPECT_EQ(parameters.map.mesh.update_budget_s, core.mesh.update_budget_s);
  EXPECT_EQ(parameters.map.memory_radius_m, core.memory_radius_m);
  EXPECT_EQ(parameters.map.max_pose_jump_m, core.max_pose_jump_m);
}

TEST(MapperParameters, ValuesReachTheCoreOptions) {
  ros::NodeHandle node("~set");
  node.setParam("voxel_size", 0.05);
  node.setParam("block_edge", 8);
  node.setParam("truncation", 0.2);
  node.setParam("min_range", 1);  // an integer where a double is expected is fine
  node.setParam("max_range", 20.0);
  node.setParam("integration_stride", 2);
  node.setParam("max_weight", 32.0);
  node.setParam("memory_radius", 50.0);
  node.setParam("max_pose_jump", 5.0);
  node.setParam("color_mode", "intensity");
  node.setParam("pose_source", "odometry");
  node.setParam("world_frame", "map");
  node.setParam("deskew", false);
  node.setParam("mesh_rate", 5);
  node.setParam("marker_chunk_blocks", 4);
  node.setParam("signed_distance", "along_ray");
  node.setParam("mesh_tolerance", 0.0);
  node.setParam("mesh_update_budget", 0.015);
  node.setParam("mesh_min_weight", 1.0);
  node.setParam("free_space_weight", 1.0);
  node.setParam("plane_fill", 100.0);
  const MapperParameters parameters = readMapperParameters(node);
  EXPECT_EQ(parameters.map.integrator.plane_fill_m, 100.0);
  EXPECT_EQ(parameters.map.integrator.free_space_weight, 1.0f);
  EXPECT_EQ(parameters.map.integrator.signed_distance, mapping::SignedDistance::kAlongRay);
  EXPECT_EQ(parameters.map.integrator.mesh_tolerance_voxels, 0.0);
  EXPECT_EQ(parameters.map.mesh.update_budget_s, 0.015);
  // One threshold for the mesher and for the integrator's re-mesh marks.
  EXPECT_EQ(parameters.map.mesh.min_weight, 1.0f);
  EXPECT_EQ(parameters.map.integrator.mesh_min_weight, 1.0f);
  EXPECT_EQ(parameters.map.grid.voxel_size_m, 0.05);
  EXPECT_EQ(parameters.map.grid.block_edge, 8);
  EXPECT_EQ(parameters.map.integrator.truncation_m, 0.2);
  EXPECT_EQ(parameters.map.integrator.min_range_m, 1.0);
  EXPECT_EQ(parameters.map.integrator.max_range_m, 20.0);
  EXPECT_EQ(parameters.map.integrator.point_stride, 2);
  EXPECT_EQ(parameters.map.integrator.max_weight, 32.0f);
  EXPECT_EQ(parameters.map.memory_radius_m, 50.0);
  EXPECT_EQ(parameters.map.max_pose_jump_m, 5.0);
  EXPECT_EQ(parameters.color_mode, MeshColorMode::kIntensity);
  EXPECT_TRUE(parameters.map.grid.store_intensity);  // intensity colours need intensity in the voxels
  EXPECT_EQ(parameters.pose_source, PoseSourceType::kOdometry);
  EXPECT_EQ(parameters.world_frame, "map");
  EXPECT_FALSE(parameters.deskew);
  EXPECT_EQ(parameters.mesh_rate_hz, 5.0);
  EXPECT_EQ(parameters.marker_chunk_blocks, 4);
}

template <typename Value>
std::string errorFor(const std::string& name, const Value& value) {
  ros::NodeHandle node("~bad_" + name);
  node.setParam(name, value);
  return errorOf([&] { readMapperParameters(node); });
}

TEST(MapperParameters, BadValuesAreErrorsNamingTheParameter) {
  // The core's checks (TsdfMapOptions::validate), reported with the node.
  const std::string zero_voxel = errorFor("voxel_size", 0.0);
  EXPECT_NE(zero_voxel.find("/bad_voxel_size"), std::string::npos) << zero_voxel;
  EXPECT_NE(zero_voxel.find("voxel_size"), std::string::npos) << zero_voxel;
  const std::string huge_voxel = errorFor("voxel_size", 1000.0);
  EXPECT_NE(huge_voxel.find("voxel_size"), std::string::npos) << huge_voxel;
  EXPECT_NE(huge_voxel.find("1000"), std::string::npos) << huge_voxel;
  const std::string edge = errorFor("block_edge", 12);
  EXPECT_NE(edge.find("block_edge"), std::string::npos) << edge;
  EXPECT_NE(edge.find("12"), std::string::npos) << edge;
  const std::string ranges = errorFor("min_range", 50.0);  // above the default max_range
  EXPECT_NE(ranges.find("range"), std::string::npos) << ranges;
  // The ROS side's own checks.
  const std::string source = errorFor("pose_source", std::string("gps"));
  EXPECT_NE(source.find("/bad_pose_source/pose_source is 'gps', expected one of: tf, odometry"), std::string::npos)
      << source;
  const std::string color = errorFor("color_mode", std::string("rgb"));
  EXPECT_NE(color.find("color_mode is 'rgb', expected one of: height, intensity"), std::string::npos) << color;
  const std::string voxel_type = errorFor("voxel_size", std::string("5cm"));
  EXPECT_NE(voxel_type.find("voxel_size must be a number, got a string"), std::string::npos) << voxel_type;
  const std::string rate = errorFor("mesh_rate", 0.0);
  EXPECT_NE(rate.find("mesh_rate is 0, expected within ["), std::string::npos) << rate;
  const std::string frame = errorFor("world_frame", std::string(""));
  EXPECT_NE(frame.find("world_frame is empty"), std::string::npos) << frame;
  const std::string deskew = errorFor("deskew", std::string("yes"));
  EXPECT_NE(deskew.find("deskew must be true or false, got a string"), std::string::npos) << deskew;
  const std::string heights = errorFor("height_color_max", -5.0);
  EXPECT_NE(heights.find("height_color_max (-5) must be above"), std::string::npos) << heights;
  const std::string distance = errorFor("signed_distance", std::string("euclidean"));
  EXPECT_NE(distance.find("signed_distance is 'euclidean', expected one of: point_to_plane, along_ray"),
            std::string::npos)
      << distance;
  const std::string budget = errorFor("mesh_update_budget", -1.0);
  EXPECT_NE(budget.find("update_budget_s"), std::string::npos) << budget;
  const std::string chunk = errorFor("marker_chunk_blocks", 0);
  EXPECT_NE(chunk.find("marker_chunk_blocks is 0, expected within [1, 64]"), std::string::npos) << chunk;
}

// The nodelet refuses to start, saying which parameter: Loader::load reports
// the exception of onInit.
TEST(MapperParameters, NodeletWithABadParameterFailsToLoad) {
  const std::string mapper = "range_image_mapping/Mapper";
  nodelet::Loader loader(false);
  test::expectRefused(loader, mapper, "/bad_mapper", "block_edge", 12, "block_edge");
  test::expectRefused(loader, mapper, "/unknown_source_mapper", "pose_source", std::string("gps"),
                      "Mapper not started: parameter /unknown_source_mapper/pose_source is 'gps'");
  ros::NodeHandle("/good_mapper").setParam("voxel_size", 0.2);
  test::expectLoaded(loader, mapper, "/good_mapper");
  loader.clear();
}

}  // namespace
}  // namespace range_image_mapping

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "mapper_parameters");
  ros::NodeHandle keep_node_alive;
  return RUN_ALL_TESTS();
}
