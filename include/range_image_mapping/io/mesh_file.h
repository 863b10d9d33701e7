// Triangle mesh files: scenes the user brings (PLY or OBJ), the ground truth
// meshes the simulator writes and the maps' meshes (PLY).
#pragma once

#include "range_image_mapping/triangle_mesh.h"

#include <stdexcept>
#include <string>

namespace range_image_mapping::io {

// A mesh file that cannot be read or written; what() names the file, the line
// where there is one, and the problem. (Malformed PLY content throws
// io::PlyFormatError; both derive from std::runtime_error.)
class MeshFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Chosen by extension, case-insensitive:
//  .ply  ASCII or binary little-endian (io::readPlyMesh): any scalar type for
//        x, y, z, faces as "vertex_indices" lists of any integer types;
//  .obj  "v x y z [w]" and "f" lines with "i", "i/t", "i//n" or "i/t/n"
//        corners, negative (relative) indices; other statements are ignored.
// Polygons become triangle fans. Only positions and faces are read (no
// normals or intensities). Rejects a mesh without triangles or with a
// non-finite vertex.
TriangleMesh loadMeshFile(const std::string& path);

// Binary little-endian PLY (io::writePlyMesh) with normals when the mesh has
// them and a float "intensity" per vertex when it has intensities; the path
// must end in .ply. Throws std::invalid_argument for normals or intensities
// that are not one per vertex or a triangle index out of range, and
// io::PlyFormatError when the file cannot be written.
void saveMeshFile(const std::string& path, const TriangleMesh& mesh);

}  // namespace range_image_mapping::io
