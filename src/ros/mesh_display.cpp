#include "range_image_mapping/ros/mesh_display.h"

#include "range_image_mapping/ros/range_image_conversions.h"

#include <boost/make_shared.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <optional>
#include <utility>

namespace range_image_mapping {
namespace {

int floorDivide(int value, int divisor) {
  return value >= 0 ? value / divisor : -((-value + divisor - 1) / divisor);
}

// Marker id of a chunk, so a chunk's update replaces its marker: x and y in
// 12 bits each, z in 8 (two's complement, wrapped). Two chunks share an id
// only 4096 chunks apart in x or y or 256 in z (chunks of 4 blocks of 8
// voxels of 10 cm: 13 km and 820 m), which a bounded map never holds at once.
int32_t markerId(const Eigen::Vector3i& chunk) {
  const uint32_t x = uint32_t(chunk.x()) & 0xfffu, y = uint32_t(chunk.y()) & 0xfffu,
                 z = uint32_t(chunk.z()) & 0xffu;
  return int32_t((z << 24) | (y << 12) | x);
}

// A hue ramp from blue (0) through green to red (1).
std_msgs::ColorRGBA rampColor(float t) {
  t = std::clamp(t, 0.0f, 1.0f);
  const float hue = (1.0f - t) * 240.0f / 60.0f;  // sector of the HSV hexagon, 4 = blue, 0 = red
  const float x = 1.0f - std::abs(std::fmod(hue, 2.0f) - 1.0f);
  std_msgs::ColorRGBA color;
  color.a = 1.0f;
  if (hue < 1.0f) color.r = 1.0f, color.g = x;
  else if (hue < 2.0f) color.r = x, color.g = 1.0f;
  else if (hue < 3.0f) color.g = 1.0f, color.b = x;
  else color.g = x, color.b = 1.0f;
  return color;
}

mapping::LevelOfDetailOptions levelOfDetailOptions(const MapperParameters& parameters) {
  mapping::LevelOfDetailOptions options;
  options.voxel_size_m = parameters.map.grid.voxel_size_m;
  options.full_detail_distance_m = parameters.display_full_detail_distance_m;
  options.triangle_budget = parameters.display_triangle_budget;
  return options;
}

}  // namespace

MeshMarkers::MeshMarkers(const MapperParameters& parameters)
    : parameters_(parameters), level_of_detail_(levelOfDetailOptions(parameters)) {}

MeshMarkers::ChunkKey MeshMarkers::chunkOf(const mapping::BlockKey& block) const {
  const int edge = parameters_.marker_chunk_blocks;
  return {floorDivide(block.x(), edge), floorDivide(block.y(), edge), floorDivide(block.z(), edge)};
}

void MeshMarkers::noteChanges(const mapping::MeshUpdate& changes) {
  for (const mapping::BlockKey& key : changes.changed) changed_.insert(chunkOf(key));
  for (const mapping::BlockKey& key : changes.removed) changed_.insert(chunkOf(key));
}

void MeshMarkers::forgetSubscribers() {
  full_resend_ = true;
  changed_.clear();
}

std::vector<MeshMarkers::Message> MeshMarkers::update(const mapping::MeshExtractor& mesh,
                                                      const Eigen::Vector3f& viewpoint) {
  visualization_msgs::MarkerArray first;
  const bool full = full_resend_;
  if (full_resend_) {
    // DELETEALL first, so whatever a subscriber held (before a reset, from an
    // earlier run) goes, then every chunk that has triangles.
    full_resend_ = false;
    published_.clear();
    level_of_detail_.clear();
    changed_.clear();
    for (const mapping::MeshChunk* chunk : mesh.chunks())
      if (!chunk->triangles.empty()) changed_.insert(chunkOf(chunk->key));
    first.markers.push_back(deleteAll());
  }
  // A chunk's lattice box: its faces are where its neighbours' triangles
  // meet its own. From lattice coordinates, as marching cubes places its
  // vertices, so a vertex on a face has the face's very bits.
  const int64_t chunk_voxels = int64_t(parameters_.marker_chunk_blocks) * parameters_.map.grid.block_edge;
  const double voxel_m = parameters_.map.grid.voxel_size_m;
  for (const ChunkKey& key : changed_) {
    const Eigen::Matrix<int64_t, 3, 1> lower = key.cast<int64_t>() * chunk_voxels;
    const Eigen::Matrix<int64_t, 3, 1> upper = lower + Eigen::Matrix<int64_t, 3, 1>::Constant(chunk_voxels);
    level_of_detail_.setPiece(key, chunkMesh(key, mesh),
                              Eigen::AlignedBox3f((lower.cast<double>() * voxel_m).cast<float>(),
                                                  (upper.cast<double>() * voxel_m).cast<float>()));
  }
  changed_.clear();
  const std::vector<ChunkKey> shown_changed = level_of_detail_.update(viewpoint);
  // The count goes with the chunks, and alone only when it changed.
  std::optional<visualization_msgs::Marker> count = countMarker(viewpoint);
  if (!full && shown_changed.empty() && count->text == last_count_text_) count.reset();
  if (count) last_count_text_ = count->text;
  return markersOf(shown_changed, std::move(first), std::move(count));
}

MeshMarkers::Message MeshMarkers::clear() {
  changed_.clear();
  published_.clear();
  level_of_detail_.clear();
  const auto message = boost::make_shared<visualization_msgs::MarkerArray>();
  message->markers.push_back(deleteAll());
  return message;
}

visualization_msgs::Marker MeshMarkers::deleteAll() const {
  visualization_msgs::Marker marker;
  marker.header.frame_id = parameters_.world_frame;
  marker.ns = "mesh";
  marker.action = visualization_msgs::Marker::DELETEALL;
  return marker;
}

TriangleMesh MeshMarkers::chunkMesh(const ChunkKey& key, const mapping::MeshExtractor& mesh) const {
  const int edge = parameters_.marker_chunk_blocks;
  const float max_height = float(parameters_.display_max_height_m);
  TriangleMesh result;
  for (int k = 0; k < edge; ++k)
    for (int j = 0; j < edge; ++j)
      for (int i = 0; i < edge; ++i) {
        const mapping::MeshChunk* chunk = mesh.chunk(key * edge + mapping::BlockKey(i, j, k));
        if (!chunk) continue;
        const int offset = int(result.vertices.size());
        result.vertices.insert(result.vertices.end(), chunk->vertices.begin(), chunk->vertices.end());
        if (chunk->normals.size() == chunk->vertices.size())
          result.normals.insert(result.normals.end(), chunk->normals.begin(), chunk->normals.end());
        else
          result.normals.resize(result.vertices.size(), Eigen::Vector3f::UnitZ());
        if (chunk->intensities.size() == chunk->vertices.size())
          result.intensities.insert(result.intensities.end(), chunk->intensities.begin(), chunk->intensities.end());
        else
          result.intensities.resize(result.vertices.size(), 0.0f);
        for (const Eigen::Vector3i& triangle : chunk->triangles)
          if (chunk->vertices[triangle[0]].z() <= max_height && chunk->vertices[triangle[1]].z() <= max_height &&
              chunk->vertices[triangle[2]].z() <= max_height)
            result.triangles.push_back(triangle + Eigen::Vector3i::Constant(offset));
      }
  return result;
}

std::vector<MeshMarkers::Message> MeshMarkers::markersOf(const std::vector<ChunkKey>& chunks,
                                                         visualization_msgs::MarkerArray markers,
                                                         std::optional<visualization_msgs::Marker> last) {
  std::vector<Message> messages;
  std::size_t triangles = 0;
  const auto send = [&] {
    if (markers.markers.empty()) return;
    const auto message = boost::make_shared<visualization_msgs::MarkerArray>();
    message->markers.swap(markers.markers);
    messages.push_back(message);
    triangles = 0;
  };
  for (const ChunkKey& key : chunks) {
    appendChunkMarker(key, markers, triangles);
    if (triangles >= kTrianglesPerMessage) send();
  }
  if (last) markers.markers.push_back(std::move(*last));
  send();
  return messages;
}

void MeshMarkers::appendChunkMarker(const ChunkKey& key, visualization_msgs::MarkerArray& markers,
                                    std::size_t& triangles) {
  const TriangleMesh* shown = level_of_detail_.shown(key);
  // A triangle list repeats each vertex for every triangle using it.
  visualization_msgs::Marker marker;
  marker.header.frame_id = parameters_.world_frame;
  marker.ns = "mesh";
  marker.id = markerId(key);
  if (!shown || shown->triangles.empty()) {
    if (published_.erase(key) == 0) return;
    marker.action = visualization_msgs::Marker::DELETE;
    markers.markers.push_back(std::move(marker));
    return;
  }
  marker.points.reserve(3 * shown->triangles.size());
  marker.colors.reserve(3 * shown->triangles.size());
  for (const Eigen::Vector3i& triangle : shown->triangles)
    for (int corner = 0; corner < 3; ++corner) {
      const Eigen::Vector3f& vertex = shown->vertices[triangle[corner]];
      geometry_msgs::Point point;
      point.x = vertex.x();
      point.y = vertex.y();
      point.z = vertex.z();
      marker.points.push_back(point);
      marker.colors.push_back(color(*shown, triangle[corner]));
    }
  marker.type = visualization_msgs::Marker::TRIANGLE_LIST;
  marker.action = visualization_msgs::Marker::ADD;
  marker.pose.orientation.w = 1.0;
  marker.scale.x = marker.scale.y = marker.scale.z = 1.0;
  marker.color.a = 1.0f;  // rviz takes the alpha of vertex-coloured triangles from here
  triangles += shown->triangles.size();
  published_.insert(key);
  markers.markers.push_back(std::move(marker));
}

// The shown and full triangle counts, floating above the sensor.
visualization_msgs::Marker MeshMarkers::countMarker(const Eigen::Vector3f& viewpoint) const {
  visualization_msgs::Marker marker;
  marker.header.frame_id = parameters_.world_frame;
  marker.ns = "mesh_triangles";
  marker.id = 0;
  marker.type = visualization_msgs::Marker::TEXT_VIEW_FACING;
  marker.action = visualization_msgs::Marker::ADD;
  marker.pose.position.x = viewpoint.x();
  marker.pose.position.y = viewpoint.y();
  marker.pose.position.z = viewpoint.z() + 4.0;
  marker.pose.orientation.w = 1.0;
  marker.scale.z = 1.5;  // text height, m
  marker.color.r = marker.color.g = marker.color.b = marker.color.a = 1.0f;
  char text[160];
  std::snprintf(text, sizeof(text), "%zu of %zu triangles shown", level_of_detail_.shownTriangles(),
                level_of_detail_.fullTriangles());
  marker.text = text;
  return marker;
}

// rviz draws vertex-coloured triangle lists unlit, so a flat colour per
// height would hide every edge: the colour is shaded here with the SDF
// normal (half-Lambert, one light from above, so no face is black).
std_msgs::ColorRGBA MeshMarkers::color(const TriangleMesh& mesh, int vertex) const {
  std_msgs::ColorRGBA color;
  if (parameters_.color_mode == MeshColorMode::kIntensity && !mesh.intensities.empty()) {
    const float grey = std::clamp(mesh.intensities[vertex] / float(parameters_.intensity_color_max), 0.0f, 1.0f);
    color.r = color.g = color.b = 0.15f + 0.85f * grey;
    color.a = 1.0f;
  } else {
    const float z = mesh.vertices[vertex].z();
    color = rampColor(float((z - parameters_.height_color_min_m) /
                            (parameters_.height_color_max_m - parameters_.height_color_min_m)));
  }
  const Eigen::Vector3f light = Eigen::Vector3f(0.35f, 0.25f, 0.9f).normalized();
  const float lambert = vertex < int(mesh.normals.size()) ? mesh.normals[vertex].dot(light) : 1.0f;
  const float shade = 0.3f + 0.7f * (0.5f + 0.5f * lambert);
  color.r *= shade;
  color.g *= shade;
  color.b *= shade;
  return color;
}

void meshVerticesToPointCloud2(const std::vector<const mapping::MeshChunk*>& chunks, bool with_intensity,
                               double max_height, const std_msgs::Header& header, sensor_msgs::PointCloud2& cloud) {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<float> intensities;
  for (const mapping::MeshChunk* chunk : chunks)
    for (std::size_t i = 0; i < chunk->vertices.size(); ++i) {
      if (!(chunk->vertices[i].z() <= max_height)) continue;
      vertices.push_back(chunk->vertices[i]);
      if (with_intensity) intensities.push_back(i < chunk->intensities.size() ? chunk->intensities[i] : 0.0f);
    }
  pointsToPointCloud2(vertices, with_intensity ? &intensities : nullptr, header, cloud);
}

}  // namespace range_image_mapping
