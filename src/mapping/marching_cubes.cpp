#include "range_image_mapping/mapping/marching_cubes.h"

#include "huge_pages.h"
#include "marching_cubes_cases.h"
#include "number_text.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tsl/robin_map.h>

#include <Eigen/Geometry>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cfloat>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <new>
#include <sstream>
#include <type_traits>

namespace range_image_mapping::mapping {
namespace {

std::string keyText(const BlockKey& key) {
  std::ostringstream text;
  text << '(' << key.x() << ", " << key.y() << ", " << key.z() << ')';
  return text.str();
}

// A block whose arrays do not match the grid would be read out of bounds.
[[noreturn]] void throwBadBlockArrays(const VoxelBlock& block, std::size_t voxels, bool intensity) {
  const auto name = [&]() -> std::pair<const char*, std::size_t> {
    if (block.sdf.size() != voxels) return {"sdf", block.sdf.size()};
    if (block.weight.size() != voxels) return {"weight", block.weight.size()};
    return {"intensity", intensity ? block.intensity.size() : voxels};
  }();
  throw MappingError("marching cubes: block " + keyText(block.key) + " has " + std::to_string(name.second) + " " +
                     name.first + " values, expected " + std::to_string(voxels));
}

// Bit x of `observed` / `negative` for the run of voxels from `sdf` and
// `weight` (run <= 32): observed means weight > 0, weight >= min_weight and
// a finite SDF; negative means sdf < 0 (a NaN is neither). Four voxels per
// comparison where SSE2 is there: this runs for every voxel a chunk reads.
inline void voxelRowBits(const float* sdf, const float* weight, int run, float min_weight, uint32_t& observed,
                         uint32_t& negative) {
  uint32_t observed_bits = 0, negative_bits = 0;
  int x = 0;
#if defined(__SSE2__)
  const __m128 zero = _mm_setzero_ps(), minimum = _mm_set1_ps(min_weight), largest = _mm_set1_ps(FLT_MAX);
  const __m128 magnitude = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
  for (; x + 4 <= run; x += 4) {
    const __m128 s = _mm_loadu_ps(sdf + x), w = _mm_loadu_ps(weight + x);
    const __m128 is_observed = _mm_and_ps(_mm_and_ps(_mm_cmpgt_ps(w, zero), _mm_cmpge_ps(w, minimum)),
                                          _mm_cmple_ps(_mm_and_ps(s, magnitude), largest));
    observed_bits |= uint32_t(_mm_movemask_ps(is_observed)) << x;
    negative_bits |= uint32_t(_mm_movemask_ps(_mm_cmplt_ps(s, zero))) << x;
  }
#endif
  for (; x < run; ++x) {
    observed_bits |= uint32_t(weight[x] > 0.0f && weight[x] >= min_weight && std::isfinite(sdf[x])) << x;
    negative_bits |= uint32_t(sdf[x] < 0.0f) << x;
  }
  observed = observed_bits;
  negative = negative_bits;
}

// The rows of one block's part of the padded arrays (a block, or the slab of
// a +1 neighbour): y_count x z_count x runs of kGroups groups of four, each
// classified as voxelRowBits does, their bits shifted to the rows' first x and
// or-ed into the row bits, and the observed voxels of either sign gathered
// in any_negative / any_positive. Whole groups, so no per-row length test:
// this is most of the instructions spent on a block that has no surface.
template <int kGroups, bool kIntensity>
inline void loadRegion(const float* sdf_in, const float* weight_in, const float* intensity_in, int edge,
                       int y_count, int z_count, int row_floats, int padded, float min_weight, uint32_t in_run,
                       int shift, float* sdf_out, float* intensity_out, uint32_t* observed_out,
                       uint32_t* negative_out, uint32_t& any_negative, uint32_t& any_positive) {
  for (int z = 0; z < z_count; ++z)
    for (int y = 0; y < y_count; ++y) {
      const int voxel = edge * (y + edge * z), target = row_floats * (y + padded * z), row = y + padded * z;
      uint32_t observed_row = 0, negative_row = 0;
#if defined(__SSE2__)
      const __m128 zero = _mm_setzero_ps(), minimum = _mm_set1_ps(min_weight), largest = _mm_set1_ps(FLT_MAX);
      const __m128 magnitude = _mm_castsi128_ps(_mm_set1_epi32(0x7fffffff));
      for (int group = 0; group < kGroups; ++group) {
        const int x = 4 * group;
        const __m128 s = _mm_loadu_ps(sdf_in + voxel + x), w = _mm_loadu_ps(weight_in + voxel + x);
        _mm_storeu_ps(sdf_out + target + x, s);
        if (kIntensity) _mm_storeu_ps(intensity_out + target + x, _mm_loadu_ps(intensity_in + voxel + x));
        const __m128 is_observed = _mm_and_ps(_mm_and_ps(_mm_cmpgt_ps(w, zero), _mm_cmpge_ps(w, minimum)),
                                              _mm_cmple_ps(_mm_and_ps(s, magnitude), largest));
        observed_row |= uint32_t(_mm_movemask_ps(is_observed)) << x;
        negative_row |= uint32_t(_mm_movemask_ps(_mm_cmplt_ps(s, zero))) << x;
      }
      observed_row &= in_run;
      negative_row &= in_run;
#else
      const int run = std::min(4 * kGroups, __builtin_popcount(in_run));
      voxelRowBits(sdf_in + voxel, weight_in + voxel, run, min_weight, observed_row, negative_row);
      std::copy(sdf_in + voxel, sdf_in + voxel + run, sdf_out + target);
      if (kIntensity) std::copy(intensity_in + voxel, intensity_in + voxel + run, intensity_out + target);
#endif
      // Observed values are finite: not negative means >= 0.
      any_negative |= observed_row & negative_row;
      any_positive |= observed_row & ~negative_row;
      observed_out[row] |= observed_row << shift;
      negative_out[row] |= negative_row << shift;
    }
}

// Inline: it runs for a block and its 7 neighbours each time a block is meshed.
inline void checkBlockArrays(const VoxelBlock& block, std::size_t voxels, bool intensity) {
  if (block.sdf.size() != voxels || block.weight.size() != voxels || (intensity && block.intensity.size() != voxels))
    throwBadBlockArrays(block, voxels, intensity);
}

// `from` into `to`'s own arrays, which keep their capacity unless that is
// over twice what `from` needs (a chunk does not hold on to the memory of
// its largest version). The arrays are first made large enough, so a failed
// allocation leaves `to` as it was.
void copyChunk(const MeshChunk& from, MeshChunk& to) {
  if (to.vertices.capacity() > 2 * from.vertices.size() + 16 ||
      to.triangles.capacity() > 2 * from.triangles.size() + 16) {
    MeshChunk smaller;
    copyChunk(from, smaller);
    to = std::move(smaller);
    return;
  }
  to.vertices.reserve(from.vertices.size());
  to.normals.reserve(from.normals.size());
  to.intensities.reserve(from.intensities.size());
  to.triangles.reserve(from.triangles.size());
  to.vertex_edges.reserve(from.vertex_edges.size());
  to.key = from.key;
  to.block_edge = from.block_edge;
  to.vertices.assign(from.vertices.begin(), from.vertices.end());
  to.normals.assign(from.normals.begin(), from.normals.end());
  to.intensities.assign(from.intensities.begin(), from.intensities.end());
  to.triangles.assign(from.triangles.begin(), from.triangles.end());
  to.vertex_edges.assign(from.vertex_edges.begin(), from.vertex_edges.end());
}

// Meshes one block at a time; one per thread, so its buffers are reused.
//
// The block's voxels and the first three voxel layers of its +1 neighbours
// are copied into one dense padded array: the cubes on the far faces need
// one layer, the one-sided gradient at the far face two more.
class BlockMesher {
 public:
  // A chunk of its own, copied once at its size from the reused buffers
  // build() fills: growing five fresh vectors per chunk cost more
  // allocations than the copy.
  MeshChunk mesh(const VoxelBlockGrid& grid, const VoxelBlock& block, const MeshOptions& options) {
    MeshChunk result;
    copyChunk(build(grid, block, options), result);
    return result;
  }

  // The block's chunk in the mesher's own buffers, valid until the next call.
  const MeshChunk& build(const VoxelBlockGrid& grid, const VoxelBlock& block, const MeshOptions& options) {
    MeshChunk& chunk = scratch_;
    chunk.key = block.key;
    chunk.block_edge = grid.blockEdge();
    chunk.vertices.clear();
    chunk.normals.clear();
    chunk.intensities.clear();
    chunk.triangles.clear();
    chunk.vertex_edges.clear();
    if (!load(grid, block, options)) return chunk;
    const MarchingCubesCases& cases = MarchingCubesCases::instance();
    std::array<int, 8> corner_offset;
    for (int c = 0; c < 8; ++c)
      corner_offset[c] = (c & 1) * stride_[0] + ((c >> 1) & 1) * stride_[1] + (c >> 2) * stride_[2];
    const int edge = edge_;
    const uint32_t cube_bits = (1u << edge) - 1u;
    for (int z = 0; z < edge; ++z)
      for (int y = 0; y < edge; ++y) {
        // Bit x: cube (x, y, z) has all 8 corners observed and both signs.
        // Most cubes of a surface block have one sign: they cost a few bit
        // operations per row here instead of 8 reads each.
        const int row = y + padded_ * z;
        const uint32_t observed = observed_bits_[row] & observed_bits_[row + 1] & observed_bits_[row + padded_] &
                                  observed_bits_[row + padded_ + 1];
        const uint32_t any_negative = negative_bits_[row] | negative_bits_[row + 1] |
                                      negative_bits_[row + padded_] | negative_bits_[row + padded_ + 1];
        const uint32_t all_negative = negative_bits_[row] & negative_bits_[row + 1] &
                                      negative_bits_[row + padded_] & negative_bits_[row + padded_ + 1];
        uint32_t active = observed & (observed >> 1) & (any_negative | (any_negative >> 1)) &
                          ~(all_negative & (all_negative >> 1)) & cube_bits;
        for (; active != 0; active &= active - 1) {
          const int x = __builtin_ctz(active);
          // Corner c = x + 2 y + 4 z offset: two bits from each of the four rows.
          const int corner_signs = int((negative_bits_[row] >> x) & 3u) |
                                   int((negative_bits_[row + 1] >> x) & 3u) << 2 |
                                   int((negative_bits_[row + padded_] >> x) & 3u) << 4 |
                                   int((negative_bits_[row + padded_ + 1] >> x) & 3u) << 6;
          int decisions = 0;
          if (cases.ambiguousFaceCount(corner_signs) > 0) {  // few cubes: the values only then
            const int base = paddedIndex(x, y, z);
            std::array<float, 8> value;
            for (int c = 0; c < 8; ++c) value[c] = sdf_[base + corner_offset[c]];
            decisions = faceDecisions(cases, corner_signs, value);
          }
          const MarchingCubesCases::Triangles triangles = cases.triangles(corner_signs, decisions);
          const Eigen::Vector3i cube(x, y, z);
          // Most cube edges were cut by an earlier cube: a lookup, by the
          // cube's first local edge plus the cube edge's offset from it.
          const int cube_local_edge = 3 * (x + (edge + 1) * (y + (edge + 1) * z));
          const auto vertexOnCubeEdge = [&](int cube_edge) {
            const int local_edge = cube_local_edge + cube_edge_offset_[cube_edge];
            const int vertex = vertex_of_edge_[local_edge];
            if (vertex >= 0) return vertex;
            const CubeEdge& edge_of_cube = cases.edges()[cube_edge];
            const int c = edge_of_cube.lower_corner;
            return newVertex(cube + Eigen::Vector3i(c & 1, (c >> 1) & 1, c >> 2), edge_of_cube.axis, local_edge);
          };
          int interior = -1;
          if (triangles.interior_loop_size > 0) {
            const int loop_begin = int(loop_vertices_.size());
            for (int i = 0; i < triangles.interior_loop_size; ++i)
              loop_vertices_.push_back(vertexOnCubeEdge(triangles.interior_loop[i]));
            interior = int(vertices_.size());
            vertices_.push_back({cube, kInterior, loop_begin, triangles.interior_loop_size});
          }
          for (int t = 0; t < triangles.count; ++t) {
            Eigen::Vector3i triangle;
            for (int corner = 0; corner < 3; ++corner) {
              const uint8_t cube_edge = triangles.edges[3 * t + corner];
              triangle[corner] = cube_edge == MarchingCubesCases::kInteriorVertex
                                     ? interior
                                     : vertexOnCubeEdge(cube_edge);
            }
            chunk.triangles.push_back(triangle);
          }
        }
      }
    for (int local_edge : vertex_local_edges_) vertex_of_edge_[local_edge] = -1;
    vertex_local_edges_.clear();
    placeVertices(grid, block.key, chunk);
    vertices_.clear();
    loop_vertices_.clear();
    return chunk;
  }

 private:
  // Per vertex of the current chunk, what placeVertices needs: the lower
  // lattice point and axis of its edge, or (axis kInterior) its cube and its
  // loop's vertices in loop_vertices_.
  static constexpr int kInterior = 3;
  struct VertexPlace {
    Eigen::Vector3i point;
    int axis, loop_begin, loop_size;
  };

  int paddedIndex(int x, int y, int z) const { return x + row_ * (y + padded_ * z); }

  // Fills the padded arrays; false when the block cannot produce a triangle.
  bool load(const VoxelBlockGrid& grid, const VoxelBlock& block, const MeshOptions& options) {
    edge_ = grid.blockEdge();
    padded_ = edge_ + 3;
    row_ = (padded_ + 3) & ~3;
    stride_ = {1, row_, row_ * padded_};
    with_intensity_ = grid.options().store_intensity;
    const std::size_t padded_voxels = std::size_t(row_) * padded_ * padded_;
    sdf_.resize(padded_voxels);
    if (with_intensity_) intensity_.resize(padded_voxels);
    vertex_of_edge_.resize(3 * std::size_t(edge_ + 1) * (edge_ + 1) * (edge_ + 1), -1);
    const MarchingCubesCases& cases = MarchingCubesCases::instance();
    for (int cube_edge = 0; cube_edge < 12; ++cube_edge) {
      const int c = cases.edges()[cube_edge].lower_corner;
      cube_edge_offset_[cube_edge] =
          cases.edges()[cube_edge].axis + 3 * ((c & 1) + (edge_ + 1) * (((c >> 1) & 1) + (edge_ + 1) * (c >> 2)));
    }
    const std::size_t lattice_points = std::size_t(edge_ + 1) * (edge_ + 1) * (edge_ + 1);
    if (gradients_.size() != lattice_points) {
      gradients_.assign(lattice_points, Eigen::Vector3f::Zero());
      gradient_chunk_.assign(lattice_points, 0u);
      chunk_number_ = 0;
    }
    if (++chunk_number_ == 0) {  // wrapped: forget every cached gradient
      std::fill(gradient_chunk_.begin(), gradient_chunk_.end(), 0u);
      chunk_number_ = 1;
    }

    const std::size_t voxels = std::size_t(grid.voxelsPerBlock());
    checkBlockArrays(block, voxels, with_intensity_);
    neighbours_[0] = &block;
    for (int neighbour = 1; neighbour < 8; ++neighbour) {
      const Eigen::Vector3i offset(neighbour & 1, (neighbour >> 1) & 1, neighbour >> 2);
      neighbours_[neighbour] = grid.find(block.key + offset);
      if (neighbours_[neighbour]) checkBlockArrays(*neighbours_[neighbour], voxels, with_intensity_);
    }
    const float min_weight = options.min_weight;
    observed_bits_.assign(std::size_t(padded_) * padded_, 0u);
    negative_bits_.assign(std::size_t(padded_) * padded_, 0u);
    uint32_t any_negative = 0, any_positive = 0;
    for (int neighbour = 0; neighbour < 8; ++neighbour) {
      // The block's own voxels are in (neighbour 0 comes first): without an
      // observed one no cube can be meshed; with one sign only, the first
      // layer of the +1 neighbours decides before they are copied.
      if (neighbour == 1 && !(any_negative != 0 && any_positive != 0)) {
        if (any_negative == 0 && any_positive == 0) return false;
        if (!neighboursCrossZero(any_negative != 0 ? 1 : 2, min_weight)) return false;
      }
      const VoxelBlock* source = neighbours_[neighbour];
      if (!source) continue;  // its bits stay 0: unobserved
      const Eigen::Vector3i offset(neighbour & 1, (neighbour >> 1) & 1, neighbour >> 2);
      const Eigen::Vector3i begin = offset * edge_;
      Eigen::Vector3i end;
      for (int axis = 0; axis < 3; ++axis) end[axis] = offset[axis] == 0 ? edge_ : padded_;
      const int run = end.x() - begin.x();
      const uint32_t in_run = run >= 32 ? ~0u : (1u << run) - 1u;
      const int first_row = begin.y() + padded_ * begin.z();
      // Raw pointers: the compiler cannot tell the stores from the vectors' own members otherwise.
      float* const sdf_out = sdf_.data() + paddedIndex(begin.x(), begin.y(), begin.z());
      float* const intensity_out =
          with_intensity_ ? intensity_.data() + paddedIndex(begin.x(), begin.y(), begin.z()) : nullptr;
      const float* const intensity_in = with_intensity_ ? source->intensity.data() : nullptr;
      // A run of 3 (a +1 neighbour across x) is one group: it reads one value
      // past its end (still inside the block's arrays, as the run starts a
      // row) and writes one into the padded row's spare slot (row_).
      const auto region = [&](auto groups, auto with_intensity) {
        loadRegion<decltype(groups)::value, decltype(with_intensity)::value>(
            source->sdf.data(), source->weight.data(), intensity_in, edge_, end.y() - begin.y(),
            end.z() - begin.z(), row_, padded_, min_weight, in_run, begin.x(), sdf_out, intensity_out,
            observed_bits_.data() + first_row, negative_bits_.data() + first_row, any_negative, any_positive);
      };
      const auto withGroups = [&](auto with_intensity) {
        switch ((run + 3) / 4) {  // runs of 3, 8 or 16 (block edges are 8 or 16)
          case 1: region(std::integral_constant<int, 1>(), with_intensity); break;
          case 2: region(std::integral_constant<int, 2>(), with_intensity); break;
          default: region(std::integral_constant<int, 4>(), with_intensity); break;
        }
      };
      if (with_intensity_)
        withGroups(std::true_type());
      else
        withGroups(std::false_type());
    }
    const bool has_negative = any_negative != 0, has_positive = any_positive != 0;
    return has_negative && has_positive;
  }

  // Whether the first layer of the +1 neighbours (what the block's cubes
  // read beyond its own voxels) holds an observed value of the sign the
  // block lacks (`signs` bit 0: the block has an observed negative value,
  // bit 1: an observed non-negative one); if not, no cube has a zero
  // crossing. Most blocks of a map hold none (free space, or wholly behind a
  // surface): this look costs far less than copying the neighbours.
  bool neighboursCrossZero(int signs, float min_weight) const {
    const auto look = [&](const float* sdf, const float* weight, int begin, int end) {
      for (int i = begin; i < end; i += 32) {
        uint32_t observed, negative;
        voxelRowBits(sdf + i, weight + i, std::min(32, end - i), min_weight, observed, negative);
        // Observed values are finite: not negative means >= 0.
        signs |= int((observed & negative) != 0) | int((observed & ~negative) != 0) << 1;
      }
    };
    for (int neighbour = 1; neighbour < 8; ++neighbour) {
      const Eigen::Vector3i offset(neighbour & 1, (neighbour >> 1) & 1, neighbour >> 2);
      const VoxelBlock* source = neighbours_[neighbour];
      if (!source) continue;
      // The neighbour's voxels at index 0 along each axis where it lies above.
      const float* sdf = source->sdf.data();
      const float* weight = source->weight.data();
      const int y_end = offset.y() ? 1 : edge_, z_end = offset.z() ? 1 : edge_, x_end = offset.x() ? 1 : edge_;
      for (int z = 0; z < z_end; ++z)
        for (int y = 0; y < y_end; ++y) {
          const int row = edge_ * (y + edge_ * z);
          look(sdf, weight, row, row + x_end);
        }
      if (signs == 3) return true;
    }
    return false;
  }

  // Asymptotic decider: on a face with diagonal negative corners, the
  // bilinear interpolant's saddle is negative (the negative corners connect)
  // when their product outweighs the positive diagonal's. Both cubes of the
  // face multiply the same two values, so they decide alike.
  static int faceDecisions(const MarchingCubesCases& cases, int corner_signs,
                           const std::array<float, 8>& value) {
    int decisions = 0;
    for (int i = 0; i < cases.ambiguousFaceCount(corner_signs); ++i) {
      const std::array<int, 4>& q = cases.faces()[cases.ambiguousFace(corner_signs, i)];
      const int first_negative = value[q[0]] < 0.0f ? 0 : 1;
      const float negative_product = value[q[first_negative]] * value[q[first_negative + 2]];
      const float positive_product = value[q[1 - first_negative]] * value[q[3 - first_negative]];
      if (negative_product > positive_product) decisions |= 1 << i;
    }
    return decisions;
  }

  // SDF derivative along one axis at a lattice point (padded index `index`),
  // in SDF units per voxel, from which of its neighbours along the axis are
  // observed (`minus`: the one below, never read at a block's lower face;
  // `plus`, `plus2`: one and two above). Central where both neighbours are
  // observed; never reading below a block's lower face keeps what a chunk
  // reads within its block and the +1 neighbours, so the value does not
  // depend on which chunk asks.
  float derivative(int index, int step, bool minus, bool plus, bool plus2) const {
    if (minus && plus) return 0.5f * (sdf_[index + step] - sdf_[index - step]);
    if (plus) {
      if (plus2)  // second order, as accurate as the central difference
        return 0.5f * (-3.0f * sdf_[index] + 4.0f * sdf_[index + step] - sdf_[index + 2 * step]);
      return sdf_[index + step] - sdf_[index];
    }
    if (minus) return sdf_[index] - sdf_[index - step];
    return 0.0f;
  }

  // A lattice point ends up to 6 cut edges: its gradient is computed once per chunk.
  const Eigen::Vector3f& gradient(const Eigen::Vector3i& point) {
    const int index = point.x() + (edge_ + 1) * (point.y() + (edge_ + 1) * point.z());
    if (gradient_chunk_[index] != chunk_number_) {
      gradient_chunk_[index] = chunk_number_;
      const int x = point.x(), row = point.y() + padded_ * point.z();
      const int padded_index = x + row_ * row;
      const uint32_t* const observed = observed_bits_.data();
      const uint32_t here = observed[row];
      const auto bit = [](uint32_t bits, int at) { return ((bits >> at) & 1u) != 0; };
      // Along y and z the neighbours are other rows (padded_ rows per z layer).
      const auto along = [&](int coordinate, int row_step, int step) {
        const bool minus = coordinate != 0 && coordinate != edge_ && bit(observed[row - row_step], x);
        return derivative(padded_index, step, minus, bit(observed[row + row_step], x),
                          bit(observed[row + 2 * row_step], x));
      };
      const bool minus_x = x != 0 && x != edge_ && bit(here, x - 1);
      gradients_[index] = {derivative(padded_index, 1, minus_x, bit(here, x + 1), bit(here, x + 2)),
                           along(point.y(), 1, stride_[1]), along(point.z(), padded_, stride_[2])};
    }
    return gradients_[index];
  }

  // The chunk's vertex on the lattice edge from `lower` (padded coordinates)
  // along `axis` (local_edge: axis + 3 * lattice index of `lower`), which
  // has none yet. Only its place in the chunk is decided here: placeVertices
  // computes every vertex after the cube walk, in a loop whose iterations
  // do not wait on one another (square roots and divisions overlap).
  int newVertex(const Eigen::Vector3i& lower, int axis, int local_edge) {
    const int vertex = int(vertices_.size());
    vertex_of_edge_[local_edge] = vertex;
    vertex_local_edges_.push_back(local_edge);
    vertices_.push_back({lower, axis, 0, 0});
    return vertex;
  }

  // Position, normal, intensity and name of every vertex of the chunk, in
  // vertex order (an interior vertex comes after its loop's vertices).
  void placeVertices(const VoxelBlockGrid& grid, const BlockKey& key, MeshChunk& chunk) {
    const std::size_t count = vertices_.size();
    chunk.vertices.resize(count);
    chunk.normals.resize(count);
    if (with_intensity_) chunk.intensities.resize(count);
    chunk.vertex_edges.resize(count);
    Eigen::Vector3f* const positions = chunk.vertices.data();
    Eigen::Vector3f* const normals = chunk.normals.data();
    float* const intensities = chunk.intensities.data();
    LatticeEdge* const names = chunk.vertex_edges.data();
    const double voxel_size = grid.voxelSize();
    for (std::size_t v = 0; v < count; ++v) {
      const VertexPlace& place = vertices_[v];
      if (place.axis == kInterior)
        interiorVertex(key, place, positions, normals, intensities, names, v);
      else
        edgeVertex(key, place.point, place.axis, voxel_size, positions[v], normals[v],
                   with_intensity_ ? &intensities[v] : nullptr, names[v]);
    }
  }

  // The vertex on the lattice edge from `lower` along `axis`.
  void edgeVertex(const BlockKey& key, const Eigen::Vector3i& lower, int axis, double voxel_size,
                  Eigen::Vector3f& position_out, Eigen::Vector3f& normal_out, float* intensity_out,
                  LatticeEdge& name) {
    const Eigen::Vector3i upper = lower + Eigen::Vector3i::Unit(axis);
    const int lower_index = paddedIndex(lower.x(), lower.y(), lower.z());
    const int upper_index = lower_index + stride_[axis];
    const float lower_sdf = sdf_[lower_index], upper_sdf = sdf_[upper_index];
    // The signs differ, so the denominator is not zero.
    const float t = std::clamp(lower_sdf / (lower_sdf - upper_sdf), 0.0f, 1.0f);

    // From global lattice coordinates, so every chunk computes the same bits.
    const Eigen::Matrix<int64_t, 3, 1> lattice =
        key.cast<int64_t>() * int64_t(edge_) + lower.cast<int64_t>();
    Eigen::Vector3d position = lattice.cast<double>();
    position[axis] += double(t);
    position_out = (position * voxel_size).cast<float>();

    Eigen::Vector3f normal = (1.0f - t) * gradient(lower) + t * gradient(upper);
    const float length = normal.norm();
    if (length > 0.0f && std::isfinite(length))
      normal /= length;
    else  // a flat or unobserved neighbourhood: the edge itself points to free space
      normal = Eigen::Vector3f::Unit(axis) * (upper_sdf > lower_sdf ? 1.0f : -1.0f);
    normal_out = normal;

    if (intensity_out) *intensity_out = (1.0f - t) * intensity_[lower_index] + t * intensity_[upper_index];

    // Name the edge by the block holding its lower end (a far-face edge
    // belongs to the +1 neighbour).
    Eigen::Vector3i voxel = lower;
    for (int a = 0; a < 3; ++a)
      if (voxel[a] == edge_) {
        voxel[a] = 0;
        name.block[a] = key[a] + 1;
      } else {
        name.block[a] = key[a];
      }
    name.index = axis + 3 * (voxel.x() + edge_ * (voxel.y() + edge_ * voxel.z()));
  }

  // The extra vertex (number v) of a cube whose iso-line loop is fanned
  // around its mean; named after the cube, so it is never welded.
  void interiorVertex(const BlockKey& key, const VertexPlace& place, Eigen::Vector3f* positions,
                      Eigen::Vector3f* normals, float* intensities, LatticeEdge* names, std::size_t v) const {
    Eigen::Vector3f position = Eigen::Vector3f::Zero(), normal = Eigen::Vector3f::Zero();
    float intensity = 0.0f;
    const int* const loop = loop_vertices_.data() + place.loop_begin;
    for (int i = 0; i < place.loop_size; ++i) {
      position += positions[loop[i]];
      normal += normals[loop[i]];
      if (with_intensity_) intensity += intensities[loop[i]];
    }
    const float count = float(place.loop_size);
    positions[v] = position / count;
    const float length = normal.norm();
    normals[v] = length > 0.0f ? Eigen::Vector3f(normal / length) : normals[loop[0]];
    if (with_intensity_) intensities[v] = intensity / count;
    const Eigen::Vector3i& cube = place.point;
    names[v].block = key;
    names[v].index = 3 * edge_ * edge_ * edge_ + cube.x() + edge_ * (cube.y() + edge_ * cube.z());
  }

  // padded_: voxels per padded edge; row_: floats per x run in sdf_ and
  // intensity_ (padded_ rounded up to whole groups of four, see load).
  int edge_ = 0, padded_ = 0, row_ = 0;
  std::array<int, 3> stride_{};
  bool with_intensity_ = false;
  std::vector<float> sdf_, intensity_;
  // Per padded (y, z) row, bit x: the voxel is observed / its SDF is negative.
  std::vector<uint32_t> observed_bits_, negative_bits_;
  std::array<const VoxelBlock*, 8> neighbours_{};  // the block and its +1 neighbours (nullptr: absent)
  MeshChunk scratch_;
  // Gradients at the lattice points [0, edge]^3, valid where gradient_chunk_ holds chunk_number_.
  std::vector<Eigen::Vector3f> gradients_;
  std::vector<uint32_t> gradient_chunk_;
  uint32_t chunk_number_ = 0;
  std::vector<int> vertex_of_edge_;      // local lattice edge -> vertex of the current chunk
  std::array<int, 12> cube_edge_offset_{};  // a cube edge's local lattice edge minus the cube's first
  std::vector<int> vertex_local_edges_;  // what to reset after the chunk
  std::vector<VertexPlace> vertices_;
  std::vector<int> loop_vertices_;  // the interior vertices' loops, one after another
};

// Whether another chunk's cubes may cut the lattice edge a vertex of this
// chunk is named after: the four cubes around an edge along `axis` lie in the
// chunk's block unless the edge's lower end is on one of the block's lower
// faces across that axis, or in a +1 neighbour.
bool mayBeShared(const BlockKey& key, int edge, const LatticeEdge& name) {
  // Block edges are 8 or 16 voxels (VoxelBlockGridOptions::validate): shifts, not divisions.
  if ((edge != 8 && edge != 16) || name.block != key) return true;
  if (name.index >= 3 * edge * edge * edge) return false;  // a cube's interior vertex
  const int bits = edge == 8 ? 3 : 4, mask = edge - 1;
  const int axis = name.index % 3, voxel = name.index / 3;
  const int lower[3] = {voxel & mask, (voxel >> bits) & mask, voxel >> (2 * bits)};
  for (int other = 0; other < 3; ++other)
    if (other != axis && lower[other] == 0) return true;
  return false;
}

// One mesh from chunks in the given order; the first chunk that cut a
// lattice edge provides its vertex. One thread, with a hash map of names:
// for chunks whose block edge is not known (weldChunks below is the
// parallel weld of meshBlock's chunks, with the same result).
TriangleMesh weldChunksByName(const std::vector<const MeshChunk*>& chunks) {
  TriangleMesh mesh;
  std::size_t vertex_count = 0, triangle_count = 0;
  bool with_intensity = false, all_with_intensity = true;
  for (const MeshChunk* chunk : chunks) {
    vertex_count += chunk->vertices.size();
    triangle_count += chunk->triangles.size();
    if (chunk->vertices.empty()) continue;
    const bool has = chunk->intensities.size() == chunk->vertices.size();
    with_intensity = with_intensity || has;
    all_with_intensity = all_with_intensity && has;
  }
  with_intensity = with_intensity && all_with_intensity;
  mesh.vertices.reserve(vertex_count);
  mesh.normals.reserve(vertex_count);
  if (with_intensity) mesh.intensities.reserve(vertex_count);
  mesh.triangles.reserve(triangle_count);

  tsl::robin_map<LatticeEdge, int, LatticeEdgeHash> vertex_of_edge;
  vertex_of_edge.reserve(vertex_count / 2);  // about the share of vertices on block faces
  std::vector<int> remap;
  for (const MeshChunk* chunk : chunks) {
    if (chunk->vertex_edges.size() != chunk->vertices.size() ||
        chunk->normals.size() != chunk->vertices.size())
      throw MappingError("marching cubes: chunk " + keyText(chunk->key) +
                         " has vertices, normals and lattice edges of different counts");
    remap.resize(chunk->vertices.size());
    for (std::size_t v = 0; v < chunk->vertices.size(); ++v) {
      // Only edges on a block's faces are cut by two chunks: the others skip the hash map.
      if (mayBeShared(chunk->key, chunk->block_edge, chunk->vertex_edges[v])) {
        const auto [found, inserted] =
            vertex_of_edge.try_emplace(chunk->vertex_edges[v], int(mesh.vertices.size()));
        remap[v] = found->second;
        if (!inserted) continue;
      } else {
        remap[v] = int(mesh.vertices.size());
      }
      mesh.vertices.push_back(chunk->vertices[v]);
      mesh.normals.push_back(chunk->normals[v]);
      if (with_intensity) mesh.intensities.push_back(chunk->intensities[v]);
    }
    for (const Eigen::Vector3i& triangle : chunk->triangles)
      mesh.triangles.emplace_back(remap[triangle[0]], remap[triangle[1]], remap[triangle[2]]);
  }
  return mesh;
}

bool nameLess(const LatticeEdge& a, const LatticeEdge& b) {
  return std::array<int, 4>{a.block.x(), a.block.y(), a.block.z(), a.index} <
         std::array<int, 4>{b.block.x(), b.block.y(), b.block.z(), b.index};
}

// A vertex other chunks may share (mayBeShared): its name and its index in the chunk.
using SharedVertex = std::pair<LatticeEdge, int>;

// What the weld reads of a chunk: its arrays (a MeshChunk's, or those of a
// chunk kept in a ChunkArena) and its vertices other chunks may share,
// sorted by name (the weld looks a name up there in the chunks around it).
struct ChunkView {
  BlockKey key = BlockKey::Zero();
  std::size_t vertex_count = 0, triangle_count = 0, shared_count = 0;
  bool with_intensity = false;
  const Eigen::Vector3f* vertices = nullptr;
  const Eigen::Vector3f* normals = nullptr;
  const float* intensities = nullptr;
  const Eigen::Vector3i* triangles = nullptr;
  const SharedVertex* shared = nullptr;
};

// The chunk's shared vertices, sorted by name, into `out` (cleared first).
void sharedVertices(const MeshChunk& chunk, std::vector<SharedVertex>& out) {
  out.clear();
  for (std::size_t v = 0; v < chunk.vertex_edges.size(); ++v)
    if (mayBeShared(chunk.key, chunk.block_edge, chunk.vertex_edges[v])) out.emplace_back(chunk.vertex_edges[v], int(v));
  std::sort(out.begin(), out.end(), [](const SharedVertex& a, const SharedVertex& b) { return nameLess(a.first, b.first); });
}

// The view of a chunk whose arrays have consistent sizes, shared vertices left out.
ChunkView viewOf(const MeshChunk& chunk) {
  if (chunk.vertex_edges.size() != chunk.vertices.size() || chunk.normals.size() != chunk.vertices.size())
    throw MappingError("marching cubes: chunk " + keyText(chunk.key) +
                       " has vertices, normals and lattice edges of different counts");
  ChunkView view;
  view.key = chunk.key;
  view.vertex_count = chunk.vertices.size();
  view.triangle_count = chunk.triangles.size();
  view.with_intensity = chunk.intensities.size() == chunk.vertices.size();
  view.vertices = chunk.vertices.data();
  view.normals = chunk.normals.data();
  view.intensities = chunk.intensities.data();
  view.triangles = chunk.triangles.data();
  return view;
}

// A full extraction's chunks, kept back to back in large segments (one arena
// per thread) instead of five vectors each: tens of MB of fresh memory,
// advised as huge pages, so that first touching it costs one page fault per
// 2 MB instead of one per 4 KB. Only the shared vertices' names are kept.
class ChunkArena {
 public:
  ChunkView keep(const MeshChunk& chunk) {
    ChunkView view = viewOf(chunk);
    sharedVertices(chunk, shared_);
    view.vertices = copy(chunk.vertices);
    view.normals = copy(chunk.normals);
    view.intensities = copy(chunk.intensities);
    view.triangles = copy(chunk.triangles);
    view.shared = copy(shared_);
    view.shared_count = shared_.size();
    return view;
  }

 private:
  static constexpr std::size_t kSegmentBytes = std::size_t(8) << 20;
  static constexpr std::size_t kHugePageBytes = std::size_t(2) << 20;

  template <typename T>
  const T* copy(const std::vector<T>& values) {
    static_assert(alignof(T) <= alignof(std::max_align_t), "segments are aligned for any scalar");
    if (values.empty()) return nullptr;
    const std::size_t bytes = values.size() * sizeof(T);
    std::size_t offset = (used_ + alignof(T) - 1) & ~(alignof(T) - 1);
    if (segments_.empty() || offset + bytes > segment_bytes_) {
      // A chunk is far smaller than a segment (at most ~1 MB for 16^3 blocks).
      segment_bytes_ = std::max(kSegmentBytes, (bytes + kHugePageBytes - 1) & ~(kHugePageBytes - 1));
      void* segment = std::aligned_alloc(kHugePageBytes, segment_bytes_);
      if (!segment) throw std::bad_alloc();
      segments_.emplace_back(static_cast<char*>(segment));
      adviseHugePages(segment, segment_bytes_);
      offset = 0;
    }
    T* out = reinterpret_cast<T*>(segments_.back().get() + offset);
    std::uninitialized_copy(values.begin(), values.end(), out);
    used_ = offset + bytes;
    return out;
  }

  struct Free {
    void operator()(char* segment) const { std::free(segment); }
  };
  std::vector<std::unique_ptr<char, Free>> segments_;
  std::size_t segment_bytes_ = 0, used_ = 0;
  std::vector<SharedVertex> shared_;
};

// weldChunksByName's result on threads: a vertex on a lattice edge can only
// be shared with the chunks of the (up to 4) blocks whose cubes hold that
// edge, so the chunk that provides it (the first of them in the given order
// that cut the edge) is found by looking in those chunks alone; vertices are
// then numbered by prefix sums, in the serial weld's order. Block edges of 8
// or 16 voxels only.
TriangleMesh weldViews(const std::vector<ChunkView>& chunks, int edge) {
  const std::size_t count = chunks.size();
  std::vector<std::size_t> first_vertex(count + 1, 0), first_triangle(count + 1, 0);
  bool with_intensity = true, any_intensity = false;
  for (std::size_t c = 0; c < count; ++c) {
    const ChunkView& chunk = chunks[c];
    first_vertex[c + 1] = first_vertex[c] + chunk.vertex_count;
    first_triangle[c + 1] = first_triangle[c] + chunk.triangle_count;
    if (chunk.vertex_count == 0) continue;
    any_intensity = any_intensity || chunk.with_intensity;
    with_intensity = with_intensity && chunk.with_intensity;
  }
  with_intensity = with_intensity && any_intensity;
  tsl::robin_map<BlockKey, uint32_t, BlockKeyHash> position_of;
  position_of.reserve(count);
  for (std::size_t c = 0; c < count; ++c) position_of.emplace(chunks[c].key, uint32_t(c));

  // Per chunk vertex: its index in the mesh, or (until resolved) -1 - the
  // flat index of the providing chunk's vertex.
  std::vector<int64_t> remap;
  resizeOnHugePages(remap, first_vertex[count]);
  const int bits = edge == 8 ? 3 : 4, mask = edge - 1;
  std::vector<std::size_t> provided(count, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 16), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t c = range.begin(); c != range.end(); ++c) {
      const ChunkView& chunk = chunks[c];
      int64_t* const own = remap.data() + first_vertex[c];
      std::fill(own, own + chunk.vertex_count, 0);  // provided by the chunk itself unless found below
      for (std::size_t s = 0; s < chunk.shared_count; ++s) {
        const LatticeEdge& name = chunk.shared[s].first;
        std::size_t provider = c, provider_vertex = 0;
        // The cubes around the edge lie in its block and, across each
        // other axis where the edge is on the block's lower face, the
        // block below.
        const int axis = name.index % 3, voxel = name.index / 3;
        const int lower[3] = {voxel & mask, (voxel >> bits) & mask, voxel >> (2 * bits)};
        int on_lower_face = 0;
        for (int other = 0; other < 3; ++other)
          if (other != axis && lower[other] == 0) on_lower_face |= 1 << other;
        for (int below = on_lower_face;; below = (below - 1) & on_lower_face) {
          const BlockKey key = name.block - Eigen::Vector3i(below & 1, (below >> 1) & 1, below >> 2);
          const auto found = position_of.find(key);
          if (found != position_of.end() && found->second < provider) {
            const ChunkView& other = chunks[found->second];
            const SharedVertex* const candidates_end = other.shared + other.shared_count;
            const SharedVertex* const match = std::lower_bound(
                other.shared, candidates_end, name, [](const SharedVertex& a, const LatticeEdge& b) { return nameLess(a.first, b); });
            if (match != candidates_end && match->first == name) {
              provider = found->second;
              provider_vertex = std::size_t(match->second);
            }
          }
          if (below == 0) break;
        }
        if (provider != c) own[chunk.shared[s].second] = -1 - int64_t(first_vertex[provider] + provider_vertex);
      }
      std::size_t next = first_vertex[c];
      for (std::size_t v = 0; v < chunk.vertex_count; ++v)
        if (own[v] >= 0) own[v] = int64_t(next++);
      provided[c] = next - first_vertex[c];
    }
  });
  // Mesh indices: chunk c's provided vertices follow those of the chunks before it.
  std::vector<std::size_t> first_provided(count + 1, 0);
  for (std::size_t c = 0; c < count; ++c) first_provided[c + 1] = first_provided[c] + provided[c];
  TriangleMesh mesh;
  resizeOnHugePages(mesh.vertices, first_provided[count]);
  resizeOnHugePages(mesh.normals, first_provided[count]);
  if (with_intensity) resizeOnHugePages(mesh.intensities, first_provided[count]);
  resizeOnHugePages(mesh.triangles, first_triangle[count]);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 16), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t c = range.begin(); c != range.end(); ++c) {
      const ChunkView& chunk = chunks[c];
      const int64_t shift = int64_t(first_provided[c]) - int64_t(first_vertex[c]);
      for (std::size_t v = 0; v < chunk.vertex_count; ++v) {
        int64_t& index = remap[first_vertex[c] + v];
        if (index < 0) continue;
        index += shift;
        mesh.vertices[std::size_t(index)] = chunk.vertices[v];
        mesh.normals[std::size_t(index)] = chunk.normals[v];
        if (with_intensity) mesh.intensities[std::size_t(index)] = chunk.intensities[v];
      }
    }
  });
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 16), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t c = range.begin(); c != range.end(); ++c) {
      const ChunkView& chunk = chunks[c];
      const auto index = [&](int v) {
        const int64_t own = remap[first_vertex[c] + std::size_t(v)];
        return int(own >= 0 ? own : remap[std::size_t(-1 - own)]);  // a provider's entry is never negative
      };
      Eigen::Vector3i* out = mesh.triangles.data() + first_triangle[c];
      for (std::size_t t = 0; t < chunk.triangle_count; ++t) {
        const Eigen::Vector3i& triangle = chunk.triangles[t];
        *out++ = Eigen::Vector3i(index(triangle[0]), index(triangle[1]), index(triangle[2]));
      }
    }
  });
  return mesh;
}

// The parallel weld (weldViews) where every chunk's block edge is 8 or 16
// voxels, the serial one by name otherwise.
TriangleMesh weldChunks(const std::vector<const MeshChunk*>& chunks) {
  const int edge = chunks.empty() ? 8 : chunks.front()->block_edge;
  for (const MeshChunk* chunk : chunks)
    if (chunk->block_edge != edge || (edge != 8 && edge != 16)) return weldChunksByName(chunks);
  std::vector<ChunkView> views;
  views.reserve(chunks.size());
  for (const MeshChunk* chunk : chunks) views.push_back(viewOf(*chunk));
  // The shared vertices of all chunks in one array: chunk c's from first_shared[c].
  std::vector<std::size_t> first_shared(chunks.size() + 1, 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks.size(), 16), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t c = range.begin(); c != range.end(); ++c) {
      const MeshChunk& chunk = *chunks[c];
      for (const LatticeEdge& name : chunk.vertex_edges) first_shared[c + 1] += mayBeShared(chunk.key, edge, name);
    }
  });
  for (std::size_t c = 0; c < chunks.size(); ++c) first_shared[c + 1] += first_shared[c];
  std::vector<SharedVertex> shared;
  resizeOnHugePages(shared, first_shared[chunks.size()]);
  tbb::enumerable_thread_specific<std::vector<SharedVertex>> scratch;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks.size(), 16), [&](const tbb::blocked_range<std::size_t>& range) {
    std::vector<SharedVertex>& sorted = scratch.local();
    for (std::size_t c = range.begin(); c != range.end(); ++c) {
      sharedVertices(*chunks[c], sorted);
      std::copy(sorted.begin(), sorted.end(), shared.begin() + std::ptrdiff_t(first_shared[c]));
      views[c].shared = shared.data() + first_shared[c];
      views[c].shared_count = sorted.size();
    }
  });
  return weldViews(views, edge);
}

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

void MeshOptions::validate() const {
  if (!std::isfinite(min_weight) || min_weight < 0.0f)
    throw MappingError("MeshOptions: min_weight must be finite and >= 0, got " +
                       numberText(min_weight));
  if (!std::isfinite(update_budget_s) || update_budget_s < 0.0)
    throw MappingError("MeshOptions: update_budget_s must be finite and >= 0 (0 = no limit), got " +
                       numberText(update_budget_s));
}

MeshChunk meshBlock(const VoxelBlockGrid& grid, const VoxelBlock& block, const MeshOptions& options) {
  options.validate();
  BlockMesher mesher;
  return mesher.mesh(grid, block, options);
}

TriangleMesh extractMesh(const VoxelBlockGrid& grid, const MeshOptions& options) {
  options.validate();
  std::vector<const VoxelBlock*> blocks = grid.blocks();
  std::sort(blocks.begin(), blocks.end(),
            [](const VoxelBlock* a, const VoxelBlock* b) { return latticeKeyLess(a->key, b->key); });
  std::vector<ChunkView> chunks;
  resizeOnHugePages(chunks, blocks.size());
  struct Worker {
    BlockMesher mesher;
    ChunkArena arena;
  };
  tbb::enumerable_thread_specific<Worker> workers;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks.size(), 4),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      Worker& worker = workers.local();
                      for (std::size_t i = range.begin(); i != range.end(); ++i)
                        chunks[i] = worker.arena.keep(worker.mesher.build(grid, *blocks[i], options));
                    });
  return weldViews(chunks, grid.blockEdge());
}

std::size_t countBoundaryEdges(const std::vector<Eigen::Vector3i>& triangles) {
  // Undirected edges as sorted index pairs; a run of length one is a boundary edge.
  std::vector<uint64_t> edges;
  edges.reserve(3 * triangles.size());
  for (const Eigen::Vector3i& triangle : triangles)
    for (int corner = 0; corner < 3; ++corner) {
      const auto a = uint32_t(triangle[corner]), b = uint32_t(triangle[(corner + 1) % 3]);
      edges.push_back(uint64_t(std::min(a, b)) << 32 | std::max(a, b));
    }
  std::sort(edges.begin(), edges.end());
  std::size_t boundary = 0;
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t end = i + 1;
    while (end < edges.size() && edges[end] == edges[i]) ++end;
    boundary += end - i == 1;
    i = end;
  }
  return boundary;
}

// ---------------------------------------------------------------- MeshExtractor

namespace {

// Blocks re-meshed between two looks at the clock under a time budget:
// enough for both threads to stay busy, few enough to overshoot little.
constexpr std::size_t kBlocksPerBudgetBatch = 64;

// What a block's lower neighbours read of it: BlockMesher::load copies voxel
// layers 0-2 of a +1 neighbour across each axis the neighbour lies above
// along. Per lower neighbour n (bit 0: below along x, bit 1 y, bit 2 z) a
// fingerprint of that region's SDF, weight and intensity bits as the
// neighbour last read it, so any change that can reach its chunk changes it.
// Computed only for neighbours nothing else re-meshes (most lower
// neighbours of a changed block changed too); bit n - 1 of `valid` says
// that entry n - 1 holds what neighbour n read.
struct ReadRegions {
  std::array<uint64_t, 7> fingerprint{};
  uint8_t valid = 0;
};

// Four lanes, word i of a run into lane i % 4: the lanes' multiply chains
// overlap instead of waiting on one another.
class Fingerprint {
 public:
  void add(const float* a, const float* b, int count) {
    int i = 0;
    for (; i + 4 <= count; i += 4)
      for (int lane = 0; lane < 4; ++lane) mix(lane, pair(a, b, i + lane));
    for (int lane = 0; i < count; ++i, ++lane) mix(lane, pair(a, b, i));
  }
  void add(const float* a, int count) {
    int i = 0;
    for (; i + 4 <= count; i += 4)
      for (int lane = 0; lane < 4; ++lane) mix(lane, bits(a + i + lane));
    for (int lane = 0; i < count; ++i, ++lane) mix(lane, bits(a + i));
  }
  uint64_t value() const {
    uint64_t hash = 0x9E3779B97F4A7C15ull;
    for (uint64_t lane : lanes_) hash = step(hash, lane);
    return hash;
  }

 private:
  static uint64_t bits(const float* value) {
    uint32_t word;
    std::memcpy(&word, value, sizeof word);
    return word;
  }
  static uint64_t pair(const float* a, const float* b, int i) { return bits(b + i) << 32 | bits(a + i); }
  // Rotate, mix the word in, multiply by an odd constant: for a given state
  // each step is a bijection of the word, and for a given word one of the
  // state, so one changed word always changes its lane, and a changed lane
  // the final value.
  static uint64_t step(uint64_t state, uint64_t word) {
    return (((state << 23) | (state >> 41)) ^ word) * 0xff51afd7ed558ccdull;
  }
  void mix(int lane, uint64_t word) { lanes_[lane] = step(lanes_[lane], word); }

  std::array<uint64_t, 4> lanes_ = {0x9E3779B97F4A7C15ull, 0xC2B2AE3D27D4EB4Full, 0x165667B19E3779F9ull,
                                    0x27D4EB2F165667C5ull};
};

uint64_t readRegionFingerprint(const VoxelBlock& block, int neighbour, int edge, bool with_intensity) {
  constexpr int kLayers = 3;  // as BlockMesher::load reads
  const int x_end = neighbour & 1 ? kLayers : edge, y_end = neighbour & 2 ? kLayers : edge,
            z_end = neighbour & 4 ? kLayers : edge;
  Fingerprint region;
  for (int z = 0; z < z_end; ++z)
    for (int y = 0; y < y_end; ++y) {
      const int row = edge * (y + edge * z);
      region.add(block.sdf.data() + row, block.weight.data() + row, x_end);
      if (with_intensity) region.add(block.intensity.data() + row, x_end);
    }
  return region.value();
}

}  // namespace

struct MeshExtractor::State {
  tsl::robin_map<BlockKey, MeshChunk, BlockKeyHash> chunks;  // only blocks with triangles
  // Every block of the grid at the last update (a block that is gone
  // changes the border cubes of its lower neighbours even if it had no
  // chunk), with what its lower neighbours last read of it.
  tsl::robin_map<BlockKey, ReadRegions, BlockKeyHash> known_blocks;
  // Blocks to re-mesh, with the grid generation at which they first waited.
  tsl::robin_map<BlockKey, uint64_t, BlockKeyHash> pending;
  // Chunks dropped with their blocks, reported by the next update that
  // completes (one that throws reports nothing).
  std::vector<BlockKey> unreported_removals;
  tbb::enumerable_thread_specific<BlockMesher> meshers;
};

MeshExtractor::MeshExtractor(MeshOptions options)
    : options_(options), state_(std::make_shared<State>()) {
  options_.validate();
}

MeshUpdate MeshExtractor::update(const VoxelBlockGrid& grid, bool force_all) {
  const auto start = std::chrono::steady_clock::now();
  MeshUpdate result;
  State& state = *state_;
  const bool remesh_all = force_all || grid.generation() < meshed_generation_;
  const uint64_t generation = grid.generation();

  const auto lowerNeighbour = [](const BlockKey& key, int neighbour) -> BlockKey {
    return key - Eigen::Vector3i(neighbour & 1, (neighbour >> 1) & 1, neighbour >> 2);
  };
  // A block already waiting keeps its place in the queue.
  const auto mark = [&](const BlockKey& key) {
    if (grid.find(key)) state.pending.try_emplace(key, generation);
  };
  // A reset or replaced grid: what waits refers to blocks that may be gone.
  if (grid.generation() < meshed_generation_) state.pending.clear();
  // Blocks whose cubes read a changed block: itself, and those of its 7 lower
  // neighbours that read a changed part of it.
  // Every block of the map is looked at: both threads test, one collects in
  // order. They count the known blocks still in the grid too: when that is
  // all of them, none is gone, and finding the gone ones is skipped.
  const std::vector<const VoxelBlock*> blocks = grid.blocks();
  // is_changed: bit 0 changed, bit 1 not known before this update.
  std::vector<uint8_t> is_changed(blocks.size());
  std::atomic<std::size_t> known_in_grid{0};
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks.size(), 1024),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      std::size_t known_here = 0;
                      for (std::size_t i = range.begin(); i != range.end(); ++i) {
                        const bool known = state.known_blocks.count(blocks[i]->key) != 0;
                        known_here += known;
                        is_changed[i] = uint8_t(remesh_all || blocks[i]->changed_generation > meshed_generation_ ||
                                                !known) |
                                        uint8_t(!known) << 1;
                      }
                      known_in_grid += known_here;
                    });
  if (known_in_grid < state.known_blocks.size()) {
    std::vector<BlockKey> gone;
    for (const auto& [key, regions] : state.known_blocks)
      if (!grid.find(key)) gone.push_back(key);
    for (const BlockKey& key : gone) {
      state.known_blocks.erase(key);
      state.pending.erase(key);
      if (state.chunks.erase(key)) state.unreported_removals.push_back(key);
      for (int neighbour = 0; neighbour < 8; ++neighbour) mark(lowerNeighbour(key, neighbour));
    }
  }
  std::vector<const VoxelBlock*> changed;
  std::vector<uint8_t> is_new;
  for (std::size_t i = 0; i < blocks.size(); ++i)
    if (is_changed[i]) {
      changed.push_back(blocks[i]);
      is_new.push_back(is_changed[i] >> 1);
    }
  const int edge = grid.blockEdge();
  const bool with_intensity = grid.options().store_intensity;
  const std::size_t voxels = std::size_t(grid.voxelsPerBlock());
  for (const VoxelBlock* block : changed) checkBlockArrays(*block, voxels, with_intensity);
  for (const VoxelBlock* block : changed) state.pending.try_emplace(block->key, generation);  // in the grid: no find
  // A lower neighbour re-meshed anyway (changed itself, or waiting) reads
  // the block as it is, and its fingerprint is not worth computing; the
  // others are re-meshed when their region's fingerprint differs from the
  // one they read (or none is known, or the block is new).
  struct Look {
    const VoxelBlock* block;
    int neighbour;
    bool is_new;
    uint64_t fingerprint;
  };
  // New entries first (one thread: they change the map); then each changed
  // block's own entry and lookups, on both threads; the looks in order.
  std::vector<uint8_t> to_look(changed.size());
  for (std::size_t i = 0; i < changed.size(); ++i)
    if (is_new[i]) state.known_blocks.try_emplace(changed[i]->key);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, changed.size(), 64),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t i = range.begin(); i != range.end(); ++i) {
                        ReadRegions& regions = state.known_blocks.find(changed[i]->key).value();
                        if (remesh_all) regions.valid = 0;
                        uint8_t look = 0;
                        for (int neighbour = 1; neighbour < 8; ++neighbour) {
                          const BlockKey lower = lowerNeighbour(changed[i]->key, neighbour);
                          const uint8_t bit = uint8_t(1u << (neighbour - 1));
                          // Most are waiting (changed too): that map is the smaller one.
                          if (!state.pending.count(lower) && grid.find(lower))
                            look |= bit;
                          else
                            regions.valid &= uint8_t(~bit);
                        }
                        to_look[i] = look;
                      }
                    });
  std::vector<Look> looks;
  for (std::size_t i = 0; i < changed.size(); ++i)
    for (int neighbour = 1; neighbour < 8; ++neighbour)
      if (to_look[i] & (1u << (neighbour - 1))) looks.push_back({changed[i], neighbour, is_new[i] != 0, 0});
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, looks.size(), 64),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t i = range.begin(); i != range.end(); ++i)
                        looks[i].fingerprint = readRegionFingerprint(*looks[i].block, looks[i].neighbour, edge,
                                                                     with_intensity);
                    });
  for (const Look& look : looks) {
    ReadRegions& regions = state.known_blocks.find(look.block->key).value();
    const uint8_t bit = uint8_t(1u << (look.neighbour - 1));
    if (look.is_new || !(regions.valid & bit) || regions.fingerprint[look.neighbour - 1] != look.fingerprint)
      mark(lowerNeighbour(look.block->key, look.neighbour));
    regions.fingerprint[look.neighbour - 1] = look.fingerprint;
    regions.valid |= bit;
  }

  // Oldest first (then by key, so that the order does not depend on the
  // hash), as many as the budget allows.
  std::vector<std::pair<uint64_t, BlockKey>> queue;
  queue.reserve(state.pending.size());
  for (const auto& [key, since] : state.pending) queue.emplace_back(since, key);
  const bool budgeted = !remesh_all && (options_.update_budget_s > 0.0 || options_.max_blocks_per_update > 0);
  // Without a budget by key alone: a block's +1 neighbours then follow it
  // closely, and their voxels are still in cache when they are meshed.
  // Keys are unique, so either order is total and a parallel sort gives the same queue.
  if (budgeted)
    tbb::parallel_sort(queue.begin(), queue.end(), [](const auto& a, const auto& b) {
      return a.first != b.first ? a.first < b.first : latticeKeyLess(a.second, b.second);
    });
  else
    tbb::parallel_sort(queue.begin(), queue.end(),
                       [](const auto& a, const auto& b) { return latticeKeyLess(a.second, b.second); });
  std::size_t take = queue.size();
  if (budgeted && options_.max_blocks_per_update > 0) take = std::min(take, options_.max_blocks_per_update);

  // Meshing may throw (a malformed block): what waited still waits (chunks
  // re-meshed before that hold their new triangles).
  std::vector<MeshChunk> rebuilt;
  std::vector<uint8_t> replaced;
  rebuilt.reserve(take);
  std::size_t done = 0;
  while (done < take) {
    std::size_t batch = take - done;
    if (budgeted && options_.update_budget_s > 0.0) {
      if (done > 0 && secondsSince(start) >= options_.update_budget_s) break;
      batch = std::min(batch, kBlocksPerBudgetBatch);
    }
    rebuilt.resize(done + batch);
    replaced.resize(done + batch, 0);
    // A chunk that replaces a stored one is copied into that one's arrays
    // (finds only: both threads): a block's new chunk is about as large as
    // its last, so it costs no allocation, no fresh memory to fault in and
    // no freeing of the old arrays. New and emptied chunks change the map:
    // one thread, below.
    tbb::parallel_for(tbb::blocked_range<std::size_t>(done, done + batch, 4),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                        BlockMesher& mesher = state.meshers.local();
                        for (std::size_t i = range.begin(); i != range.end(); ++i) {
                          const MeshChunk& built = mesher.build(grid, *grid.find(queue[i].second), options_);
                          if (!built.triangles.empty()) {
                            const auto stored = state.chunks.find(built.key);
                            if (stored != state.chunks.end()) {
                              copyChunk(built, stored.value());
                              replaced[i] = 1;
                              continue;
                            }
                          }
                          copyChunk(built, rebuilt[i]);
                        }
                      });
    done += batch;
  }

  result.removed.swap(state.unreported_removals);
  std::sort(result.removed.begin(), result.removed.end(), latticeKeyLess);
  result.changed.reserve(rebuilt.size());
  // Every waiting block is in the queue: when all of it was meshed, nothing waits.
  const bool all_done = done == queue.size();
  if (all_done) state.pending.clear();
  for (std::size_t i = 0; i < rebuilt.size(); ++i) {
    const BlockKey key = queue[i].second;
    if (!all_done) state.pending.erase(key);
    result.changed.push_back(key);
    if (replaced[i]) continue;
    if (rebuilt[i].triangles.empty())
      state.chunks.erase(key);
    else
      state.chunks.emplace(key, std::move(rebuilt[i]));
  }
  // Without a budget the queue was in key order already.
  if (!std::is_sorted(result.changed.begin(), result.changed.end(), latticeKeyLess))
    std::sort(result.changed.begin(), result.changed.end(), latticeKeyLess);
  result.pending = state.pending.size();
  meshed_generation_ = generation;
  result.seconds = secondsSince(start);
  return result;
}

const MeshChunk* MeshExtractor::chunk(const BlockKey& key) const {
  const auto found = state_->chunks.find(key);
  return found == state_->chunks.end() ? nullptr : &found->second;
}

std::vector<const MeshChunk*> MeshExtractor::chunks() const {
  std::vector<const MeshChunk*> sorted;
  sorted.reserve(state_->chunks.size());
  for (const auto& [key, chunk] : state_->chunks) sorted.push_back(&chunk);
  std::sort(sorted.begin(), sorted.end(),
            [](const MeshChunk* a, const MeshChunk* b) { return latticeKeyLess(a->key, b->key); });
  return sorted;
}

std::size_t MeshExtractor::triangleCount() const {
  std::size_t count = 0;
  for (const auto& [key, chunk] : state_->chunks) count += chunk.triangles.size();
  return count;
}

TriangleMesh MeshExtractor::combined() const { return weldChunks(chunks()); }

std::size_t MeshExtractor::pendingCount() const { return state_->pending.size(); }

void MeshExtractor::clear() {
  state_->chunks.clear();
  state_->known_blocks.clear();
  state_->pending.clear();
  state_->unreported_removals.clear();
  meshed_generation_ = 0;
}

}  // namespace range_image_mapping::mapping
