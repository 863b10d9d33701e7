// Triangle mesh files: scenes the user brings (PLY or OBJ) and the ground
// truth meshes the simulator writes (PLY).
#pragma once

#include "range_image_mapping/simulation/triangle_mesh.h"

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
// Polygons become triangle fans. Rejects a mesh without triangles or with a
// non-finite vertex.
simulation::TriangleMesh loadMeshFile(const std::string& path);

// Binary little-endian PLY (io::writePlyMesh); the path must end in .ply.
void saveMeshFile(const std::string& path, const simulation::TriangleMesh& mesh);

}  // namespace range_image_mapping::io
