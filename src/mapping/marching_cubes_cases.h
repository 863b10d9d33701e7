// The marching cubes case table, generated at start-up from the cube's
// topology instead of being typed in: for each sign pattern of the 8 corners
// (and each choice on ambiguous faces) the iso-lines on the 6 faces are
// joined into closed loops, and each loop is triangulated as a fan.
//
// Ambiguous faces (two diagonal corners negative, the other two not) are
// resolved by the asymptotic decider, which only reads the face's own four
// values: the two cubes sharing a face choose the same iso-lines, so the mesh
// has no cracks.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

namespace range_image_mapping::mapping {

// Corner c of a cube sits at (c & 1, (c >> 1) & 1, (c >> 2) & 1) voxels from
// its lower corner.
struct CubeEdge {
  int lower_corner = 0;  // the end with the smaller coordinate
  int axis = 0;          // 0 = x, 1 = y, 2 = z
};

class MarchingCubesCases {
 public:
  // Built once, on first use (thread-safe static initialisation).
  static const MarchingCubesCases& instance();

  const std::array<CubeEdge, 12>& edges() const { return edges_; }
  // The 4 corners of each face, counter-clockwise seen from outside the cube.
  const std::array<std::array<int, 4>, 6>& faces() const { return faces_; }

  // corner_signs: bit c set when corner c is negative (inside, SDF < 0).
  // The faces of that pattern whose iso-lines are ambiguous, in the order
  // the `decisions` bits of triangles() refer to.
  int ambiguousFaceCount(int corner_signs) const { return ambiguous_face_count_[corner_signs]; }
  int ambiguousFace(int corner_signs, int i) const { return ambiguous_faces_[corner_signs][i]; }

  // Triangles as cube edge indices, three per triangle, counter-clockwise
  // seen from the positive side. Bit i of `decisions` set: on the i-th
  // ambiguous face the negative corners are connected (the positive ones cut
  // off); clear: the negative corners are cut off.
  //
  // No triangle edge joins two vertices on one cube face unless the iso-line
  // itself does: such an edge could be repeated by the cube across that face
  // and the mesh would stop being a manifold. The few loops (tunnels, up to
  // 12 vertices) that cannot be cut that way are fanned around an extra
  // vertex inside the cube, the mean of the loop's vertices; kInteriorVertex
  // stands for it and interior_loop lists the loop's edges.
  static constexpr uint8_t kInteriorVertex = 12;
  struct Triangles {
    const uint8_t* edges = nullptr;
    int count = 0;
    const uint8_t* interior_loop = nullptr;
    int interior_loop_size = 0;
  };
  Triangles triangles(int corner_signs, int decisions) const {
    const Entry& entry = entries_[first_entry_[corner_signs] + uint32_t(decisions)];
    return {edge_lists_.data() + entry.triangles_begin, entry.triangle_count,
            edge_lists_.data() + entry.interior_loop_begin, entry.interior_loop_size};
  }

 private:
  MarchingCubesCases();
  struct Entry {
    uint32_t triangles_begin = 0;  // into edge_lists_
    uint32_t interior_loop_begin = 0;
    uint8_t triangle_count = 0;
    uint8_t interior_loop_size = 0;
  };
  // The entry of one corner pattern and face choice.
  Entry generateEntry(int corner_signs, int decisions);
  // Appends a triangulation of `loop` (cube edges in order) whose diagonals
  // never join two edges of one face; false if there is none.
  bool triangulateLoop(const std::vector<int>& loop);
  bool shareFace(int edge_a, int edge_b) const { return (edge_faces_[edge_a] & edge_faces_[edge_b]) != 0; }
  int edgeBetween(int corner_a, int corner_b) const { return edge_between_[corner_a][corner_b]; }

  std::array<CubeEdge, 12> edges_{};
  std::array<std::array<int, 8>, 8> edge_between_{};  // -1 when not adjacent
  std::array<std::array<int, 4>, 6> faces_{};
  std::array<uint8_t, 12> edge_faces_{};  // bit f set: the edge lies on face f
  std::array<uint8_t, 256> ambiguous_face_count_{};
  std::array<std::array<uint8_t, 6>, 256> ambiguous_faces_{};
  std::array<uint32_t, 256> first_entry_{};
  std::vector<Entry> entries_;
  std::vector<uint8_t> edge_lists_;  // triangles' and interior loops' cube edges
};

}  // namespace range_image_mapping::mapping
