// Point clouds into range images: organized clouds pixel for pixel, clouds with
// a ring field by ring and azimuth, plain clouds by the projection Pi.
#pragma once

#include "range_image_mapping/range_image.h"

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping {

// A cloud whose arrays disagree (sizes, organized shape) or a ring map that
// does not fit the model; what() names the field.
class PointCloudError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// A cloud as plain arrays (no ROS types): the ROS side fills it from PointCloud2.
struct PointCloudInput {
  // Lidar frame, metres. NaN/Inf points and points exactly at the origin are
  // how drivers mark "no return"; both are dropped and counted.
  std::vector<Eigen::Vector3f> points;
  std::vector<float> intensity;               // empty or one per point
  std::string intensity_field = "intensity";  // what intensity holds, copied to the image
  std::vector<uint16_t> ring;                 // empty or one per point
  std::vector<float> time_offset_s;           // empty or one per point (relative to stamp)
  int organized_height = 1;                   // > 1: organized, points in row-major H x W
  int organized_width = 0;                    // read only when organized_height > 1
  // Column order of an organized cloud. ouster-ros publishes its organized
  // cloud destaggered (columns in azimuth order; driver parameter destagger,
  // default true since 0.10) and in the sensor frame, so the caller moves it
  // into the lidar frame first. A cloud unprojected from a staggered range
  // image, or from ouster-ros with destagger off, is staggered.
  ColumnOrder organized_column_order = ColumnOrder::kDestaggered;
  uint64_t stamp_ns = 0;

  std::size_t size() const { return points.size(); }
  bool isOrganized() const { return organized_height > 1; }
  // Throws PointCloudError when an optional array or the organized shape does
  // not match the number of points.
  void validate() const;
};

struct ProjectionStatistics {
  std::size_t input_points = 0;
  std::size_t non_finite = 0;     // NaN/Inf, dropped
  std::size_t no_return = 0;      // exactly at the origin, dropped
  std::size_t outside_model = 0;  // outside the field of view, unknown ring, behind the beam
  std::size_t occluded = 0;       // lost to a nearer return in the same pixel
  std::size_t kept = 0;           // = valid pixels of the image
  // Organized clouds only: the largest distance between a point and the ray of
  // its pixel. More than a few millimetres means the cloud was not made with
  // this model's intrinsics, or is not in the lidar frame.
  double max_ray_distance_m = 0.0;

  // Points that carry a measurement.
  std::size_t measured() const { return input_points - non_finite - no_return; }
  // Share of the measured points that made it into the image: low values
  // point at wrong intrinsics (field of view, ring map, frame).
  double keptFraction() const { return measured() ? double(kept) / double(measured()) : 0.0; }
  // Sums another scan's counts into these (the largest ray distance of both).
  void add(const ProjectionStatistics& scan);
};

// An organized cloud of the model's H x W read in column order `order`: the
// median angle (rad) between a sample of its points (about 4000, spread over
// rows and columns) and their pixels' rays; NaN for other shapes or under 100
// measured points in the sample. Near 0 when the cloud's pixels are the
// model's; about pi when, e.g., the clouds are in a frame turned half a turn
// from the model's (ouster-ros's os_sensor against a model of os_lidar).
double organizedOffRayAngle(const PointCloudInput& cloud, const LidarModel& model, ColumnOrder order);

// Projects into a staggered image of model's size, in one pass over the points
// with the image itself as the depth buffer (the nearest return per pixel wins):
// - organized clouds of exactly the model's H x W map pixel for pixel (after
//   re-staggering destaggered input) when their pixels are the model's (their
//   points within half a column of their pixels' rays); other organized
//   clouds count as unorganized;
// - with a ring_to_row map and a ring field, row = ring_to_row[ring] and the
//   column comes from the azimuth minus the row's theta_lut;
// - otherwise each point goes through model.project() (Pi).
// Ranges are the r whose unprojection model.unproject(u, v, r) lies nearest to
// the point (Pi's own range on the Pi path). Intensity is carried when present;
// a column's timestamp is stamp + the smallest time offset of the points that
// fell into it (0 for columns without points). The image's stamp is the cloud's.
RangeImage projectPointCloud(const PointCloudInput& cloud, const LidarModelConstPtr& model,
                             ProjectionStatistics* statistics = nullptr);
RangeImage projectPointCloud(const PointCloudInput& cloud, const LidarModelConstPtr& model,
                             const std::vector<int>& ring_to_row,
                             ProjectionStatistics* statistics = nullptr);

// Intrinsics estimated from a cloud with a ring field, plus the ring -> row map
// that goes with them (rows sorted from the highest beam down, so Velodyne
// order, ring 0 lowest, and Ouster order, ring 0 highest, both come out right).
struct RingIntrinsics {
  LidarIntrinsics intrinsics;    // sensor_model "ring", no azimuth offsets, r0 = 0
  std::vector<int> ring_to_row;  // one entry per ring index 0 .. H-1
};

// H = largest ring index + 1; each ring's altitude is the median elevation of
// its measured points. Throws IntrinsicsError when the cloud has no ring field
// or a ring below the largest one has no points (naming it).
RingIntrinsics intrinsicsFromRings(const PointCloudInput& cloud, int columns);

}  // namespace range_image_mapping
