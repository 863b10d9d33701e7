// Indoor scene: a square floor with a corridor ring, rooms outside and inside
// the ring, doors onto the corridor, furniture, a stair flight, thin poles,
// pillars and ceiling lights. The route follows the corridor ring and detours
// through some rooms (in by one door, out by another).
#include "plan_axes.h"
#include "procedural_scenes.h"
#include "random_choice.h"
#include "route_loop.h"
#include "scene_assembly.h"

#include <algorithm>
#include <cmath>

namespace range_image_mapping::simulation {
namespace {

using Eigen::AlignedBox2d;
using Eigen::Vector2d;
using Eigen::Vector3d;

constexpr double kWallThickness = 0.15;
constexpr double kOuterWallThickness = 0.3;
constexpr double kSlabThickness = 0.2;
constexpr double kDoorHeight = 2.1;
constexpr double kPoleRadius = 0.025;  // 5 cm: thinner than a pixel beyond a few metres
// A cart carries the sensor at about 1 m, a handheld rig up to about 1.9 m.
constexpr RouteClearance kClearance{0.6, 0.5, 1.9};
// How far a smoothed trajectory may stray from the route polyline.
constexpr double kPlacementMargin = 0.15;
constexpr double kCornerRadius = 0.6;
// Route doors leave the full clearance above the highest sensor.
constexpr double kRouteDoorHeight = kClearance.highest_m + kClearance.distance_m + kPlacementMargin;
constexpr double kItemGap = 0.25;  // between furniture items, so they stay separate shapes

Vector3d lifted(const Vector2d& point, double z) { return Vector3d(point.x(), point.y(), z); }

// Positions splitting [low, high] into pieces of about min_piece..max_piece.
std::vector<double> splitPositions(double low, double high, double min_piece, double max_piece,
                                   SeededRandom& random) {
  const double length = high - low;
  const int most = std::max(1, static_cast<int>(length / min_piece));
  const int count = std::clamp(
      static_cast<int>(std::lround(length / random.uniform(min_piece, max_piece))), 1, most);
  std::vector<double> weights(count);
  double total = 0.0;
  for (double& weight : weights) total += (weight = random.uniform(0.85, 1.15));
  std::vector<double> cuts;
  double position = low;
  for (int i = 0; i + 1 < count; ++i) cuts.push_back(position += length * weights[i] / total);
  return cuts;
}

// An opening in a corridor wall.
struct Door {
  int wall_axis;     // the axis the wall runs along
  double wall_face;  // the wall's corridor-side face, on the other axis
  double centre, width, height;
};

// Where a room's wall borders a corridor leg.
struct CorridorSide {
  int leg;
  double face;       // the corridor-side face of that wall, across the leg
  double low, high;  // along the leg, where a door may open
};

struct Room {
  AlignedBox2d interior;
  std::vector<CorridorSide> sides;
  bool has_door = false;
  bool on_route = false;
};

// A straight stretch of the corridor ring's centre line, in travel order
// (counter-clockwise seen from above).
struct Leg {
  int along_axis;
  double fixed;   // the centre line's coordinate across the leg
  int direction;  // +1 when travel increases the along coordinate
};

struct Wall {
  AlignedBox2d footprint;
  int axis;  // the axis it runs along
};

// ---------------------------------------------------------------- furniture

SceneObject table(const AlignedBox2d& footprint, double height) {
  SceneObject object;
  const double top = 0.04, leg = 0.05;
  object.addBox(lifted(footprint.min(), height - top), lifted(footprint.max(), height),
                SurfaceClass::kFurniture);
  for (int corner = 0; corner < 4; ++corner) {
    const Vector2d at((corner & 1) ? footprint.max().x() - 0.05 - leg : footprint.min().x() + 0.05,
                      (corner & 2) ? footprint.max().y() - 0.05 - leg : footprint.min().y() + 0.05);
    object.addBox(lifted(at, 0.0), lifted(at + Vector2d(leg, leg), height - top),
                  SurfaceClass::kFurniture);
  }
  return object;
}

SceneObject chair(const AlignedBox2d& footprint, int back_side) {
  SceneObject object = table(footprint, 0.46);
  // The backrest stands on one edge: 0 low y, 1 high x, 2 high y, 3 low x.
  AlignedBox2d back = footprint;
  const int axis = back_side % 2 == 0 ? 1 : 0;
  if (back_side == 0 || back_side == 3)
    back.max()[axis] = back.min()[axis] + 0.04;
  else
    back.min()[axis] = back.max()[axis] - 0.04;
  object.addBox(lifted(back.min(), 0.46), lifted(back.max(), 0.9), SurfaceClass::kFurniture);
  return object;
}

SceneObject shelf(const AlignedBox2d& footprint, int back_side, double height,
                  SeededRandom& random) {
  SceneObject object;
  const int depth_axis = back_side % 2 == 0 ? 1 : 0;
  const int length_axis = 1 - depth_axis;
  const bool back_at_low = back_side == 0 || back_side == 3;
  const double board = 0.02;
  // Side panels at both ends, a back panel, boards.
  for (int end = 0; end < 2; ++end) {
    AlignedBox2d panel = footprint;
    if (end == 0)
      panel.max()[length_axis] = panel.min()[length_axis] + board;
    else
      panel.min()[length_axis] = panel.max()[length_axis] - board;
    object.addBox(lifted(panel.min(), 0.0), lifted(panel.max(), height), SurfaceClass::kFurniture);
  }
  AlignedBox2d back = footprint;
  if (back_at_low)
    back.max()[depth_axis] = back.min()[depth_axis] + 0.01;
  else
    back.min()[depth_axis] = back.max()[depth_axis] - 0.01;
  object.addBox(lifted(back.min(), 0.0), lifted(back.max(), height), SurfaceClass::kFurniture);
  const int levels = std::max(2, static_cast<int>(height / 0.4));
  for (int level = 0; level < levels; ++level) {
    const double z = 0.08 + level * (height - 0.1) / (levels - 1);
    object.addBox(lifted(footprint.min(), z - board), lifted(footprint.max(), z),
                  SurfaceClass::kFurniture);
    if (level + 1 == levels) break;
    // A few things on the board: boxes of varied size.
    double along = footprint.min()[length_axis] + board + random.uniform(0.02, 0.2);
    const double depth = footprint.sizes()[depth_axis];
    while (true) {
      const double width = random.uniform(0.1, 0.35);
      if (along + width > footprint.max()[length_axis] - board - 0.02) break;
      if (chance(random, 0.7)) {
        const double item_depth = random.uniform(0.4, 0.85) * depth;
        const double item_height =
            std::min(random.uniform(0.08, 0.3), (height - 0.1) / (levels - 1) - 0.05);
        const double front = back_at_low ? footprint.min()[depth_axis] + 0.02
                                         : footprint.max()[depth_axis] - 0.02 - item_depth;
        const AlignedBox2d item =
            boxOnAxes(length_axis, along, along + width, front, front + item_depth);
        object.addBox(lifted(item.min(), z), lifted(item.max(), z + item_height),
                      SurfaceClass::kFurniture);
      }
      along += width + random.uniform(0.03, 0.25);
    }
  }
  return object;
}

// Cardboard boxes stacked, each a little turned; they stay inside the footprint.
SceneObject boxPile(const AlignedBox2d& footprint, SeededRandom& random) {
  SceneObject object;
  const Vector2d centre = footprint.center();
  const double room = 0.5 * footprint.sizes().minCoeff();
  double z = 0.0;
  const int count = uniformInteger(random, 1, 4);
  double half = room / std::sqrt(2.0);  // any yaw stays inside
  for (int i = 0; i < count && half > 0.1; ++i) {
    const double box_half_x = random.uniform(0.7, 1.0) * half;
    const double box_half_y = random.uniform(0.7, 1.0) * half;
    const double box_height = random.uniform(0.25, 0.6);
    const Eigen::Isometry3f pose =
        Eigen::Translation3f(float(centre.x()), float(centre.y()), float(z)) *
        Eigen::AngleAxisf(float(random.uniform(-0.4, 0.4)), Eigen::Vector3f::UnitZ());
    object.add(makeBox(Eigen::Vector3f(-box_half_x, -box_half_y, 0.0f),
                       Eigen::Vector3f(box_half_x, box_half_y, box_height)),
               SurfaceClass::kFurniture, pose);
    z += box_height;
    half = std::min(box_half_x, box_half_y) * random.uniform(0.6, 0.95);
  }
  return object;
}

SceneObject thinPole(const Vector2d& at, double height, bool standing) {
  SceneObject object;
  object.add(makeCylinder(lifted(at, 0.0).cast<float>(), float(kPoleRadius), float(height), 12),
             SurfaceClass::kPole);
  if (standing)  // a heavy foot, as on a lamp stand or a barrier post
    object.add(makeCylinder(lifted(at, 0.0).cast<float>(), 0.15f, 0.03f, 16),
               SurfaceClass::kFurniture);
  return object;
}

// A straight flight up to a landing, against a wall, railing on the open side.
// Local frame: x up the flight from 0, y across in [0, width].
SceneObject stairFlight(int steps, double rise, double tread, double landing, double width,
                        bool railing_at_low_y) {
  SceneObject object;
  const double run = steps * tread;
  for (int step = 0; step < steps; ++step)
    object.addBox(Vector3d(step * tread, 0.0, 0.0),
                  Vector3d((step + 1) * tread, width, (step + 1) * rise), SurfaceClass::kBuilding);
  object.addBox(Vector3d(run, 0.0, 0.0), Vector3d(run + landing, width, steps * rise),
                SurfaceClass::kBuilding);
  // Rail 0.9 m above the nosings; posts down to the treads.
  const double rail_y = railing_at_low_y ? 0.04 : width - 0.04;
  const double rail_height = 0.9;
  const auto tread_top = [&](double x) {
    return std::min(steps, static_cast<int>(x / tread) + 1) * rise;
  };
  // Along the nosings, then level over the landing.
  const double slope_run = (steps - 1) * tread;
  const auto rail_z = [&](double x) {
    return rail_height + std::min(rise + x * rise / tread, steps * rise);
  };
  for (double x = 0.5 * tread; x < run + landing; x += 3 * tread) {
    const double base = tread_top(x);
    object.add(makeCylinder(Eigen::Vector3f(float(x), float(rail_y), float(base)), 0.02f,
                            float(rail_z(x) - base), 8),
               SurfaceClass::kPole);
  }
  const double slope_length = std::hypot(slope_run, (steps - 1) * rise);
  const Eigen::Isometry3f slope_pose =
      Eigen::Translation3f(float(slope_run / 2), float(rail_y), float(rail_z(slope_run / 2))) *
      Eigen::AngleAxisf(-float(std::atan2((steps - 1) * rise, slope_run)),
                        Eigen::Vector3f::UnitY());
  object.add(makeBox(Eigen::Vector3f(-float(slope_length / 2), -0.02f, -0.02f),
                     Eigen::Vector3f(float(slope_length / 2), 0.02f, 0.02f)),
             SurfaceClass::kPole, slope_pose);
  object.addBox(Vector3d(slope_run, rail_y - 0.02, steps * rise + rail_height - 0.02),
                Vector3d(run + landing, rail_y + 0.02, steps * rise + rail_height + 0.02),
                SurfaceClass::kPole);
  return object;
}

// ---------------------------------------------------------------- the floor plan

class IndoorGenerator {
 public:
  IndoorGenerator(uint32_t seed, double extent_m)
      : random_({seed, 0x1D00Full}), half_(extent_m / 2.0) {}

  Scene generate() {
    planLayout();
    SceneAssembly assembly(planRoute(), kClearance, kPlacementMargin);
    addDoorsOffTheRoute();
    addStructure(assembly);
    addStairs(assembly);
    for (Room& room : rooms_) {
      addPillars(assembly, room.interior);
      furnish(assembly, room.interior, room.interior.volume() / random_.uniform(5.0, 8.0), false);
    }
    for (const AlignedBox2d& corridor : corridorLegs())
      furnish(assembly, corridor, corridor.volume() / 25.0, true);
    addPoles(assembly);
    addLights(assembly);
    return std::move(assembly).finish();
  }

 private:
  // ------------------------------------------------------------ layout

  void planLayout() {
    height_ = random_.uniform(2.75, 3.0);
    const double band_depth = std::clamp(0.18 * 2.0 * half_, 4.0, 8.0) + random_.uniform(-0.4, 0.4);
    corridor_width_ = random_.uniform(2.2, 2.8);
    ring_outer_ = half_ - band_depth;
    ring_inner_ = ring_outer_ - corridor_width_;
    const double t = kWallThickness;

    // The corridor's walls: outer ones reach the building's outer walls and
    // close the bands of rooms; their bodies lie outside the corridor.
    walls_.push_back(
        {AlignedBox2d(Vector2d(-half_, -ring_outer_ - t), Vector2d(half_, -ring_outer_)), 0});
    walls_.push_back(
        {AlignedBox2d(Vector2d(-half_, ring_outer_), Vector2d(half_, ring_outer_ + t)), 0});
    walls_.push_back({AlignedBox2d(Vector2d(-ring_outer_ - t, -ring_outer_),
                                   Vector2d(-ring_outer_, ring_outer_)),
                      1});
    walls_.push_back(
        {AlignedBox2d(Vector2d(ring_outer_, -ring_outer_), Vector2d(ring_outer_ + t, ring_outer_)),
         1});

    // Bands of rooms between the corridor and the outer walls. Bottom and top
    // span the full width, left and right fit between them.
    struct Band {
      int along_axis, leg;
      double along_low, along_high, across_low, across_high, face;
    };
    const Band bands[4] = {
        {0, 0, -half_, half_, -half_, -ring_outer_ - t, -ring_outer_},
        {1, 1, -ring_outer_, ring_outer_, ring_outer_ + t, half_, ring_outer_},
        {0, 2, -half_, half_, ring_outer_ + t, half_, ring_outer_},
        {1, 3, -ring_outer_, ring_outer_, -half_, -ring_outer_ - t, -ring_outer_},
    };
    for (const Band& band : bands) {
      std::vector<double> edges{band.along_low};
      for (double cut : splitPositions(-ring_outer_, ring_outer_, 4.0, 7.0, random_)) {
        edges.push_back(cut);
        walls_.push_back({boxOnAxes(band.along_axis, cut - t / 2, cut + t / 2, band.across_low,
                                    band.across_high),
                          1 - band.along_axis});
      }
      edges.push_back(band.along_high);
      for (std::size_t i = 0; i + 1 < edges.size(); ++i) {
        Room room;
        const double low = edges[i] + (i == 0 ? 0.0 : t / 2);
        const double high = edges[i + 1] - (i + 2 == edges.size() ? 0.0 : t / 2);
        room.interior = boxOnAxes(band.along_axis, low, high, band.across_low, band.across_high);
        room.sides.push_back(
            {band.leg, band.face, std::max(low, -ring_outer_), std::min(high, ring_outer_)});
        rooms_.push_back(room);
      }
    }
    planInnerBlock();
  }

  // Inside the ring: up to 3 x 2 rooms, so each touches the corridor; a solid
  // core when there is no space for a room.
  void planInnerBlock() {
    const double t = kWallThickness;
    const double inside = ring_inner_ - t;
    if (2.0 * inside < 3.0) {
      if (ring_inner_ > 0.0)
        core_ = AlignedBox2d(Vector2d::Constant(-ring_inner_), Vector2d::Constant(ring_inner_));
      return;
    }
    walls_.push_back(
        {AlignedBox2d(Vector2d(-ring_inner_, -ring_inner_), Vector2d(ring_inner_, -inside)), 0});
    walls_.push_back(
        {AlignedBox2d(Vector2d(-ring_inner_, inside), Vector2d(ring_inner_, ring_inner_)), 0});
    walls_.push_back({AlignedBox2d(Vector2d(-ring_inner_, -inside), Vector2d(-inside, inside)), 1});
    walls_.push_back({AlignedBox2d(Vector2d(inside, -inside), Vector2d(ring_inner_, inside)), 1});

    const double size = 2.0 * inside;
    int counts[2] = {std::clamp(static_cast<int>(std::lround(size / 10.0)), 1, 3),
                     std::clamp(static_cast<int>(std::lround(size / 10.0)), 1, 2)};
    if (chance(random_, 0.5)) std::swap(counts[0], counts[1]);
    std::vector<double> edges[2];
    for (int axis = 0; axis < 2; ++axis) {
      edges[axis].push_back(-inside);
      const double piece = size / counts[axis];
      for (double cut : splitPositions(-inside, inside, piece, piece, random_)) {
        edges[axis].push_back(cut);
        walls_.push_back(
            {boxOnAxes(1 - axis, -inside, inside, cut - t / 2, cut + t / 2), 1 - axis});
      }
      edges[axis].push_back(inside);
    }
    for (std::size_t i = 0; i + 1 < edges[0].size(); ++i) {
      for (std::size_t j = 0; j + 1 < edges[1].size(); ++j) {
        Room room;
        const double x0 = edges[0][i] + (i == 0 ? 0.0 : t / 2);
        const double x1 = edges[0][i + 1] - (i + 2 == edges[0].size() ? 0.0 : t / 2);
        const double y0 = edges[1][j] + (j == 0 ? 0.0 : t / 2);
        const double y1 = edges[1][j + 1] - (j + 2 == edges[1].size() ? 0.0 : t / 2);
        room.interior = AlignedBox2d(Vector2d(x0, y0), Vector2d(x1, y1));
        if (j == 0) room.sides.push_back({0, -ring_inner_, x0, x1});
        if (i + 2 == edges[0].size()) room.sides.push_back({1, ring_inner_, y0, y1});
        if (j + 2 == edges[1].size()) room.sides.push_back({2, ring_inner_, x0, x1});
        if (i == 0) room.sides.push_back({3, -ring_inner_, y0, y1});
        rooms_.push_back(room);
      }
    }
  }

  Leg leg(int index) const {
    const double r = ringCentre();
    switch (index) {
      case 0:
        return {0, -r, +1};
      case 1:
        return {1, r, +1};
      case 2:
        return {0, r, -1};
      default:
        return {1, -r, -1};
    }
  }
  double ringCentre() const { return ring_outer_ - corridor_width_ / 2.0; }

  std::vector<AlignedBox2d> corridorLegs() const {
    return {
        AlignedBox2d(Vector2d(-ring_outer_, -ring_outer_), Vector2d(ring_outer_, -ring_inner_)),
        AlignedBox2d(Vector2d(ring_inner_, -ring_outer_), Vector2d(ring_outer_, ring_outer_)),
        AlignedBox2d(Vector2d(-ring_outer_, ring_inner_), Vector2d(ring_outer_, ring_outer_)),
        AlignedBox2d(Vector2d(-ring_outer_, -ring_outer_), Vector2d(-ring_inner_, ring_outer_))};
  }

  void addDoor(const Leg& leg, const CorridorSide& side, double centre, double width,
               double height) {
    const Door door{leg.along_axis, side.face, centre, width, height};
    doors_.push_back(door);
    // Nothing stands in front of a door, on either side.
    door_zones_.push_back(boxOnAxes(leg.along_axis, centre - width / 2 - 0.3,
                                    centre + width / 2 + 0.3, side.face - 1.3, side.face + 1.3));
  }

  // ------------------------------------------------------------ route

  // The ring's centre line, with detours through up to three rooms: in by
  // one door, across the room's middle, out by a second door.
  std::vector<Eigen::Vector3d> planRoute() {
    const double r = ringCentre();
    const double keep = kClearance.distance_m + kPlacementMargin + 0.05;
    // Rooms along each leg where two route doors fit.
    struct Candidate {
      std::size_t room;
      CorridorSide side;
      double low, high, width;
    };
    std::vector<Candidate> candidates[4];
    std::vector<int> legs_with_candidates;
    for (int index = 0; index < 4; ++index) {
      const int a = leg(index).along_axis;
      for (std::size_t i = 0; i < rooms_.size(); ++i) {
        for (const CorridorSide& side : rooms_[i].sides) {
          if (side.leg != index) continue;
          const double width = random_.uniform(1.6, 1.9);
          const double low =
              std::max({side.low + width / 2 + 0.05, rooms_[i].interior.min()[a] + keep, -r + 1.5});
          const double high =
              std::min({side.high - width / 2 - 0.05, rooms_[i].interior.max()[a] - keep, r - 1.5});
          if (high - low >= 2.5) candidates[index].push_back({i, side, low, high, width});
        }
      }
      if (!candidates[index].empty()) legs_with_candidates.push_back(index);
    }
    // At least one detour (there is always a band room that fits), at most three.
    const int forced_leg = legs_with_candidates.empty()
                               ? -1
                               : legs_with_candidates[uniformInteger(
                                     random_, 0, int(legs_with_candidates.size()) - 1)];

    std::vector<Vector2d> corners;
    int detours = 0;
    for (int index = 0; index < 4; ++index) {
      const Leg current = leg(index);
      corners.push_back(onAxes(current.along_axis, -r * current.direction, current.fixed));
      if (candidates[index].empty()) continue;
      if (index != forced_leg && !(detours < 2 && chance(random_, 0.5))) continue;
      const Candidate& pick =
          candidates[index][uniformInteger(random_, 0, int(candidates[index].size()) - 1)];
      Room& room = rooms_[pick.room];
      const double slack = pick.high - pick.low - 2.5;
      const double first = pick.low + random_.uniform(0.0, 0.3) * slack;
      const double second = pick.high - random_.uniform(0.0, 0.3) * slack;
      const double across = room.interior.center()[1 - current.along_axis];
      addDoor(current, pick.side, first, pick.width, kRouteDoorHeight);
      addDoor(current, pick.side, second, pick.width, kRouteDoorHeight);
      room.has_door = room.on_route = true;
      const double enter = current.direction > 0 ? first : second;
      const double leave = current.direction > 0 ? second : first;
      corners.push_back(onAxes(current.along_axis, enter, current.fixed));
      corners.push_back(onAxes(current.along_axis, enter, across));
      corners.push_back(onAxes(current.along_axis, leave, across));
      corners.push_back(onAxes(current.along_axis, leave, current.fixed));
      ++detours;
    }
    std::vector<Eigen::Vector3d> route;
    for (const Vector2d& point : roundedLoop(corners, kCornerRadius, 2.0))
      route.push_back(lifted(point, 0.0));
    return route;
  }

  void addDoorsOffTheRoute() {
    for (Room& room : rooms_) {
      if (room.has_door) continue;
      std::vector<CorridorSide> sides = room.sides;
      for (std::size_t i = sides.size(); i > 1; --i)
        std::swap(sides[i - 1], sides[uniformInteger(random_, 0, int(i) - 1)]);
      for (const CorridorSide& side : sides) {
        const double width = random_.uniform(0.9, 1.2);
        if (side.high - side.low < width + 0.5) continue;
        addDoor(leg(side.leg), side,
                random_.uniform(side.low + width / 2 + 0.25, side.high - width / 2 - 0.25), width,
                kDoorHeight);
        room.has_door = true;
        break;
      }
    }
  }

  // ------------------------------------------------------------ structure

  void addStructure(SceneAssembly& assembly) const {
    SceneObject structure;
    const double outer = half_ + kOuterWallThickness;
    structure.addBox(Vector3d(-outer, -outer, -kSlabThickness), Vector3d(outer, outer, 0.0),
                     SurfaceClass::kGround);
    structure.addBox(Vector3d(-outer, -outer, height_),
                     Vector3d(outer, outer, height_ + kSlabThickness), SurfaceClass::kBuilding);
    structure.addBox(Vector3d(-outer, -outer, 0.0), Vector3d(outer, -half_, height_),
                     SurfaceClass::kBuilding);
    structure.addBox(Vector3d(-outer, half_, 0.0), Vector3d(outer, outer, height_),
                     SurfaceClass::kBuilding);
    structure.addBox(Vector3d(-outer, -half_, 0.0), Vector3d(-half_, half_, height_),
                     SurfaceClass::kBuilding);
    structure.addBox(Vector3d(half_, -half_, 0.0), Vector3d(outer, half_, height_),
                     SurfaceClass::kBuilding);
    if (!core_.isEmpty())
      structure.addBox(lifted(core_.min(), 0.0), lifted(core_.max(), height_),
                       SurfaceClass::kBuilding);
    for (const Wall& wall : walls_) addWall(structure, wall);
    assembly.add(structure);
  }

  // Solid pieces between the door openings, a lintel above each.
  void addWall(SceneObject& structure, const Wall& wall) const {
    const int a = wall.axis;
    std::vector<const Door*> openings;
    for (const Door& door : doors_)
      if (door.wall_axis == a && door.wall_face >= wall.footprint.min()[1 - a] - 1e-9 &&
          door.wall_face <= wall.footprint.max()[1 - a] + 1e-9 &&
          door.centre > wall.footprint.min()[a] && door.centre < wall.footprint.max()[a])
        openings.push_back(&door);
    std::sort(openings.begin(), openings.end(),
              [](const Door* left, const Door* right) { return left->centre < right->centre; });
    const double across_low = wall.footprint.min()[1 - a],
                 across_high = wall.footprint.max()[1 - a];
    const auto piece = [&](double low, double high, double z_low) {
      if (high - low < 1e-6) return;
      const AlignedBox2d footprint = boxOnAxes(a, low, high, across_low, across_high);
      structure.addBox(lifted(footprint.min(), z_low), lifted(footprint.max(), height_),
                       SurfaceClass::kBuilding);
    };
    double solid_from = wall.footprint.min()[a];
    for (const Door* door : openings) {
      piece(solid_from, door->centre - door->width / 2, 0.0);
      piece(door->centre - door->width / 2, door->centre + door->width / 2, door->height);
      solid_from = door->centre + door->width / 2;
    }
    piece(solid_from, wall.footprint.max()[a], 0.0);
  }

  // ------------------------------------------------------------ contents

  // Free floor for an item: inside the region, off the door zones, apart from other items.
  bool isFree(const AlignedBox2d& footprint, const AlignedBox2d& region) const {
    if (!region.contains(footprint)) return false;
    for (const AlignedBox2d& zone : door_zones_)
      if (zone.intersects(footprint)) return false;
    AlignedBox2d spaced = footprint;
    spaced.min().array() -= kItemGap;
    spaced.max().array() += kItemGap;
    for (const AlignedBox2d& taken : occupied_)
      if (taken.intersects(spaced)) return false;
    return true;
  }

  bool place(SceneAssembly& assembly, const AlignedBox2d& footprint, const AlignedBox2d& region,
             const SceneObject& object) {
    if (!isFree(footprint, region) || !assembly.addIfClear(object)) return false;
    occupied_.push_back(footprint);
    return true;
  }

  void addStairs(SceneAssembly& assembly) {
    std::vector<std::size_t> order;
    for (std::size_t i = 0; i < rooms_.size(); ++i) order.push_back(i);
    for (std::size_t i = order.size(); i > 1; --i)
      std::swap(order[i - 1], order[uniformInteger(random_, 0, int(i) - 1)]);
    // Rooms off the route first: a stair flight fills a room.
    std::stable_sort(order.begin(), order.end(), [&](std::size_t left, std::size_t right) {
      return !rooms_[left].on_route && rooms_[right].on_route;
    });
    for (std::size_t index : order) {
      const AlignedBox2d& interior = rooms_[index].interior;
      for (int attempt = 0; attempt < 20; ++attempt) {
        const int steps = uniformInteger(random_, 7, 10);
        const double rise = random_.uniform(0.16, 0.18), tread = 0.28, landing = 1.0;
        const double width = random_.uniform(0.9, 1.2), length = steps * tread + landing;
        const int quarter_turns = uniformInteger(random_, 0, 3);
        const double yaw = quarter_turns * M_PI / 2.0;
        const Vector2d x_direction(std::round(std::cos(yaw)), std::round(std::sin(yaw)));
        const Vector2d y_direction(-x_direction.y(), x_direction.x());
        AlignedBox2d rotated;  // the local footprint turned by yaw
        for (int corner = 0; corner < 4; ++corner)
          rotated.extend(((corner & 1) ? length : 0.0) * x_direction +
                         ((corner & 2) ? width : 0.0) * y_direction);
        const Vector2d size = rotated.sizes();
        if ((size.array() > interior.sizes().array() - 0.05).any()) break;
        // Against the wall on one long side, anywhere along it.
        const int across_axis = y_direction.x() != 0.0 ? 0 : 1, along_axis = 1 - across_axis;
        const bool wall_at_far_side = chance(random_, 0.5);
        const bool against_high_wall = wall_at_far_side == (y_direction[across_axis] > 0.0);
        Vector2d minimum;
        minimum[across_axis] = against_high_wall
                                   ? interior.max()[across_axis] - size[across_axis] - 0.01
                                   : interior.min()[across_axis] + 0.01;
        minimum[along_axis] = random_.uniform(interior.min()[along_axis] + 0.01,
                                              interior.max()[along_axis] - size[along_axis] - 0.01);
        const AlignedBox2d footprint(minimum, minimum + size);
        const Vector2d offset = minimum - rotated.min();
        const Eigen::Isometry3f pose =
            Eigen::Translation3f(float(offset.x()), float(offset.y()), 0.0f) *
            Eigen::AngleAxisf(float(yaw), Eigen::Vector3f::UnitZ());
        SceneObject stairs;
        stairs.add(stairFlight(steps, rise, tread, landing, width, wall_at_far_side), pose);
        if (place(assembly, footprint, interior, stairs)) return;
      }
    }
  }

  void addPillars(SceneAssembly& assembly, const AlignedBox2d& interior) {
    if (interior.sizes().minCoeff() < 9.0) return;
    const double spacing = random_.uniform(4.5, 6.5), side = random_.uniform(0.3, 0.45);
    for (double x = interior.min().x() + spacing; x < interior.max().x() - spacing / 2;
         x += spacing) {
      for (double y = interior.min().y() + spacing; y < interior.max().y() - spacing / 2;
           y += spacing) {
        const AlignedBox2d footprint(Vector2d(x - side / 2, y - side / 2),
                                     Vector2d(x + side / 2, y + side / 2));
        SceneObject pillar;
        pillar.addBox(lifted(footprint.min(), 0.0), lifted(footprint.max(), height_),
                      SurfaceClass::kBuilding);
        place(assembly, footprint, interior, pillar);
      }
    }
  }

  // A footprint of the given size against a random wall of the region.
  AlignedBox2d againstWall(const AlignedBox2d& region, double length, double depth,
                           int* back_side) {
    *back_side = uniformInteger(random_, 0, 3);
    const int along_axis = *back_side % 2 == 0 ? 0 : 1;
    const double low = region.min()[along_axis], high = region.max()[along_axis] - length;
    const double along = high > low ? random_.uniform(low, high) : low;
    const bool at_high = *back_side == 1 || *back_side == 2;
    const double across =
        at_high ? region.max()[1 - along_axis] - 0.02 - depth : region.min()[1 - along_axis] + 0.02;
    return boxOnAxes(along_axis, along, along + length, across, across + depth);
  }

  AlignedBox2d anywhere(const AlignedBox2d& region, double size_x, double size_y) {
    const Vector2d room = region.sizes() - Vector2d(size_x, size_y);
    if ((room.array() <= 0.0).any())
      return AlignedBox2d(region.min(), region.min() + Vector2d(size_x, size_y));
    const Vector2d minimum(region.min().x() + random_.uniform(0.0, room.x()),
                           region.min().y() + random_.uniform(0.0, room.y()));
    return AlignedBox2d(minimum, minimum + Vector2d(size_x, size_y));
  }

  // Corridors only get shallow cabinets along their walls.
  void furnish(SceneAssembly& assembly, const AlignedBox2d& region, double target, bool corridor) {
    const int count = static_cast<int>(std::lround(target));
    for (int item = 0; item < count; ++item) {
      const double kind = random_.uniform();
      for (int attempt = 0; attempt < 25; ++attempt) {
        int back_side = 0;
        AlignedBox2d footprint;
        SceneObject object;
        if (corridor || kind < 0.15) {  // a cabinet against a wall
          footprint = againstWall(region, random_.uniform(0.5, 1.2),
                                  corridor ? 0.35 : random_.uniform(0.4, 0.6), &back_side);
          object.addBox(lifted(footprint.min(), 0.0),
                        lifted(footprint.max(), random_.uniform(0.8, 2.0)),
                        SurfaceClass::kFurniture);
        } else if (kind < 0.4) {
          footprint =
              againstWall(region, random_.uniform(0.8, 2.4), random_.uniform(0.3, 0.5), &back_side);
          object = shelf(footprint, back_side, random_.uniform(1.6, 2.2), random_);
        } else if (kind < 0.65) {
          const double length = random_.uniform(1.2, 2.0), depth = random_.uniform(0.7, 1.0);
          footprint = chance(random_, 0.5) ? anywhere(region, length, depth)
                                           : anywhere(region, depth, length);
          object = table(footprint, random_.uniform(0.72, 0.76));
        } else if (kind < 0.8) {
          footprint = anywhere(region, 0.45, 0.45);
          object = chair(footprint, uniformInteger(random_, 0, 3));
        } else {
          const double size = random_.uniform(0.5, 1.2);
          footprint = anywhere(region, size, size);
          object = boxPile(footprint, random_);
        }
        if (place(assembly, footprint, region, object)) break;
      }
    }
  }

  // Thin poles: floor-to-ceiling pipes and free-standing posts, in rooms and
  // along corridor walls.
  void addPoles(SceneAssembly& assembly) {
    const int count = static_cast<int>(std::lround(half_ * 1.2));
    const std::vector<AlignedBox2d> corridors = corridorLegs();
    for (int pole = 0; pole < count; ++pole) {
      for (int attempt = 0; attempt < 25; ++attempt) {
        const bool in_corridor = chance(random_, 0.4);
        const AlignedBox2d region =
            in_corridor ? corridors[uniformInteger(random_, 0, 3)]
                        : rooms_[uniformInteger(random_, 0, int(rooms_.size()) - 1)].interior;
        const double reach = kPoleRadius + 0.05;
        AlignedBox2d footprint;
        if (in_corridor) {
          int back_side = 0;
          footprint =
              againstWall(region, 2 * reach, 2 * reach + random_.uniform(0.05, 0.25), &back_side);
        } else {
          footprint = anywhere(region, 0.3, 0.3);  // room for a foot
        }
        const bool pipe = chance(random_, 0.5);
        const SceneObject object =
            thinPole(footprint.center(), pipe ? height_ : random_.uniform(1.0, 1.9), !pipe);
        if (place(assembly, footprint, region, object)) break;
      }
    }
  }

  void addLights(SceneAssembly& assembly) {
    const double r = ringCentre();
    for (int index = 0; index < 4; ++index) {
      const Leg current = leg(index);
      for (double along = -r + 1.5; along < r - 1.0; along += 3.6) {
        SceneObject light;
        const AlignedBox2d footprint = boxOnAxes(current.along_axis, along - 0.6, along + 0.6,
                                                 current.fixed - 0.15, current.fixed + 0.15);
        light.addBox(lifted(footprint.min(), height_ - 0.06), lifted(footprint.max(), height_),
                     SurfaceClass::kFurniture);
        assembly.addIfClear(light);
      }
    }
    for (const Room& room : rooms_) {
      const Vector2d count = (room.interior.sizes() / 3.0).array().floor().max(1.0);
      const Vector2d step = room.interior.sizes().cwiseQuotient(count);
      for (int i = 0; i < count.x(); ++i) {
        for (int j = 0; j < count.y(); ++j) {
          const Vector2d centre =
              room.interior.min() + step.cwiseProduct(Vector2d(i + 0.5, j + 0.5));
          SceneObject light;
          light.addBox(lifted(centre - Vector2d(0.3, 0.3), height_ - 0.06),
                       lifted(centre + Vector2d(0.3, 0.3), height_), SurfaceClass::kFurniture);
          assembly.addIfClear(light);
        }
      }
    }
  }

  SeededRandom random_;
  double half_;
  double height_ = 0.0;
  double corridor_width_ = 0.0;
  double ring_outer_ = 0.0;  // the corridor's outer faces, from the centre
  double ring_inner_ = 0.0;  // its inner faces
  AlignedBox2d core_;        // solid, when the ring is too small for inner rooms
  std::vector<Room> rooms_;
  std::vector<Wall> walls_;
  std::vector<Door> doors_;
  std::vector<AlignedBox2d> door_zones_;
  std::vector<AlignedBox2d> occupied_;
};

}  // namespace

Scene generateIndoorScene(uint32_t seed, double extent_m) {
  return IndoorGenerator(seed, extent_m).generate();
}

}  // namespace range_image_mapping::simulation
