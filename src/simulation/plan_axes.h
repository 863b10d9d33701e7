// Plans of the procedural scenes are axis-aligned: walls, streets and rows of
// cars run along x or y. These name a point or a box by its coordinate along
// such an axis and across it, so one piece of code serves both directions.
#pragma once

#include <Eigen/Geometry>

namespace range_image_mapping::simulation {

inline Eigen::Vector2d onAxes(int along_axis, double along, double across) {
  return along_axis == 0 ? Eigen::Vector2d(along, across) : Eigen::Vector2d(across, along);
}

inline Eigen::AlignedBox2d boxOnAxes(int along_axis, double along_low, double along_high,
                                     double across_low, double across_high) {
  return Eigen::AlignedBox2d(onAxes(along_axis, along_low, across_low),
                             onAxes(along_axis, along_high, across_high));
}

}  // namespace range_image_mapping::simulation
