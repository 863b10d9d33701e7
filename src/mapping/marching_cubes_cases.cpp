#include "marching_cubes_cases.h"

#include <functional>
#include <stdexcept>
#include <string>

namespace range_image_mapping::mapping {
namespace {

bool isNegative(int corner_signs, int corner) { return (corner_signs >> corner) & 1; }

}  // namespace

const MarchingCubesCases& MarchingCubesCases::instance() {
  static const MarchingCubesCases cases;
  return cases;
}

MarchingCubesCases::MarchingCubesCases() {
  for (auto& row : edge_between_) row.fill(-1);
  int edge = 0;
  for (int axis = 0; axis < 3; ++axis)
    for (int corner = 0; corner < 8; ++corner) {
      if (isNegative(corner, axis)) continue;  // bit `axis` set: not the lower end
      const int upper = corner | (1 << axis);
      edges_[edge] = {corner, axis};
      edge_between_[corner][upper] = edge_between_[upper][corner] = edge;
      ++edge;
    }

  // Face (axis, side): the corners whose `axis` bit equals side. Walking
  // (0,0), (1,0), (1,1), (0,1) in the two other axes (cyclic order) turns
  // counter-clockwise about +axis, which is outward for side 1.
  int face = 0;
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side) {
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      constexpr int kCycle[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
      for (int i = 0; i < 4; ++i) {
        const int step = side == 1 ? i : (4 - i) % 4;  // reversed for the face looking down -axis
        faces_[face][i] = (side << axis) | (kCycle[step][0] << u) | (kCycle[step][1] << v);
      }
      ++face;
    }

  for (int f = 0; f < 6; ++f)
    for (int i = 0; i < 4; ++i) edge_faces_[edgeBetween(faces_[f][i], faces_[f][(i + 1) % 4])] |= uint8_t(1 << f);

  for (int corner_signs = 0; corner_signs < 256; ++corner_signs) {
    int count = 0;
    for (int f = 0; f < 6; ++f) {
      int crossings = 0;
      for (int i = 0; i < 4; ++i)
        crossings += isNegative(corner_signs, faces_[f][i]) !=
                     isNegative(corner_signs, faces_[f][(i + 1) % 4]);
      if (crossings == 4) ambiguous_faces_[corner_signs][count++] = uint8_t(f);
    }
    ambiguous_face_count_[corner_signs] = uint8_t(count);
    first_entry_[corner_signs] = uint32_t(entries_.size());
    for (int decisions = 0; decisions < (1 << count); ++decisions)
      entries_.push_back(generateEntry(corner_signs, decisions));
  }
}

MarchingCubesCases::Entry MarchingCubesCases::generateEntry(int corner_signs, int decisions) {
  // Each face contributes directed iso-line segments between crossed edges:
  // walking the face counter-clockwise from outside, a segment runs from a
  // positive-to-negative crossing to a negative-to-positive one, which keeps
  // the negative side on the same hand everywhere. The two faces of an edge
  // walk it in opposite directions, so every crossed edge starts exactly one
  // segment and ends exactly one: the segments close into loops.
  std::array<int, 12> next;
  next.fill(-1);
  const auto link = [&](int from, int to) {
    if (next[from] != -1) throw std::logic_error("marching cubes table: edge starts two segments");
    next[from] = to;
  };
  int ambiguous_index = 0;
  for (int f = 0; f < 6; ++f) {
    const std::array<int, 4>& q = faces_[f];
    const auto negative = [&](int i) { return isNegative(corner_signs, q[(i + 4) % 4]); };
    const auto edgeAfter = [&](int i) { return edgeBetween(q[(i + 4) % 4], q[(i + 5) % 4]); };
    int crossings = 0;
    for (int i = 0; i < 4; ++i) crossings += negative(i) != negative(i + 1);
    if (crossings == 2) {
      int from = -1, to = -1;
      for (int i = 0; i < 4; ++i) {
        if (!negative(i) && negative(i + 1)) from = edgeAfter(i);
        if (negative(i) && !negative(i + 1)) to = edgeAfter(i);
      }
      link(from, to);
    } else if (crossings == 4) {
      // Cut off each corner of one sign: the negative ones unless the
      // decider connected them across the face.
      const bool connect_negatives = (decisions >> ambiguous_index++) & 1;
      for (int i = 0; i < 4; ++i) {
        if (negative(i) == connect_negatives) continue;
        const int before = edgeAfter(i - 1), after = edgeAfter(i);
        if (negative(i))
          link(before, after);
        else
          link(after, before);
      }
    }
  }

  Entry entry;
  entry.triangles_begin = uint32_t(edge_lists_.size());
  std::vector<int> interior_loop;
  std::array<bool, 12> visited{};
  std::vector<int> loop;
  for (int start = 0; start < 12; ++start) {
    if (next[start] == -1 || visited[start]) continue;
    loop.clear();
    for (int edge = start; !visited[edge]; edge = next[edge]) {
      if (next[edge] == -1) throw std::logic_error("marching cubes table: open iso-line loop");
      visited[edge] = true;
      loop.push_back(edge);
    }
    if (loop.size() < 3 || next[loop.back()] != start)
      throw std::logic_error("marching cubes table: malformed loop for corner pattern " +
                             std::to_string(corner_signs));
    if (triangulateLoop(loop)) continue;
    if (!interior_loop.empty())
      throw std::logic_error("marching cubes table: two loops need an interior vertex");
    interior_loop = loop;
    // A fan around the interior vertex keeps the loop's orientation.
    for (std::size_t i = 0; i < loop.size(); ++i)
      for (int edge : {int(kInteriorVertex), loop[i], loop[(i + 1) % loop.size()]})
        edge_lists_.push_back(uint8_t(edge));
  }
  entry.triangle_count = uint8_t((edge_lists_.size() - entry.triangles_begin) / 3);
  entry.interior_loop_begin = uint32_t(edge_lists_.size());
  entry.interior_loop_size = uint8_t(interior_loop.size());
  for (int edge : interior_loop) edge_lists_.push_back(uint8_t(edge));
  return entry;
}

bool MarchingCubesCases::triangulateLoop(const std::vector<int>& loop) {
  // Dynamic programming over the sub-polygons loop[i..j] (closed by the
  // chord i-j): pick an apex k whose chords to i and j are allowed. Any
  // triangle keeps the loop's order, hence its orientation.
  const int n = int(loop.size());
  const auto allowed = [&](int i, int j) {
    return j - i == 1 || (i == 0 && j == n - 1) || !shareFace(loop[i], loop[j]);
  };
  constexpr int kUnknown = -2, kNone = -1;
  std::array<std::array<int, 12>, 12> apex;
  for (auto& row : apex) row.fill(kUnknown);
  const std::function<bool(int, int)> solvable = [&](int i, int j) {
    if (j - i < 2) return true;
    int& best = apex[i][j];
    if (best == kUnknown) {
      best = kNone;
      for (int k = i + 1; k < j && best == kNone; ++k)
        if (allowed(i, k) && allowed(k, j) && solvable(i, k) && solvable(k, j)) best = k;
    }
    return best != kNone;
  };
  if (!solvable(0, n - 1)) return false;
  const std::function<void(int, int)> emit = [&](int i, int j) {
    if (j - i < 2) return;
    const int k = apex[i][j];
    for (int corner : {loop[i], loop[k], loop[j]}) edge_lists_.push_back(uint8_t(corner));
    emit(i, k);
    emit(k, j);
  };
  emit(0, n - 1);
  return true;
}

}  // namespace range_image_mapping::mapping
