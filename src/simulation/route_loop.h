// Closed routes for the procedural scenes: a loop through corner points with
// every corner replaced by a circular arc, so a smoothed trajectory follows it
// closely and the clearance checked against it is the clearance driven.
#pragma once

#include <Eigen/Core>

#include <vector>

namespace range_image_mapping::simulation {

// corners: the loop's corners in travel order (not repeated at the end), in
// the horizontal plane. Each corner becomes an arc of radius_m (less where the
// neighbouring stretches are short) sampled every 10 degrees; straight
// stretches get points at most max_spacing_m apart. The result starts and ends
// (repeated) in the middle of the longest straight stretch.
std::vector<Eigen::Vector2d> roundedLoop(const std::vector<Eigen::Vector2d>& corners,
                                         double radius_m, double max_spacing_m);

}  // namespace range_image_mapping::simulation
