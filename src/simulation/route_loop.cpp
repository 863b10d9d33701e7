#include "route_loop.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace range_image_mapping::simulation {
namespace {

double cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

// Points from `from` to `to`, `from` included, `to` left for the next piece.
void appendStraight(const Eigen::Vector2d& from, const Eigen::Vector2d& to, double max_spacing_m,
                    std::vector<Eigen::Vector2d>& points) {
  const int pieces = std::max(1, static_cast<int>(std::ceil((to - from).norm() / max_spacing_m)));
  for (int k = 0; k < pieces; ++k) points.push_back(from + (to - from) * (double(k) / pieces));
}

}  // namespace

std::vector<Eigen::Vector2d> roundedLoop(const std::vector<Eigen::Vector2d>& input_corners,
                                         double radius_m, double max_spacing_m) {
  // Collinear points are not corners.
  std::vector<Eigen::Vector2d> corners;
  const std::size_t input_count = input_corners.size();
  for (std::size_t i = 0; i < input_count; ++i) {
    const Eigen::Vector2d& previous = input_corners[(i + input_count - 1) % input_count];
    const Eigen::Vector2d& next = input_corners[(i + 1) % input_count];
    const Eigen::Vector2d in = input_corners[i] - previous, out = next - input_corners[i];
    if (in.norm() < 1e-9 || out.norm() < 1e-9)
      throw std::logic_error("roundedLoop: repeated corner");
    if (std::abs(cross(in.normalized(), out.normalized())) > 1e-9)
      corners.push_back(input_corners[i]);
  }
  const std::size_t count = corners.size();
  if (count < 3) throw std::logic_error("roundedLoop: a loop needs three corners");

  // Each corner's arc: where it leaves the incoming and joins the outgoing stretch.
  struct Arc {
    Eigen::Vector2d start, end, centre;
    double start_angle = 0.0, sweep = 0.0;
  };
  std::vector<Arc> arcs(count);
  for (std::size_t i = 0; i < count; ++i) {
    const Eigen::Vector2d& corner = corners[i];
    const Eigen::Vector2d in = corner - corners[(i + count - 1) % count];
    const Eigen::Vector2d out = corners[(i + 1) % count] - corner;
    const Eigen::Vector2d in_direction = in.normalized(), out_direction = out.normalized();
    const double turn =
        std::atan2(cross(in_direction, out_direction), in_direction.dot(out_direction));
    // Neighbouring arcs share a stretch: each may use at most 45 % of it.
    const double tangent =
        std::min(radius_m * std::tan(std::abs(turn) / 2.0), 0.45 * std::min(in.norm(), out.norm()));
    const double radius = tangent / std::tan(std::abs(turn) / 2.0);
    Arc& arc = arcs[i];
    arc.start = corner - tangent * in_direction;
    arc.end = corner + tangent * out_direction;
    const Eigen::Vector2d left(-in_direction.y(), in_direction.x());
    arc.centre = arc.start + (turn > 0 ? radius : -radius) * left;
    const Eigen::Vector2d from_centre = arc.start - arc.centre;
    arc.start_angle = std::atan2(from_centre.y(), from_centre.x());
    arc.sweep = turn;
  }

  // Start in the middle of the longest straight stretch (arc i's end to arc i+1's start).
  std::size_t longest = 0;
  for (std::size_t i = 1; i < count; ++i)
    if ((arcs[(i + 1) % count].start - arcs[i].end).norm() >
        (arcs[(longest + 1) % count].start - arcs[longest].end).norm())
      longest = i;

  std::vector<Eigen::Vector2d> points;
  const Eigen::Vector2d middle = 0.5 * (arcs[longest].end + arcs[(longest + 1) % count].start);
  appendStraight(middle, arcs[(longest + 1) % count].start, max_spacing_m, points);
  for (std::size_t k = 1; k <= count; ++k) {
    const Arc& arc = arcs[(longest + k) % count];
    const double radius = (arc.start - arc.centre).norm();
    const int pieces =
        std::max(1, static_cast<int>(std::ceil(std::abs(arc.sweep) / (M_PI / 18.0))));
    for (int p = 0; p < pieces; ++p) {
      const double angle = arc.start_angle + arc.sweep * p / pieces;
      points.push_back(arc.centre + radius * Eigen::Vector2d(std::cos(angle), std::sin(angle)));
    }
    const Eigen::Vector2d next_start = k == count ? middle : arcs[(longest + k + 1) % count].start;
    appendStraight(arc.end, next_start, max_spacing_m, points);
  }
  points.push_back(middle);
  return points;
}

}  // namespace range_image_mapping::simulation
