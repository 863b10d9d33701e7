#include "range_image_mapping/point_cloud_projection.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

namespace range_image_mapping {
namespace {

void checkOptionalArray(std::size_t entries, std::size_t points, const char* name) {
  if (entries != 0 && entries != points)
    throw PointCloudError("point cloud: " + std::string(name) + " has " + std::to_string(entries) +
                          " entries for " + std::to_string(points) + " points");
}

// What a point is before it reaches the image.
enum class PointKind { kNonFinite, kNoReturn, kMeasured };

PointKind classify(const Eigen::Vector3f& point) {
  if (!point.allFinite()) return PointKind::kNonFinite;
  if (point.x() == 0.0f && point.y() == 0.0f && point.z() == 0.0f) return PointKind::kNoReturn;
  return PointKind::kMeasured;
}

// Counts NaN/Inf and origin points; true for a point that carries a measurement.
bool isMeasurement(const Eigen::Vector3f& point, ProjectionStatistics& statistics) {
  switch (classify(point)) {
    case PointKind::kNonFinite:
      ++statistics.non_finite;
      return false;
    case PointKind::kNoReturn:
      ++statistics.no_return;
      return false;
    case PointKind::kMeasured:
      return true;
  }
  return false;
}

// The range whose unprojection lies nearest to the point: Pi^-1 is
// p = r d + o with unit d, so the least-squares r is d . (p - o).
float rangeAlongRay(const LidarModel& model, int column, int row, const Eigen::Vector3f& point) {
  return model.direction(column, row).dot(point - model.offset(column, row));
}

// Writes points into the image, keeping the nearest return per pixel (the
// image's range array is the depth buffer) and the earliest time per column.
class ImageWriter {
 public:
  ImageWriter(const PointCloudInput& cloud, RangeImage& image, ProjectionStatistics& statistics)
      : cloud_(cloud),
        image_(image),
        statistics_(statistics),
        earliest_time_s_(image.columns(), std::numeric_limits<double>::infinity()) {}

  void write(std::size_t point_index, int row, int column, float range) {
    if (!(range > 0.0f) || !std::isfinite(range)) {
      ++statistics_.outside_model;
      return;
    }
    if (!cloud_.time_offset_s.empty()) {
      const double time = cloud_.time_offset_s[point_index];
      if (time < earliest_time_s_[column]) earliest_time_s_[column] = time;
    } else if (earliest_time_s_[column] > 0.0) {
      earliest_time_s_[column] = 0.0;  // no time field: the column is seen at the stamp
    }
    const std::size_t pixel = image_.index(row, column);
    float& stored = image_.range[pixel];
    if (isValidRange(stored)) {
      ++statistics_.occluded;  // one of the two returns is lost either way
      if (stored <= range) return;
    } else {
      ++statistics_.kept;
    }
    stored = range;
    if (!cloud_.intensity.empty()) image_.intensity[pixel] = cloud_.intensity[point_index];
  }

  void finishColumnTimestamps() {
    for (int u = 0; u < image_.columns(); ++u) {
      const double time = earliest_time_s_[u];
      if (!std::isfinite(time)) continue;  // no points: stays 0
      const int64_t stamp =
          static_cast<int64_t>(cloud_.stamp_ns) + static_cast<int64_t>(std::llround(time * 1e9));
      image_.column_timestamp_ns[u] = stamp > 0 ? static_cast<uint64_t>(stamp) : 0;
    }
  }

 private:
  const PointCloudInput& cloud_;
  RangeImage& image_;
  ProjectionStatistics& statistics_;
  std::vector<double> earliest_time_s_;  // per column, relative to the stamp
};

void projectOrganized(const PointCloudInput& cloud, const LidarModel& model, ImageWriter& writer,
                      ProjectionStatistics& statistics) {
  const int rows = model.rows();
  const int columns = model.columns();
  const bool destaggered = cloud.organized_column_order == ColumnOrder::kDestaggered;
  const auto& shifts = model.intrinsics().pixel_shift_by_row;
  for (int row = 0; row < rows; ++row) {
    // Destaggered input column c holds staggered column (c - shift) mod W.
    const int shift = destaggered ? ((shifts[row] % columns) + columns) % columns : 0;
    for (int input_column = 0; input_column < columns; ++input_column) {
      const std::size_t i = static_cast<std::size_t>(row) * columns + input_column;
      const Eigen::Vector3f& point = cloud.points[i];
      if (!isMeasurement(point, statistics)) continue;
      int column = input_column - shift;
      if (column < 0) column += columns;
      const float range = rangeAlongRay(model, column, row, point);
      const double off_ray = (model.unproject(column, row, range) - point).norm();
      statistics.max_ray_distance_m = std::max(statistics.max_ray_distance_m, off_ray);
      writer.write(i, row, column, range);
    }
  }
}

void projectByRing(const PointCloudInput& cloud, const LidarModel& model,
                   const std::vector<int>& ring_to_row, ImageWriter& writer,
                   ProjectionStatistics& statistics) {
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3f& point = cloud.points[i];
    if (!isMeasurement(point, statistics)) continue;
    const uint16_t ring = cloud.ring[i];
    if (ring >= ring_to_row.size()) {
      ++statistics.outside_model;
      continue;
    }
    const std::optional<ProjectedPixel> pixel = model.projectOnRow(point, ring_to_row[ring]);
    if (!pixel) {
      ++statistics.outside_model;
      continue;
    }
    writer.write(i, pixel->row, pixel->column, rangeAlongRay(model, pixel->column, pixel->row, point));
  }
}

void projectThroughModel(const PointCloudInput& cloud, const LidarModel& model, ImageWriter& writer,
                         ProjectionStatistics& statistics) {
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3f& point = cloud.points[i];
    if (!isMeasurement(point, statistics)) continue;
    const std::optional<ProjectedPixel> pixel = model.project(point);
    if (!pixel) {
      ++statistics.outside_model;
      continue;
    }
    writer.write(i, pixel->row, pixel->column, pixel->range);
  }
}

}  // namespace

double organizedOffRayAngle(const PointCloudInput& cloud, const LidarModel& model, ColumnOrder order) {
  const int rows = model.rows(), columns = model.columns();
  if (!cloud.isOrganized() || cloud.organized_height != rows || cloud.organized_width != columns ||
      cloud.size() != std::size_t(rows) * columns)
    return std::numeric_limits<double>::quiet_NaN();
  const std::vector<int>& shifts = model.intrinsics().pixel_shift_by_row;
  // About 4000 points, every step-th of the cloud: an odd step, so that the
  // sample walks across the columns of every row rather than down a few.
  constexpr std::size_t kSample = 4096;
  const std::size_t step = std::max<std::size_t>(7, cloud.size() / kSample) | 1;
  std::vector<double> angles;
  angles.reserve(cloud.size() / step + 1);
  for (std::size_t i = 0; i < cloud.size(); i += step) {
    const Eigen::Vector3f& point = cloud.points[i];
    if (!point.allFinite() || point.squaredNorm() < 1e-6f) continue;
    const int row = int(i / std::size_t(columns)), input_column = int(i % std::size_t(columns));
    const int shift = order == ColumnOrder::kDestaggered ? ((shifts[row] % columns) + columns) % columns : 0;
    const int column = (input_column - shift + columns) % columns;
    const Eigen::Vector3f& ray = model.direction(column, row);
    const Eigen::Vector3f from_origin = point - model.offset(column, row);
    angles.push_back(std::atan2(double(ray.cross(from_origin).norm()), double(ray.dot(from_origin))));
  }
  if (angles.size() < 100) return std::numeric_limits<double>::quiet_NaN();
  std::nth_element(angles.begin(), angles.begin() + angles.size() / 2, angles.end());
  return angles[angles.size() / 2];
}

void ProjectionStatistics::add(const ProjectionStatistics& scan) {
  input_points += scan.input_points;
  non_finite += scan.non_finite;
  no_return += scan.no_return;
  outside_model += scan.outside_model;
  occluded += scan.occluded;
  kept += scan.kept;
  max_ray_distance_m = std::max(max_ray_distance_m, scan.max_ray_distance_m);
}

void PointCloudInput::validate() const {
  checkOptionalArray(intensity.size(), points.size(), "intensity");
  checkOptionalArray(ring.size(), points.size(), "ring");
  checkOptionalArray(time_offset_s.size(), points.size(), "time_offset_s");
  if (organized_height < 1)
    throw PointCloudError("point cloud: organized_height must be at least 1, got " +
                          std::to_string(organized_height));
  if (isOrganized() &&
      static_cast<std::size_t>(organized_height) * std::max(organized_width, 0) != points.size())
    throw PointCloudError("point cloud: organized " + std::to_string(organized_height) + " x " +
                          std::to_string(organized_width) + " does not hold " +
                          std::to_string(points.size()) + " points");
}

RangeImage projectPointCloud(const PointCloudInput& cloud, const LidarModelConstPtr& model,
                             ProjectionStatistics* statistics) {
  return projectPointCloud(cloud, model, {}, statistics);
}

RangeImage projectPointCloud(const PointCloudInput& cloud, const LidarModelConstPtr& model,
                             const std::vector<int>& ring_to_row,
                             ProjectionStatistics* statistics) {
  if (!model) throw PointCloudError("projectPointCloud: no sensor model");
  cloud.validate();
  for (std::size_t ring = 0; ring < ring_to_row.size(); ++ring) {
    if (ring_to_row[ring] < 0 || ring_to_row[ring] >= model->rows())
      throw PointCloudError("projectPointCloud: ring_to_row[" + std::to_string(ring) +
                            "] = " + std::to_string(ring_to_row[ring]) + " is not a row of the " +
                            std::to_string(model->rows()) + "-row model");
  }

  RangeImage image(model);
  image.stamp_ns = cloud.stamp_ns;
  if (!cloud.intensity.empty()) {
    image.intensity.assign(image.range.size(), 0.0f);
    image.intensity_field = cloud.intensity_field;
  }
  ProjectionStatistics local_statistics;
  ProjectionStatistics& counts = statistics ? *statistics : local_statistics;
  counts = ProjectionStatistics();
  counts.input_points = cloud.size();

  ImageWriter writer(cloud, image, counts);
  // Half a column: points nearer their pixel's ray than that are in the pixel.
  const double half_column_rad = M_PI / model->columns();
  const bool pixel_for_pixel = cloud.isOrganized() && cloud.organized_height == model->rows() &&
                               cloud.organized_width == model->columns() &&
                               organizedOffRayAngle(cloud, *model, cloud.organized_column_order) < half_column_rad;
  if (pixel_for_pixel) {
    projectOrganized(cloud, *model, writer, counts);
  } else if (!ring_to_row.empty() && !cloud.ring.empty()) {
    projectByRing(cloud, *model, ring_to_row, writer, counts);
  } else {
    projectThroughModel(cloud, *model, writer, counts);
  }
  writer.finishColumnTimestamps();
  return image;
}

RingIntrinsics intrinsicsFromRings(const PointCloudInput& cloud, int columns) {
  cloud.validate();
  if (cloud.ring.empty()) throw IntrinsicsError("intrinsicsFromRings: the cloud has no ring field");

  // Group the elevations by ring in one buffer (a counting sort), so each
  // ring's median is an nth_element on its own slice.
  std::vector<std::size_t> slice_start;  // ring -> first slot, then one past the last
  int rings = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    if (classify(cloud.points[i]) != PointKind::kMeasured) continue;
    rings = std::max(rings, cloud.ring[i] + 1);
  }
  if (rings == 0) throw IntrinsicsError("intrinsicsFromRings: the cloud has no measured points");
  slice_start.assign(rings + 1, 0);
  for (std::size_t i = 0; i < cloud.size(); ++i)
    if (classify(cloud.points[i]) == PointKind::kMeasured) ++slice_start[cloud.ring[i] + 1];
  for (int ring = 0; ring < rings; ++ring) {
    if (slice_start[ring + 1] == 0)
      throw IntrinsicsError("intrinsicsFromRings: ring " + std::to_string(ring) +
                            " has no points (rings 0.." + std::to_string(rings - 1) +
                            " expected from the largest ring index)");
    slice_start[ring + 1] += slice_start[ring];
  }
  std::vector<float> elevation(slice_start[rings]);
  std::vector<std::size_t> next_slot(slice_start.begin(), slice_start.end() - 1);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const Eigen::Vector3f& point = cloud.points[i];
    if (classify(point) != PointKind::kMeasured) continue;
    elevation[next_slot[cloud.ring[i]]++] = std::atan2(point.z(), std::hypot(point.x(), point.y()));
  }
  std::vector<double> ring_altitude(rings);
  for (int ring = 0; ring < rings; ++ring) {
    const auto first = elevation.begin() + slice_start[ring];
    const auto last = elevation.begin() + slice_start[ring + 1];
    const auto middle = first + (last - first) / 2;
    std::nth_element(first, middle, last);
    ring_altitude[ring] = *middle;
  }

  // Rows from the highest beam down; equal altitudes keep ring order.
  std::vector<int> ring_of_row(rings);
  std::iota(ring_of_row.begin(), ring_of_row.end(), 0);
  std::stable_sort(ring_of_row.begin(), ring_of_row.end(),
                   [&](int a, int b) { return ring_altitude[a] > ring_altitude[b]; });

  RingIntrinsics result;
  LidarIntrinsics& intrinsics = result.intrinsics;
  intrinsics.rows = rings;
  intrinsics.columns = columns;
  intrinsics.altitude_rad.resize(rings);
  intrinsics.azimuth_offset_rad.assign(rings, 0.0);
  intrinsics.pixel_shift_by_row.assign(rings, 0);
  intrinsics.sensor_model = "ring";
  result.ring_to_row.resize(rings);
  for (int row = 0; row < rings; ++row) {
    intrinsics.altitude_rad[row] = ring_altitude[ring_of_row[row]];
    result.ring_to_row[ring_of_row[row]] = row;
  }
  intrinsics.validate();
  return result;
}

}  // namespace range_image_mapping
