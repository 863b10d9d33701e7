#include "range_image_mapping/normal_map.h"

#include "range_image_mapping/lidar_intrinsics.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>

namespace range_image_mapping {
namespace {

const Eigen::Vector3f kInvalid = Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN());

bool isValidPoint(const Eigen::Vector3f& point) { return std::isfinite(point.x()); }

// Image-domain neighbourhood of one level. Columns are staggered (column =
// measurement id), so the beams of one column look in different azimuths;
// the neighbour of a pixel in another row is the one next to it once
// at the same azimuth (columns apart by the rows' azimuth offsets), not the
// same column. Columns
// wrap around the cylinder, rows do not. A neighbour breaks the surface when
// its range differs from the centre's by more than the allowed jump for its
// distance in full-resolution pixels.
struct LevelNeighbourhood {
  const VertexNormalMap& map;
  ImageView<const float> ranges;  // the image at this level
  float jump_per_pixel;           // max_range_jump_ratio * stride
  float max_chord_offset_m;       // NormalMapOptions::max_chord_offset_m
  // Per level row, the column shift to the same azimuth in each row of the
  // window (row steps -radius..radius), from the rows' azimuth offsets.
  int radius;
  const std::vector<int>& row_shifts;

  int wrapColumn(int column) const {
    if (unsigned(column) < unsigned(map.columns)) return column;
    column %= map.columns;
    return column < 0 ? column + map.columns : column;
  }
  // Level column in row + row_step next to (row, column) in azimuth.
  int alignedColumn(int row, int row_step, int column) const {
    return column + row_shifts[std::size_t(row) * (2 * radius + 1) + (row_step + radius)];
  }
  // A neighbour's index in the level, or one of these: outside the image or
  // no point there, or across a depth discontinuity. Found once per
  // neighbour: its range decides, its point is then read by index.
  static constexpr std::ptrdiff_t kMissing = -1, kAcrossEdge = -2;
  // What a neighbour's range says, given the largest jump allowed at its
  // distance: kMissing, kAcrossEdge, or 0 (usable).
  static std::ptrdiff_t classify(float range, float centre_range, float max_jump) {
    if (!isValidRange(range)) return kMissing;
    return std::abs(range - centre_range) > max_jump ? kAcrossEdge : 0;
  }
  std::ptrdiff_t neighbour(int row, int row_step, int column, float centre_range, int pixel_distance) const {
    const int neighbour_row = row + row_step;
    if (neighbour_row < 0 || neighbour_row >= map.rows) return kMissing;
    const int neighbour_column = wrapColumn(alignedColumn(row, row_step, column));
    const std::ptrdiff_t kind = classify(ranges(neighbour_row, neighbour_column), centre_range,
                                         jump_per_pixel * pixel_distance * centre_range);
    return kind < 0 ? kind : std::ptrdiff_t(neighbour_row) * map.columns + neighbour_column;
  }
};

// Normals face the sensor: the beam origin is within centimetres of the
// lidar origin, so the sign of n . p decides.
Eigen::Vector3f facingSensor(const Eigen::Vector3f& normal, const Eigen::Vector3f& point) {
  return normal.dot(point) > 0.0f ? Eigen::Vector3f(-normal) : normal;
}

// The five ranges a pixel's cross product reads (its own, its row
// neighbours', the rows' above and below at its azimuth), and their
// validity and range jump as masks (isValidRange and
// LevelNeighbourhood::classify; 0 for NaN).
struct CrossRanges {
  float centre, right, left, up, down, max_jump;
  static int valid(float range) { return int(range > 0.0f) & int(std::abs(range) <= std::numeric_limits<float>::max()); }
  int usable(float range) const { return valid(range) & int(std::abs(range - centre) <= max_jump); }
};
[[gnu::always_inline]] inline CrossRanges crossRanges(const float* centre_ranges, const float* up_ranges,
                                                      const float* down_ranges, int range_step, int up_shift,
                                                      int down_shift, int column, float jump_per_pixel) {
  CrossRanges r;
  r.centre = centre_ranges[std::ptrdiff_t(column) * range_step];
  r.right = centre_ranges[std::ptrdiff_t(column + 1) * range_step];
  r.left = centre_ranges[std::ptrdiff_t(column - 1) * range_step];
  r.up = up_ranges[std::ptrdiff_t(column + up_shift) * range_step];
  r.down = down_ranges[std::ptrdiff_t(column + down_shift) * range_step];
  r.max_jump = jump_per_pixel * r.centre;
  return r;
}

// A pixel's central differences (points as xyz triples): r along the row,
// from its left to its right neighbour, c along the column, from the row
// above to the row below, their lengths, and the points they start from.
struct CrossTangents {
  const float *centre, *left, *up;
  float rx, ry, rz, cx, cy, cz, row_norm, column_norm;
};
[[gnu::always_inline]] inline CrossTangents crossTangents(const float* centre_points, const float* up_points,
                                                          const float* down_points, int up_shift, int down_shift,
                                                          int column) {
  CrossTangents t;
  t.centre = centre_points + 3 * column;
  t.left = centre_points + 3 * (column - 1);
  t.up = up_points + 3 * (column + up_shift);
  const float* right = centre_points + 3 * (column + 1);
  const float* down = down_points + 3 * (column + down_shift);
  t.rx = right[0] - t.left[0], t.ry = right[1] - t.left[1], t.rz = right[2] - t.left[2];
  t.cx = down[0] - t.up[0], t.cy = down[1] - t.up[1], t.cz = down[2] - t.up[2];
  t.row_norm = std::sqrt(t.rx * t.rx + (t.ry * t.ry + t.rz * t.rz));
  t.column_norm = std::sqrt(t.cx * t.cx + (t.cy * t.cy + t.cz * t.cz));
  return t;
}

// The normal of a pixel's tangents (r x c), unit and facing the sensor,
// into out where `reliable` and the tangents are not nearly parallel, else
// NaN: Eigen's cross, and its squaredNorm and dot as it sums three terms,
// x + (y + z). Every value is computed before the selects, so that they
// stay selects.
[[gnu::always_inline]] inline void writeCrossNormal(const CrossTangents& t, int reliable, float* out) {
  const float nx = t.ry * t.cz - t.rz * t.cy, ny = t.rz * t.cx - t.rx * t.cz, nz = t.rx * t.cy - t.ry * t.cx;
  const float norm = std::sqrt(nx * nx + (ny * ny + nz * nz));
  const int kept = int(norm > 1e-3f * t.row_norm * t.column_norm) & reliable;
  const float ux = nx / norm, uy = ny / norm, uz = nz / norm;
  const float sign = ux * t.centre[0] + (uy * t.centre[1] + uz * t.centre[2]) > 0.0f ? -1.0f : 1.0f;
  const float fx = sign * ux, fy = sign * uy, fz = sign * uz;
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  out[0] = kept ? fx : kNaN;
  out[1] = kept ? fy : kNaN;
  out[2] = kept ? fz : kNaN;
}

// The common case of crossProductNormalsOfRow over plain arrays, branch
// free so that it vectorises: a pixel whose four neighbours (its row's next
// columns, and the rows above and below at the same azimuth) all have a
// return within the allowed jump gets the central differences' normal, with
// the same float operations in the same order as the general path (so the
// same bits); done[column] says which pixels it did. Columns [first, last)
// need no wrap; ranges are read every range_step elements, points (xyz
// triples) are the level's. Cloned for AVX2 and AVX-512 (products never
// fused: the libraries are built with -ffp-contract=off).
RANGE_IMAGE_MAPPING_SIMD_CLONES
void interiorCrossProducts(const float* centre_ranges, const float* up_ranges, const float* down_ranges,
                           int range_step, const float* centre_points, const float* up_points,
                           const float* down_points, int up_shift, int down_shift, int first, int last,
                           float jump_per_pixel, float* __restrict normals, uint8_t* __restrict done) {
  for (int column = first; column < last; ++column) {
    const CrossRanges r =
        crossRanges(centre_ranges, up_ranges, down_ranges, range_step, up_shift, down_shift, column, jump_per_pixel);
    const int all = r.valid(r.centre) & r.usable(r.right) & r.usable(r.left) & r.usable(r.up) & r.usable(r.down);
    const CrossTangents t = crossTangents(centre_points, up_points, down_points, up_shift, down_shift, column);
    writeCrossNormal(t, 1, normals + 3 * column);
    done[column] = uint8_t(all);
  }
}

// The common case of crossProductNormalsOfRow's in-line rows (a sensor with
// sparse rows, full resolution), as interiorCrossProducts: a pixel whose row
// neighbours have a return within the allowed jump and whose rows above and
// below have a return (whatever its range) gets the central differences'
// normal if the pixel lies within max_chord_offset of both chords (the
// segment between its row neighbours, and between the rows above and
// below), else none; the general path's arithmetic, to the bit.
RANGE_IMAGE_MAPPING_SIMD_CLONES
void inLineCrossProducts(const float* centre_ranges, const float* up_ranges, const float* down_ranges,
                         int range_step, const float* centre_points, const float* up_points, const float* down_points,
                         int up_shift, int down_shift, int first, int last, float jump_per_pixel,
                         float max_chord_offset, float* __restrict normals, uint8_t* __restrict done) {
  for (int column = first; column < last; ++column) {
    const CrossRanges r =
        crossRanges(centre_ranges, up_ranges, down_ranges, range_step, up_shift, down_shift, column, jump_per_pixel);
    const int all = r.valid(r.centre) & r.usable(r.right) & r.usable(r.left) & r.valid(r.up) & r.valid(r.down);
    const CrossTangents t = crossTangents(centre_points, up_points, down_points, up_shift, down_shift, column);
    // onChord: |(centre - before) x chord| <= max_chord_offset |chord|.
    const auto offset = [&](const float* before, float dx, float dy, float dz) {
      const float ax = t.centre[0] - before[0], ay = t.centre[1] - before[1], az = t.centre[2] - before[2];
      const float ox = ay * dz - az * dy, oy = az * dx - ax * dz, oz = ax * dy - ay * dx;
      return std::sqrt(ox * ox + (oy * oy + oz * oz));
    };
    const int on_chords = int(offset(t.up, t.cx, t.cy, t.cz) <= max_chord_offset * t.column_norm) &
                          int(offset(t.left, t.rx, t.ry, t.rz) <= max_chord_offset * t.row_norm);
    writeCrossNormal(t, on_chords, normals + 3 * column);
    done[column] = uint8_t(all);
  }
}

// Cross-product normals of one level row: the tangent along each image axis
// is the central difference when both neighbours are usable, else the
// one-sided one; none when neither is usable or a neighbour is across a depth
// discontinuity (the pixel sits on an edge, where mixed returns and occlusion
// shadows make the normal unreliable). The row's ranges, points and azimuth
// shifts are looked up once per row: every scan's normals go through here.
// done: a row's worth of scratch.
void crossProductNormalsOfRow(const LevelNeighbourhood& level, int row, Eigen::Vector3f* normals, uint8_t* done) {
  const VertexNormalMap& map = level.map;
  const int columns = map.columns;
  const int range_step = level.ranges.fullColumn(1);  // level column -> element of the full row
  // Row r's ranges and points, and the column shift to the same azimuth in
  // it; null outside the image.
  struct Row {
    const float* ranges = nullptr;
    const Eigen::Vector3f* points = nullptr;
    int shift = 0;
  };
  const auto rowAt = [&](int row_step) {
    Row neighbour;
    const int r = row + row_step;
    if (r < 0 || r >= map.rows) return neighbour;
    neighbour.ranges = &level.ranges(r, 0);
    neighbour.points = map.points.data() + std::size_t(r) * columns;
    neighbour.shift = row_step == 0 ? 0 : level.alignedColumn(row, row_step, 0);
    return neighbour;
  };
  const Row centre_row = rowAt(0), above = rowAt(-1), below = rowAt(1), above2 = rowAt(-2), below2 = rowAt(2);
  // Most pixels first, in the common case's loop; the rest below.
  std::fill(done, done + columns, uint8_t(0));
  const bool in_line = level.max_chord_offset_m > 0.0f && map.stride == 1;
  if (above.ranges && below.ranges) {
    const int first = std::max({1, -above.shift, -below.shift});
    const int last = std::min({columns - 1, columns - above.shift, columns - below.shift});
    if (first < last) {
      if (in_line)
        inLineCrossProducts(centre_row.ranges, above.ranges, below.ranges, range_step, centre_row.points->data(),
                            above.points->data(), below.points->data(), above.shift, below.shift, first, last,
                            level.jump_per_pixel, level.max_chord_offset_m, normals->data(), done);
      else
        interiorCrossProducts(centre_row.ranges, above.ranges, below.ranges, range_step, centre_row.points->data(),
                              above.points->data(), below.points->data(), above.shift, below.shift, first, last,
                              level.jump_per_pixel, normals->data(), done);
    }
  }
  for (int column = 0; column < columns; ++column) {
    if (done[std::size_t(column)]) continue;
    const float centre_range = centre_row.ranges[std::ptrdiff_t(column) * range_step];
    if (!isValidRange(centre_range)) {
      normals[column] = kInvalid;
      continue;
    }
    // LevelNeighbourhood::neighbour at one pixel's distance, from the cached
    // rows: the point, or null when missing; false across a depth discontinuity.
    const float max_jump = level.jump_per_pixel * centre_range;
    const auto neighbour = [&](const Row& at, int neighbour_column, const Eigen::Vector3f*& point,
                               int pixel_distance = 1) {
      point = nullptr;
      if (!at.ranges) return true;
      neighbour_column = level.wrapColumn(neighbour_column + at.shift);
      const std::ptrdiff_t kind = LevelNeighbourhood::classify(
          at.ranges[std::ptrdiff_t(neighbour_column) * range_step], centre_range, max_jump * pixel_distance);
      if (kind == LevelNeighbourhood::kAcrossEdge) return false;
      if (kind == 0) point = at.points + neighbour_column;
      return true;
    };
    const Eigen::Vector3f& centre = centre_row.points[column];
    const auto tangentOf = [&](const Eigen::Vector3f* after, const Eigen::Vector3f* before, Eigen::Vector3f& out) {
      if (after && before)
        out = *after - *before;
      else if (after)
        out = *after - centre;
      else if (before)
        out = centre - *before;
      else
        return false;
      return true;
    };
    const Eigen::Vector3f *right, *left, *down, *up;
    Eigen::Vector3f along_row, along_column = Eigen::Vector3f::Zero();  // (set on every path that reads it)
    // Where both neighbours along an axis are missing, the next ones out: a
    // model with more columns or rows than the sensor fills every scan (an
    // estimated model that keeps the points of beams firing between steps)
    // leaves every other pixel of a row empty.
    const auto farNeighbours = [&](const Row& after_row, int after_column, const Row& before_row,
                                   int before_column, const Eigen::Vector3f*& after,
                                   const Eigen::Vector3f*& before) {
      if (after || before) return true;
      return neighbour(after_row, after_column, after, 2) && neighbour(before_row, before_column, before, 2);
    };
    const auto onChord = [&](const Eigen::Vector3f* after, const Eigen::Vector3f* before) {
      if (!after || !before) return false;
      const Eigen::Vector3f chord = *after - *before;
      return (centre - *before).cross(chord).norm() <= level.max_chord_offset_m * chord.norm();
    };
    // In-line rows: the nearest rows with a return on both sides (the next
    // ones out where both are empty), whatever their ranges.
    if (in_line) {
      const auto point = [&](const Row& at) -> const Eigen::Vector3f* {
        if (!at.ranges) return nullptr;
        const int c = level.wrapColumn(column + at.shift);
        return isValidRange(at.ranges[std::ptrdiff_t(c) * range_step]) ? at.points + c : nullptr;
      };
      down = point(below);
      up = point(above);
      if (!down && !up) {
        down = point(below2);
        up = point(above2);
      }
      if (!onChord(down, up)) {
        normals[column] = kInvalid;
        continue;
      }
      along_column = *down - *up;
    }
    if (!neighbour(centre_row, column + 1, right) || !neighbour(centre_row, column - 1, left) ||
        !farNeighbours(centre_row, column + 2, centre_row, column - 2, right, left) ||
        !tangentOf(right, left, along_row) ||
        (!in_line && (!neighbour(below, column, down) || !neighbour(above, column, up) ||
                      !farNeighbours(below2, column, above2, column, down, up) ||
                      !tangentOf(down, up, along_column))) ||
        (in_line && !onChord(right, left))) {
      normals[column] = kInvalid;
      continue;
    }
    const Eigen::Vector3f normal = along_row.cross(along_column);
    const float norm = normal.norm();
    // Nearly parallel tangents (a surface seen edge-on) have no reliable normal.
    normals[column] = norm > 1e-3f * along_row.norm() * along_column.norm() ? facingSensor(normal / norm, centre)
                                                                            : kInvalid;
  }
}

Eigen::Vector3f covarianceNormal(const LevelNeighbourhood& level, int row, int column, float centre_range,
                                 int radius) {
  // Centred on the pixel's own point so that float sums stay exact enough far
  // from the sensor; the covariance itself is accumulated in double.
  const Eigen::Vector3f& centre = level.map.points[std::size_t(row) * level.map.columns + column];
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d outer = Eigen::Matrix3d::Zero();
  int count = 0;
  for (int dr = -radius; dr <= radius; ++dr) {
    for (int dc = -radius; dc <= radius; ++dc) {
      const std::ptrdiff_t index =
          level.neighbour(row, dr, column + dc, centre_range, std::max(std::abs(dr), std::abs(dc)));
      if (index == LevelNeighbourhood::kAcrossEdge) return kInvalid;  // on an edge, as for the cross product
      if (index < 0) continue;
      const Eigen::Vector3d d = (level.map.points[index] - centre).cast<double>();
      sum += d;
      outer.noalias() += d * d.transpose();
      ++count;
    }
  }
  // At least a row and a column's worth of points, so the window spans a surface.
  if (count < 2 * radius + 3) return kInvalid;
  const Eigen::Vector3d mean = sum / count;
  const Eigen::Matrix3d covariance = outer / count - mean * mean.transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  solver.computeDirect(covariance);
  const Eigen::Vector3d eigenvalues = solver.eigenvalues();  // ascending
  // Points on a line (one beam, or a thin pole seen edge-on): no plane.
  if (!(eigenvalues(1) > 1e-3 * eigenvalues(2)) || !(eigenvalues(1) > 0.0)) return kInvalid;
  const Eigen::Vector3f normal = solver.eigenvectors().col(0).cast<float>().normalized();
  if (!isValidPoint(normal)) return kInvalid;
  return facingSensor(normal, centre);
}

}  // namespace

void computeVertexNormalMap(const RangeImage& image, int stride, const NormalMapOptions& options,
                            VertexNormalMap& out) {
  if (!image.model) throw std::invalid_argument("computeVertexNormalMap: the range image has no sensor model");
  if (image.range.size() != std::size_t(image.rows()) * image.columns()) {
    throw std::invalid_argument("computeVertexNormalMap: the range image holds " +
                                std::to_string(image.range.size()) + " ranges, its model " +
                                std::to_string(image.rows()) + " x " + std::to_string(image.columns()));
  }
  if (image.column_order != ColumnOrder::kStaggered) {
    throw std::invalid_argument("computeVertexNormalMap: the range image is destaggered; geometry needs staggered columns");
  }
  if (stride < 1) throw std::invalid_argument("computeVertexNormalMap: stride must be >= 1, got " + std::to_string(stride));
  if (options.window_radius < 1) {
    throw std::invalid_argument("computeVertexNormalMap: window_radius must be >= 1, got " +
                                std::to_string(options.window_radius));
  }
  if (!(options.max_range_jump_ratio > 0.0f)) {
    throw std::invalid_argument("computeVertexNormalMap: max_range_jump_ratio must be positive");
  }
  if (!(options.max_chord_offset_m >= 0.0f) || !std::isfinite(options.max_chord_offset_m))
    throw std::invalid_argument("computeVertexNormalMap: max_chord_offset_m must be finite and not negative (0: off)");

  const ImageView<const float> view = image.rangeView(stride);
  const LidarModel& model = *image.model;
  out.rows = view.rows();
  out.columns = view.columns();
  out.stride = stride;
  const std::size_t size = std::size_t(out.rows) * out.columns;
  out.points.resize(size);
  out.normals.resize(size);

  tbb::parallel_for(tbb::blocked_range<int>(0, out.rows), [&](const tbb::blocked_range<int>& rows) {
    for (int row = rows.begin(); row != rows.end(); ++row) {
      for (int column = 0; column < out.columns; ++column) {
        const std::size_t i = std::size_t(row) * out.columns + column;
        const float range = view(row, column);
        out.points[i] = isValidRange(range) ? model.unproject(view.fullColumn(column), view.fullRow(row), range)
                                            : kInvalid;
      }
    }
  });

  // Row azimuths from the model's own rays (rather than the destagger shifts,
  // which only approximate them), relative to row 0 and wrapped to half a
  // turn, in full-resolution columns; then the shift between each level row
  // and its window's rows in level columns. The azimuth falls as the column
  // grows: a row that starts further left reaches the same azimuth further
  // right. (Two small allocations per call: thread_local buffers would be
  // overwritten if this thread, waiting in parallel_for below, ran a task
  // that computes another map.)
  std::vector<float> row_azimuth_columns(image.rows());
  const auto azimuthOfRow = [&](int row) {
    const Eigen::Vector3f& direction = model.direction(0, row);
    return std::atan2(double(direction.y()), double(direction.x()));
  };
  const double first_azimuth = azimuthOfRow(0);
  for (int row = 0; row < image.rows(); ++row) {
    const double turn = std::remainder(azimuthOfRow(row) - first_azimuth, 2.0 * M_PI);
    row_azimuth_columns[row] = float(turn * image.columns() / (2.0 * M_PI));
  }
  // The cross product reaches two rows out where the next row is empty.
  const int radius = options.method == NormalMethod::kCrossProduct ? 2 : options.window_radius;
  std::vector<int> row_shifts(std::size_t(out.rows) * (2 * radius + 1), 0);
  for (int row = 0; row < out.rows; ++row) {
    for (int step = -radius; step <= radius; ++step) {
      if (step == 0 || row + step < 0 || row + step >= out.rows) continue;
      const float difference = row_azimuth_columns[std::size_t(row + step) * stride] -
                               row_azimuth_columns[std::size_t(row) * stride];
      row_shifts[std::size_t(row) * (2 * radius + 1) + (step + radius)] = int(std::lround(difference / float(stride)));
    }
  }
  const LevelNeighbourhood level{out, view, options.max_range_jump_ratio * float(stride), options.max_chord_offset_m,
                               radius, row_shifts};
  tbb::parallel_for(tbb::blocked_range<int>(0, out.rows), [&](const tbb::blocked_range<int>& rows) {
    std::vector<uint8_t> done(options.method == NormalMethod::kCrossProduct ? std::size_t(out.columns) : 0);
    for (int row = rows.begin(); row != rows.end(); ++row) {
      if (options.method == NormalMethod::kCrossProduct) {
        crossProductNormalsOfRow(level, row, out.normals.data() + std::size_t(row) * out.columns, done.data());
        continue;
      }
      for (int column = 0; column < out.columns; ++column) {
        const std::size_t i = std::size_t(row) * out.columns + column;
        const float range = view(row, column);
        out.normals[i] = isValidRange(range) ? covarianceNormal(level, row, column, range, options.window_radius)
                                             : kInvalid;
      }
    }
  });
}

}  // namespace range_image_mapping
