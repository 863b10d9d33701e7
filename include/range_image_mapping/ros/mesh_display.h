// The map's mesh for display: rviz markers (one TRIANGLE_LIST per chunk of
// marker_chunk_blocks^3 voxel blocks, coloured by height or intensity and
// shaded; only changed chunks re-sent) and the surface-points cloud. Both
// leave out what is above display_max_height (ceilings); the markers show
// each chunk at a level of detail by its distance from the sensor, under
// display_triangle_budget (mapping::MeshLevelOfDetail). The map and saved
// meshes keep everything at full resolution.
#pragma once

#include "range_image_mapping/mapping/marching_cubes.h"
#include "range_image_mapping/mapping/mesh_level_of_detail.h"
#include "range_image_mapping/mapping/voxel_block_grid.h"
#include "range_image_mapping/ros/parameters.h"

#include <sensor_msgs/PointCloud2.h>
#include <std_msgs/Header.h>
#include <visualization_msgs/MarkerArray.h>

#include <boost/shared_ptr.hpp>

#include <optional>
#include <string>
#include <unordered_set>
#include <vector>

namespace range_image_mapping {

class MeshMarkers {
 public:
  using Message = boost::shared_ptr<const visualization_msgs::MarkerArray>;

  // Uses world_frame and the colour and display parameters.
  explicit MeshMarkers(const MapperParameters& parameters);

  // The chunks a mesh update changed or removed wait for the next update().
  void noteChanges(const mapping::MeshUpdate& changes);
  // The next update() re-sends everything (a new subscriber, republish_mesh).
  void requestFullResend() { full_resend_ = true; }
  // Nobody holds the markers: the changes are dropped and the next
  // subscriber gets everything.
  void forgetSubscribers();
  // The messages that bring a subscriber up to date with mesh seen from
  // viewpoint (the sensor): the chunks whose shown mesh changed (new
  // triangles, or a new level as the sensor moved; a DELETE for a chunk that
  // lost its triangles or that the budget leaves out), or after
  // requestFullResend a DELETEALL and every shown chunk; last a text marker
  // with the triangle counts (alone only when they changed). Messages are split past kTrianglesPerMessage,
  // so rviz and the transport never see one huge message on a full re-send.
  std::vector<Message> update(const mapping::MeshExtractor& mesh, const Eigen::Vector3f& viewpoint);
  // Triangles in the markers rviz holds after the last update.
  std::size_t shownTriangles() const { return level_of_detail_.shownTriangles(); }
  // After a map reset: a DELETEALL, and nothing held or changed.
  Message clear();

  static constexpr std::size_t kTrianglesPerMessage = 500'000;

 private:
  using ChunkKey = Eigen::Vector3i;  // a cube of marker_chunk_blocks^3 blocks
  using ChunkSet = std::unordered_set<ChunkKey, mapping::BlockKeyHash>;

  ChunkKey chunkOf(const mapping::BlockKey& block) const;
  // The chunk's full mesh for display: its blocks' triangles at or below
  // display_max_height.
  TriangleMesh chunkMesh(const ChunkKey& key, const mapping::MeshExtractor& mesh) const;
  // The chunks' shown meshes as markers after `markers`, split into
  // messages, `last` at the end.
  std::vector<Message> markersOf(const std::vector<ChunkKey>& chunks, visualization_msgs::MarkerArray markers,
                                 std::optional<visualization_msgs::Marker> last);
  // The chunk's shown triangles as one marker (ADD), or a DELETE when it has
  // none and rviz holds it; nothing for a chunk that is empty and never was sent.
  void appendChunkMarker(const ChunkKey& key, visualization_msgs::MarkerArray& markers, std::size_t& triangles);
  visualization_msgs::Marker countMarker(const Eigen::Vector3f& viewpoint) const;
  std_msgs::ColorRGBA color(const TriangleMesh& mesh, int vertex) const;
  visualization_msgs::Marker deleteAll() const;

  MapperParameters parameters_;
  mapping::MeshLevelOfDetail level_of_detail_;  // every chunk's full mesh and shown level
  ChunkSet changed_, published_;  // changed since their last publication; held by rviz
  std::string last_count_text_;   // of the count marker last sent
  bool full_resend_ = true;
};

// Mesh vertices at or below max_height as an unorganized x y z (and
// intensity) cloud.
void meshVerticesToPointCloud2(const std::vector<const mapping::MeshChunk*>& chunks, bool with_intensity,
                               double max_height, const std_msgs::Header& header, sensor_msgs::PointCloud2& cloud);

}  // namespace range_image_mapping
