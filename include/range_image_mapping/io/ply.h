// PLY files: binary little-endian point clouds with extra per-vertex
// properties, triangle meshes, and reading vertex positions and faces back.
// (io::saveMeshFile writes a TriangleMesh with its normals and intensities.)
#pragma once

#include "range_image_mapping/triangle_mesh.h"

#include <Eigen/Core>

#include <cstdint>
#include <stdexcept>
#include <string>
#include <variant>
#include <vector>

namespace range_image_mapping::io {

// A PLY file that cannot be read or written; what() names the file and the problem.
class PlyFormatError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// One extra scalar per vertex, written after x, y, z in the order given.
struct PlyProperty {
  std::string name;  // e.g. "row", "col", "range", "intensity"
  std::variant<std::vector<uint8_t>, std::vector<uint16_t>, std::vector<int32_t>,
               std::vector<float>>
      values;
};

// Binary little-endian, "float x y z" then the extra properties. Throws
// std::invalid_argument for a property whose size or name does not fit.
void writePlyPointCloud(const std::string& path, const std::vector<Eigen::Vector3f>& points,
                        const std::vector<PlyProperty>& properties = {});

// Binary little-endian triangle mesh: float x y z (and nx ny nz when normals
// are given, one per vertex), faces as "list uchar int vertex_indices".
void writePlyMesh(const std::string& path, const std::vector<Eigen::Vector3f>& vertices,
                  const std::vector<Eigen::Vector3f>& normals,
                  const std::vector<Eigen::Vector3i>& triangles);
// The same with extra per-vertex properties after the normals (e.g. a TSDF
// mesh's "intensity"), checked as writePlyPointCloud checks its properties.
void writePlyMesh(const std::string& path, const std::vector<Eigen::Vector3f>& vertices,
                  const std::vector<Eigen::Vector3f>& normals,
                  const std::vector<Eigen::Vector3i>& triangles,
                  const std::vector<PlyProperty>& vertex_properties);

// Vertex x, y, z of an ASCII or binary little-endian PLY (any scalar type,
// converted to float); other properties and elements are skipped.
std::vector<Eigen::Vector3f> readPlyPoints(const std::string& path);

// Vertex x, y, z and the "face" element's "vertex_indices" (or "vertex_index")
// lists of an ASCII or binary little-endian PLY, any count and index types.
// Polygons are split into triangle fans (exact for convex polygons). Throws
// PlyFormatError naming the face for an index out of range or a face with
// fewer than three corners.
TriangleMesh readPlyMesh(const std::string& path);

}  // namespace range_image_mapping::io
