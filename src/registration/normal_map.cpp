#include "range_image_mapping/registration/normal_map.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Eigenvalues>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace range_image_mapping::registration {
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
  std::ptrdiff_t neighbour(int row, int row_step, int column, float centre_range, int pixel_distance) const {
    const int neighbour_row = row + row_step;
    if (neighbour_row < 0 || neighbour_row >= map.rows) return kMissing;
    const int neighbour_column = wrapColumn(alignedColumn(row, row_step, column));
    const float range = ranges(neighbour_row, neighbour_column);
    if (!isValidRange(range)) return kMissing;
    if (std::abs(range - centre_range) > jump_per_pixel * pixel_distance * centre_range) return kAcrossEdge;
    return std::ptrdiff_t(neighbour_row) * map.columns + neighbour_column;
  }
};

// Normals face the sensor: the beam origin is within centimetres of the
// lidar origin, so the sign of n . p decides.
Eigen::Vector3f facingSensor(const Eigen::Vector3f& normal, const Eigen::Vector3f& point) {
  return normal.dot(point) > 0.0f ? Eigen::Vector3f(-normal) : normal;
}

// Tangent along one image axis: the central difference when both neighbours
// are usable, else the one-sided one. False when none is usable or a
// neighbour is across a depth discontinuity (the pixel sits on an edge, where
// mixed returns and occlusion shadows make the normal unreliable).
bool tangent(const LevelNeighbourhood& level, int row, int column, int row_step, int column_step,
             float centre_range, Eigen::Vector3f& out) {
  const std::ptrdiff_t after = level.neighbour(row, row_step, column + column_step, centre_range, 1);
  const std::ptrdiff_t before = level.neighbour(row, -row_step, column - column_step, centre_range, 1);
  if (after == LevelNeighbourhood::kAcrossEdge || before == LevelNeighbourhood::kAcrossEdge) return false;
  const std::vector<Eigen::Vector3f>& points = level.map.points;
  const Eigen::Vector3f& centre = points[std::size_t(row) * level.map.columns + column];
  if (after >= 0 && before >= 0) {
    out = points[after] - points[before];
  } else if (after >= 0) {
    out = points[after] - centre;
  } else if (before >= 0) {
    out = centre - points[before];
  } else {
    return false;
  }
  return true;
}

Eigen::Vector3f crossProductNormal(const LevelNeighbourhood& level, int row, int column, float centre_range) {
  Eigen::Vector3f along_row, along_column;
  if (!tangent(level, row, column, 0, 1, centre_range, along_row) ||
      !tangent(level, row, column, 1, 0, centre_range, along_column)) {
    return kInvalid;
  }
  const Eigen::Vector3f normal = along_row.cross(along_column);
  const float norm = normal.norm();
  // Nearly parallel tangents (a surface seen edge-on) have no reliable normal.
  if (!(norm > 1e-3f * along_row.norm() * along_column.norm())) return kInvalid;
  return facingSensor(normal / norm, level.map.points[std::size_t(row) * level.map.columns + column]);
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
  const int radius = options.method == NormalMethod::kCrossProduct ? 1 : options.window_radius;
  std::vector<int> row_shifts(std::size_t(out.rows) * (2 * radius + 1), 0);
  for (int row = 0; row < out.rows; ++row) {
    for (int step = -radius; step <= radius; ++step) {
      if (step == 0 || row + step < 0 || row + step >= out.rows) continue;
      const float difference = row_azimuth_columns[std::size_t(row + step) * stride] -
                               row_azimuth_columns[std::size_t(row) * stride];
      row_shifts[std::size_t(row) * (2 * radius + 1) + (step + radius)] = int(std::lround(difference / float(stride)));
    }
  }
  const LevelNeighbourhood level{out, view, options.max_range_jump_ratio * float(stride), radius, row_shifts};
  tbb::parallel_for(tbb::blocked_range<int>(0, out.rows), [&](const tbb::blocked_range<int>& rows) {
    for (int row = rows.begin(); row != rows.end(); ++row) {
      for (int column = 0; column < out.columns; ++column) {
        const std::size_t i = std::size_t(row) * out.columns + column;
        const float range = view(row, column);
        if (!isValidRange(range)) {
          out.normals[i] = kInvalid;
          continue;
        }
        out.normals[i] = options.method == NormalMethod::kCrossProduct
                             ? crossProductNormal(level, row, column, range)
                             : covarianceNormal(level, row, column, range, options.window_radius);
      }
    }
  });
}

}  // namespace range_image_mapping::registration
