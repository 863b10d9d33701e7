// A spinning LiDAR's beam tables estimated from its point clouds, for clouds
// that come without them (a Velodyne, Hesai or RoboSense driver's output, a
// folder of .bin scans, an Ouster cloud without its metadata).
//
// From plain x, y, z points of a few scans: the beams are the clusters of the
// points' elevations seen from the beam origin, whose offset from the axis
// (r0, and a height) is fitted so that the clusters are tightest; the column
// count comes from the azimuth step between a beam's neighbouring points; each
// beam's azimuth offset is where its points sit on that column grid. With a
// ring field the rings are the beams and only the rest is estimated.
#pragma once

#include "range_image_mapping/lidar_intrinsics.h"
#include "range_image_mapping/point_cloud_projection.h"

#include <cstddef>
#include <stdexcept>
#include <string>
#include <vector>

namespace range_image_mapping {

// Too few points, or data in which no beam structure can be found; what()
// says which and what was seen.
class SensorEstimationError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct SensorEstimationOptions {
  // Columns per revolution; 0: from the azimuth step (the smallest multiple
  // of 360 deg / step that loses at most max_collision_share of the points to
  // a neighbour in the same pixel, at most twice the step's count).
  int columns = 0;
  double max_collision_share = 0.01;
  // Rows from the ring field when the clouds carry one.
  bool use_ring_field = true;
  // Search bounds of the beam origin: radius from the axis (Ouster 13-28 mm)
  // and height above the cloud's origin (a Velodyne's lasers sit about 0.2 m
  // above the frame KITTI gives; an Ouster cloud in os_sensor 36-78 mm).
  bool estimate_beam_origin = true;
  double max_beam_origin_radius_m = 0.06;
  double max_beam_origin_height_m = 0.4;
  // A cluster of elevations is a beam when it holds at least this share of
  // the median beam's points (the rest are strays, counted outside the model).
  double min_beam_share = 0.05;
  // Points nearer the axis than this are not used (their elevation depends
  // most on the beam origin, and drivers' self-returns live there).
  double min_horizontal_range_m = 0.5;
};

// How well a model explains clouds: every measured point (finite, not at the
// origin) is either kept, outside the model's field of view, or lost to
// another point in the same pixel.
struct SensorModelFit {
  std::size_t scans = 0;
  std::size_t measured_points = 0;
  std::size_t kept = 0;
  std::size_t outside_model = 0;
  std::size_t occluded = 0;  // two points in one pixel: the farther one is lost
  // RMS over the projected points of the angle between the point and its
  // pixel's ray, seen from the pixel's beam origin: in elevation (beam
  // altitude) and in azimuth (column grid plus azimuth offset), degrees.
  double elevation_residual_deg = 0.0;
  double azimuth_residual_deg = 0.0;

  double keptShare() const { return measured_points ? double(kept) / double(measured_points) : 0.0; }
  double outsideShare() const { return measured_points ? double(outside_model) / double(measured_points) : 0.0; }
  double occludedShare() const { return measured_points ? double(occluded) / double(measured_points) : 0.0; }
};

struct SensorEstimate {
  // sensor_model "estimated" (or "estimated from rings"); no pixel shifts
  // beyond the display ones, identity lidar_to_sensor, full column window.
  LidarIntrinsics intrinsics;
  // With the ring field: ring -> row (rows sorted from the highest beam down).
  std::vector<int> ring_to_row;
  std::vector<std::size_t> points_per_row;  // points of the input that made each beam
  double azimuth_step_deg = 0.0;            // median step between a beam's neighbouring points
  SensorModelFit fit;                       // of the estimate, on the clouds it came from
};

// Throws SensorEstimationError when the clouds hold fewer than 1000 usable
// points or no beam can be told apart.
SensorEstimate estimateSensorModel(const std::vector<PointCloudInput>& scans,
                                   const SensorEstimationOptions& options = {});

// Projects every cloud with the model (through ring_to_row when it is given
// and the clouds have rings) and measures the fit.
SensorModelFit measureSensorModelFit(const std::vector<PointCloudInput>& scans, const LidarModelConstPtr& model,
                                     const std::vector<int>& ring_to_row = {});

}  // namespace range_image_mapping
