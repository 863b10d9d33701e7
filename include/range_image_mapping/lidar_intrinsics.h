// The cylindrical range-image model of a spinning LiDAR (paper section 3).
//
// Row v is a laser beam with altitude phi_lut[v] and azimuth offset theta_lut[v];
// column u is the encoder angle theta_e(u) = 2*pi - 2*pi*u/W (column 0 looks
// along +x, the azimuth decreases as u grows, as in Ouster's lidar frame).
// Every beam starts on a circle of radius r0 around the z axis. All geometry is
// in the lidar frame, on the *staggered* image (column = measurement id).
#pragma once

#include <Eigen/Geometry>

#include <array>
#include <cstdint>
#include <cstring>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

// On a hot loop over plain arrays: AVX-512 and AVX2 clones besides the
// baseline build, picked at load time for the CPU (the code is built without
// -march, for the ABI shared with PCL and the nodelets). Elsewhere one
// version. The libraries are built with -ffp-contract=off, so the AVX-512
// clones (whose instructions include fused multiply-adds) round as the others
// do and the poses are the same on every CPU.
#if defined(__x86_64__) && (defined(__clang__) ? __clang_major__ >= 14 : defined(__GNUC__))
#define RANGE_IMAGE_MAPPING_SIMD_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#else
#define RANGE_IMAGE_MAPPING_SIMD_CLONES
#endif

namespace range_image_mapping {

// value where keep is 1, +0.0f where it is 0 (a NaN value too), with a bit
// mask: the vectoriser takes it where it does not take a select on a float
// that may be NaN.
inline float zeroUnless(float value, int keep) {
  int32_t bits;
  std::memcpy(&bits, &value, sizeof bits);
  bits &= -keep;
  std::memcpy(&value, &bits, sizeof value);
  return value;
}

// Raised for intrinsics that cannot describe a sensor; the message names the field.
class IntrinsicsError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// Plain description of a sensor, as read from metadata, a config file or a message.
struct LidarIntrinsics {
  int rows = 0;     // H, beams
  int columns = 0;  // W, measurement ids per revolution
  std::vector<double> altitude_rad;        // phi_lut[H], row 0 = highest beam
  std::vector<double> azimuth_offset_rad;  // theta_lut[H]
  // Beam origin: Ouster beam_to_lidar_transform(0,3) and (2,3) in metres.
  // For the flat metadata format it is (lidar_origin_to_beam_origin_mm, 0).
  double beam_origin_radius_m = 0.0;  // r0
  double beam_origin_z_m = 0.0;
  std::vector<int> pixel_shift_by_row;  // destagger shifts, H entries (zeros if none)
  Eigen::Isometry3d lidar_to_sensor = Eigen::Isometry3d::Identity();
  std::array<int, 2> column_window{0, -1};  // first, last column with data (inclusive, may wrap)
  std::string sensor_model;                 // e.g. "OS-1-128", "synthetic", "ring"

  // Throws IntrinsicsError naming the first inconsistent field.
  void validate() const;

  // Uniform vertical field of view, no azimuth offsets, no beam offset: the
  // synthetic projection the paper reduces to for KITTI.
  static LidarIntrinsics synthetic(int rows, int columns, double fov_up_rad, double fov_down_rad);

  bool columnInWindow(int column) const;
  int columnWindowWidth() const;
  // The median angle between neighbouring rows' altitudes (0 with one row):
  // how sparse the sensor's rows are.
  double medianRowSpacingRad() const;
};

// A pixel hit by the projection Pi, with the range from the beam origin as the
// sensor reports it (so that unproject(project(p)) == p up to rounding of u, v).
struct ProjectedPixel {
  int column = 0;
  int row = 0;
  float range = 0.0f;
};

// Intrinsics plus the precomputed tables that make Pi and Pi^-1 cheap.
// Immutable once built; range images of one sensor share one instance.
class LidarModel {
 public:
  explicit LidarModel(LidarIntrinsics intrinsics);

  const LidarIntrinsics& intrinsics() const { return intrinsics_; }
  int rows() const { return intrinsics_.rows; }
  int columns() const { return intrinsics_.columns; }

  // Pi^-1 (paper eq. 1-2): p = range * direction(u, v) + offset(u, v), lidar frame, metres.
  Eigen::Vector3f unproject(int column, int row, float range) const {
    const std::size_t i = static_cast<std::size_t>(row) * intrinsics_.columns + column;
    return range * direction_[i] + offset_[i];
  }
  const Eigen::Vector3f& direction(int column, int row) const {
    return direction_[static_cast<std::size_t>(row) * intrinsics_.columns + column];
  }
  const Eigen::Vector3f& offset(int column, int row) const {
    return offset_[static_cast<std::size_t>(row) * intrinsics_.columns + column];
  }

  // Pi (paper section 3.2). Returns nothing for points outside the vertical
  // field of view (beyond half a beam spacing past the outermost beams) or
  // closer to the beam origin than the origin offset.
  std::optional<ProjectedPixel> project(const Eigen::Vector3f& point_lidar) const;
  // Pi for many points: hits[i] = 1 and pixels[i] = project(points[i]) where
  // it hits, hits[i] = 0 (pixels[i] untouched) where it does not. Several
  // times faster than calling project() per point.
  void projectMany(const Eigen::Vector3f* points, std::size_t count, ProjectedPixel* pixels,
                   uint8_t* hits) const;
  // The same for points given as separate x, y, z arrays (callers that
  // compute their points in vectorised passes), the same pixels.
  void projectMany(const float* x, const float* y, const float* z, std::size_t count, ProjectedPixel* pixels,
                   uint8_t* hits) const;
  // Pi with the row already known (a cloud's ring field): only the column
  // and range are solved for.
  std::optional<ProjectedPixel> projectOnRow(const Eigen::Vector3f& point_lidar, int row) const;

  // Continuous encoder column of an azimuth, in [0, W).
  float columnOfEncoderAngle(float encoder_angle_rad) const;
  std::size_t inverseAltitudeTableSize() const { return inverse_altitude_.size(); }

 private:
  void buildInverseAltitudeTable();
  std::optional<ProjectedPixel> solveProjection(const Eigen::Vector3f& point, int fixed_row) const;
  int nearestRow(float sin_altitude) const;  // -1 outside the field of view

  LidarIntrinsics intrinsics_;
  std::vector<Eigen::Vector3f> direction_;  // unit ray per pixel, H*W
  std::vector<Eigen::Vector3f> offset_;     // beam origin term per pixel, H*W
  std::vector<float> azimuth_offset_;  // theta_lut
  std::vector<float> azimuth_offset_cos_, azimuth_offset_sin_;
  // Inverse altitude LUT (over sin of the altitude): bin -> rank in altitude
  // order, at least 2H bins, fine enough that the neighbour check is exact.
  // 32-bit entries, as the other tables: projectMany's look-ups vectorise.
  std::vector<int32_t> inverse_altitude_;
  std::vector<int> rows_by_altitude_;       // rank -> row, ascending altitude
  std::vector<float> cell_bound_;           // H+1 sines of the midpoints between ranks
  float table_bins_per_unit_ = 0.0f;
  float column_per_radian_ = 0.0f;
  float accept_sin_low_ = 0.0f, accept_sin_high_ = 0.0f;
  float beam_origin_radius_ = 0.0f, beam_origin_z_ = 0.0f, beam_origin_norm_ = 0.0f;
};

using LidarModelConstPtr = std::shared_ptr<const LidarModel>;

}  // namespace range_image_mapping
