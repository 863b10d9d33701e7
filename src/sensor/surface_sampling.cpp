#include "range_image_mapping/surface_sampling.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace range_image_mapping {
namespace {

constexpr std::size_t kTrianglesPerTask = 256;

// SplitMix64: independent, reproducible random numbers per triangle.
uint64_t splitMix64(uint64_t state) {
  uint64_t z = state + 0x9E3779B97F4A7C15ull;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}
double unitInterval(uint64_t bits) { return static_cast<double>(bits >> 11) * 0x1.0p-53; }

// One triangle's grid samples. The longest edge is the grid's u axis, so the
// opposite corner projects inside it and every grid row is one interval.
void sampleTriangle(Eigen::Vector3d corners[3], double spacing, uint64_t random_bits,
                    const SurfaceRegion* region, std::vector<Eigen::Vector3f>& samples) {
  int longest = 0;
  for (int edge = 1; edge < 3; ++edge)
    if ((corners[(edge + 1) % 3] - corners[edge]).squaredNorm() >
        (corners[(longest + 1) % 3] - corners[longest]).squaredNorm())
      longest = edge;
  const Eigen::Vector3d& a = corners[longest];
  const Eigen::Vector3d& b = corners[(longest + 1) % 3];
  const Eigen::Vector3d& c = corners[(longest + 2) % 3];
  const double base_length = (b - a).norm();
  if (!(base_length > 0.0)) return;
  const Eigen::Vector3d u_axis = (b - a) / base_length;
  const double apex_u = (c - a).dot(u_axis);
  const Eigen::Vector3d apex_offset = (c - a) - apex_u * u_axis;
  const double apex_v = apex_offset.norm();
  if (!(apex_v > 1e-12 * base_length)) return;  // degenerate: no area
  const Eigen::Vector3d v_axis = apex_offset / apex_v;

  const double offset_u = unitInterval(random_bits) * spacing;
  const double offset_v = unitInterval(splitMix64(random_bits)) * spacing;
  if (offset_v > apex_v) return;
  const int64_t last_row = static_cast<int64_t>(std::floor((apex_v - offset_v) / spacing));
  // Row j at v lies within [u_low(v), u_high(v)]; both are linear in v.
  const auto rowColumns = [&](int64_t row, int64_t& first, int64_t& last) {
    const double t = (offset_v + row * spacing) / apex_v;
    const double low = t * apex_u;
    const double high = base_length + t * (apex_u - base_length);
    first = static_cast<int64_t>(std::ceil((low - offset_u) / spacing));
    last = static_cast<int64_t>(std::floor((high - offset_u) / spacing));
  };
  const auto point = [&](int64_t column, int64_t row) {
    return (a + (offset_u + column * spacing) * u_axis + (offset_v + row * spacing) * v_axis)
        .cast<float>();
  };

  // Square tiles of tile x tile samples; without a region one tile is the triangle.
  const int64_t tile =
      region ? std::max<int64_t>(1, static_cast<int64_t>(region->tileEdge() / spacing)) : last_row + 1;
  const float tile_radius = static_cast<float>((tile - 1) * spacing * M_SQRT1_2 + spacing);
  for (int64_t band = 0; band <= last_row; band += tile) {
    const int64_t band_end = std::min(last_row, band + tile - 1);
    int64_t first_a, last_a, first_b, last_b;
    rowColumns(band, first_a, last_a);
    rowColumns(band_end, first_b, last_b);
    const int64_t band_first = std::min(first_a, first_b);
    const int64_t band_last = std::max(last_a, last_b);
    const int64_t column_tile = region ? tile : band_last - band_first + 1;
    for (int64_t tile_first = band_first; tile_first <= band_last; tile_first += column_tile) {
      const int64_t tile_last = tile_first + column_tile - 1;
      if (region) {
        const Eigen::Vector3f centre =
            ((point(tile_first, band).cast<double>() + point(tile_last, band_end).cast<double>()) / 2)
                .cast<float>();
        if (!region->mayBeNear(centre, tile_radius)) continue;
      }
      for (int64_t row = band; row <= band_end; ++row) {
        int64_t first, last;
        rowColumns(row, first, last);
        for (int64_t column = std::max(first, tile_first); column <= std::min(last, tile_last);
             ++column) {
          const Eigen::Vector3f sample = point(column, row);
          if (region == nullptr || region->isNear(sample)) samples.push_back(sample);
        }
      }
    }
  }
}

std::vector<Eigen::Vector3f> sample(const TriangleMesh& mesh, const SurfaceSampleOptions& options,
                                    const SurfaceRegion* region) {
  if (!(options.spacing_m > 0.0) || !std::isfinite(options.spacing_m))
    throw std::invalid_argument("surface sampling: spacing_m " + std::to_string(options.spacing_m) +
                                " must be positive and finite");
  const std::size_t vertex_count = mesh.vertices.size();
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
    for (int corner = 0; corner < 3; ++corner)
      if (mesh.triangles[t][corner] < 0 ||
          static_cast<std::size_t>(mesh.triangles[t][corner]) >= vertex_count)
        throw std::invalid_argument("surface sampling: triangle " + std::to_string(t) +
                                    " has vertex index " + std::to_string(mesh.triangles[t][corner]) +
                                    ", the mesh has " + std::to_string(vertex_count) + " vertices");

  // Fixed chunks, concatenated in order: the result does not depend on the threads.
  const std::size_t tasks = (mesh.triangles.size() + kTrianglesPerTask - 1) / kTrianglesPerTask;
  std::vector<std::vector<Eigen::Vector3f>> chunks(tasks);
  const uint64_t seed_bits = splitMix64(options.seed);
  tbb::parallel_for(std::size_t{0}, tasks, [&](std::size_t task) {
    const std::size_t end = std::min(mesh.triangles.size(), (task + 1) * kTrianglesPerTask);
    for (std::size_t t = task * kTrianglesPerTask; t < end; ++t) {
      const Eigen::Vector3i& triangle = mesh.triangles[t];
      Eigen::Vector3d corners[3] = {mesh.vertices[triangle[0]].cast<double>(),
                                    mesh.vertices[triangle[1]].cast<double>(),
                                    mesh.vertices[triangle[2]].cast<double>()};
      sampleTriangle(corners, options.spacing_m, splitMix64(seed_bits ^ splitMix64(t)), region,
                     chunks[task]);
    }
  });
  std::size_t total = 0;
  for (const auto& chunk : chunks) total += chunk.size();
  std::vector<Eigen::Vector3f> samples;
  samples.reserve(total);
  for (const auto& chunk : chunks) samples.insert(samples.end(), chunk.begin(), chunk.end());
  return samples;
}

}  // namespace

std::vector<Eigen::Vector3f> sampleSurface(const TriangleMesh& mesh, const SurfaceSampleOptions& options) {
  return sample(mesh, options, nullptr);
}

std::vector<Eigen::Vector3f> sampleSurface(const TriangleMesh& mesh, const SurfaceSampleOptions& options,
                                           const SurfaceRegion& region) {
  return sample(mesh, options, &region);
}

}  // namespace range_image_mapping
