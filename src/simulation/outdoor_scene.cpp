// Outdoor scene: a grid of streets over gently sloping ground, blocks of
// buildings with facade relief, sidewalks with kerbs, lamp posts, signs,
// bollards, parked cars, trees, bushes and parks. The route is the boundary of
// a random set of blocks: a loop along street centre lines, turning at
// intersections.
#include "plan_axes.h"
#include "procedural_scenes.h"
#include "random_choice.h"
#include "route_loop.h"
#include "scene_assembly.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <stdexcept>

namespace range_image_mapping::simulation {
namespace {

using Eigen::AlignedBox2d;
using Eigen::Vector2d;
using Eigen::Vector3d;

// A car with the sensor on its roof at 1.8-2.5 m; 1.5 m leaves room for the car itself.
constexpr RouteClearance kClearance{1.5, 1.0, 3.0};
constexpr double kPlacementMargin = 0.3;  // what a smoothed trajectory may stray from the route
constexpr double kCornerRadius = 6.0;     // turning at an intersection
constexpr double kRouteSpacing = 5.0;     // route points follow the ground this closely
constexpr double kKerbHeight = 0.14;
constexpr double kParkingGap = 0.15;  // between a parked car and the kerb
constexpr double kMaxSlope = 0.035;   // of the ground, rise over run
constexpr double kGridSpacing = 3.0;  // of the ground mesh
constexpr int kPoleSegments = 10;

// ---------------------------------------------------------------- ground

// A sum of long waves. |gradient| <= sum of amplitude * wavenumber, so that
// sum is set to the slope wanted; a linear interpolation over a grid stays
// within it (mean value theorem along each grid edge).
class Terrain {
 public:
  explicit Terrain(SeededRandom& random) {
    const double slope = random.uniform(0.5, 1.0) * kMaxSlope;
    double total_weight = 0.0;
    for (Wave& wave : waves_) total_weight += (wave.amplitude = random.uniform(0.2, 1.0));
    for (Wave& wave : waves_) {
      const double wavenumber = 2.0 * M_PI / random.uniform(60.0, 250.0);
      const double direction = random.uniform(0.0, 2.0 * M_PI);
      wave.wave_vector = wavenumber * Vector2d(std::cos(direction), std::sin(direction));
      wave.amplitude *= slope / total_weight / wavenumber;
      wave.phase = random.uniform(0.0, 2.0 * M_PI);
    }
  }

  double height(const Vector2d& at) const {
    double sum = 0.0;
    for (const Wave& wave : waves_)
      sum += wave.amplitude * std::sin(wave.wave_vector.dot(at) + wave.phase);
    return sum;
  }

 private:
  struct Wave {
    Vector2d wave_vector;
    double amplitude = 0.0, phase = 0.0;
  };
  std::array<Wave, 3> waves_;
};

// ---------------------------------------------------------------- streets

struct Street {
  double centre, width, sidewalk;
  bool parking;
  double carriagewayLow() const { return centre - width / 2 + sidewalk; }
  double carriagewayHigh() const { return centre + width / 2 - sidewalk; }
  double low() const { return centre - width / 2; }
  double high() const { return centre + width / 2; }
};

// Streets across one axis, blocks between them; the first and last blocks
// reach the scene's edge.
std::vector<Street> planStreets(double half, SeededRandom& random) {
  const double block = std::clamp(half / 3.0, 25.0, 40.0);
  for (int attempt = 0; attempt < 50; ++attempt) {
    std::vector<Street> streets;
    double position = -half + random.uniform(0.6, 1.0) * block;
    while (true) {
      Street street;
      street.width = random.uniform(10.0, 15.0);
      street.sidewalk = std::min(random.uniform(1.8, 2.6), (street.width - 6.5) / 2.0);
      street.centre = position + street.width / 2;
      if (street.high() + 0.6 * block > half) break;
      // A parked car's inner side must stay clear of the route on the centre line.
      const double car_inner_side = (street.width / 2 - street.sidewalk) - kParkingGap - 1.85;
      street.parking = car_inner_side >= kClearance.distance_m + kPlacementMargin;
      streets.push_back(street);
      position = street.high() + random.uniform(block, 2.0 * block);
    }
    if (streets.size() >= 2) return streets;
  }
  throw std::logic_error("planStreets: no two streets fit");
}

struct Interval {
  double low, high;
  bool street_below, street_above;  // whether a street borders it at low, at high
};

// What lies between the streets (including their sidewalks).
std::vector<Interval> blocksBetween(const std::vector<Street>& streets, double half) {
  std::vector<Interval> blocks;
  double low = -half;
  bool street_below = false;
  for (const Street& street : streets) {
    blocks.push_back({low, street.low(), street_below, true});
    low = street.high();
    street_below = true;
  }
  blocks.push_back({low, half, true, false});
  return blocks;
}

// Along a street, the stretches between crossing carriageways.
std::vector<Interval> stretchesBetween(const std::vector<Street>& crossing, double half) {
  std::vector<Interval> stretches;
  double low = -half;
  for (const Street& street : crossing) {
    stretches.push_back({low, street.carriagewayLow(), low > -half, true});
    low = street.carriagewayHigh();
  }
  stretches.push_back({low, half, true, false});
  return stretches;
}

// ---------------------------------------------------------------- 2D occupancy

// Footprints of placed objects, hashed into cells so checks stay local.
class Occupancy {
 public:
  bool isFree(const AlignedBox2d& footprint, double gap) const {
    AlignedBox2d spaced = footprint;
    spaced.min().array() -= gap;
    spaced.max().array() += gap;
    bool free = true;
    forCells(spaced, [&](int64_t key) {
      const auto found = cells_.find(key);
      if (found == cells_.end()) return;
      for (const AlignedBox2d& taken : found->second)
        if (taken.intersects(spaced)) free = false;
    });
    return free;
  }
  void take(const AlignedBox2d& footprint) {
    forCells(footprint, [&](int64_t key) { cells_[key].push_back(footprint); });
  }

 private:
  static constexpr double kCell = 8.0;
  template <typename Visit>
  static void forCells(const AlignedBox2d& box, Visit&& visit) {
    const int x0 = int(std::floor(box.min().x() / kCell)),
              x1 = int(std::floor(box.max().x() / kCell));
    const int y0 = int(std::floor(box.min().y() / kCell)),
              y1 = int(std::floor(box.max().y() / kCell));
    for (int x = x0; x <= x1; ++x)
      for (int y = y0; y <= y1; ++y) visit((int64_t(x) << 32) ^ int64_t(uint32_t(y)));
  }
  std::map<int64_t, std::vector<AlignedBox2d>> cells_;
};

// ---------------------------------------------------------------- objects

// A convex blob: an icosphere with its vertices pushed in and out.
TriangleMesh blob(const Vector3d& centre, double radius, SeededRandom& random) {
  TriangleMesh sphere = makeSphere(Eigen::Vector3f::Zero(), 1.0f, 1);
  for (Eigen::Vector3f& vertex : sphere.vertices)
    vertex = (centre + vertex.cast<double>() * radius * random.uniform(0.8, 1.15)).cast<float>();
  return sphere;
}

SceneObject tree(const Vector3d& base, double scale, SeededRandom& random) {
  SceneObject object;
  const double trunk_radius = random.uniform(0.12, 0.22) * scale;
  const double trunk_height = random.uniform(2.2, 3.5) * scale;
  const double crown_radius = random.uniform(1.3, 2.4) * scale;
  const Vector3d crown = base + Vector3d(0.0, 0.0, trunk_height + 0.7 * crown_radius);
  object.add(makeCylinder((base - Vector3d(0, 0, 0.3)).cast<float>(), float(trunk_radius),
                          float(trunk_height + 0.3 + 0.5 * crown_radius), 10),
             SurfaceClass::kVegetation);
  const int blobs = uniformInteger(random, 6, 11);
  for (int i = 0; i < blobs; ++i) {
    const double radius = random.uniform(0.45, 0.75) * crown_radius;
    Vector3d offset;
    do offset = Vector3d(random.uniform(-1, 1), random.uniform(-1, 1), random.uniform(-0.7, 0.7));
    while (offset.squaredNorm() > 1.0);
    object.add(blob(crown + offset * (crown_radius - radius), radius, random),
               SurfaceClass::kVegetation);
  }
  return object;
}

SceneObject bush(const Vector3d& base, SeededRandom& random) {
  SceneObject object;
  const int blobs = uniformInteger(random, 2, 4);
  for (int i = 0; i < blobs; ++i) {
    const double radius = random.uniform(0.4, 0.9);
    const Vector3d centre =
        base + Vector3d(random.uniform(-0.6, 0.6), random.uniform(-0.6, 0.6), 0.3 * radius);
    object.add(blob(centre, radius, random), SurfaceClass::kVegetation);
  }
  return object;
}

// A car from a few boxes and four wheels; local frame x forward, z up, origin
// on the ground under its centre.
SceneObject car(double length, double width, bool van, SeededRandom& random) {
  SceneObject object;
  const double clearance = 0.3;
  if (van) {
    object.addBox(Vector3d(-length / 2, -width / 2, clearance),
                  Vector3d(length / 2 - 0.9, width / 2, 2.1), SurfaceClass::kVehicle);
    object.addBox(Vector3d(length / 2 - 0.9, -width / 2, clearance),
                  Vector3d(length / 2, width / 2, 1.15), SurfaceClass::kVehicle);
  } else {
    const double body_top = clearance + random.uniform(0.55, 0.7);
    object.addBox(Vector3d(-length / 2, -width / 2, clearance),
                  Vector3d(length / 2, width / 2, body_top), SurfaceClass::kVehicle);
    const double cabin_start = -length / 2 + random.uniform(0.18, 0.28) * length;
    const double cabin_end = cabin_start + random.uniform(0.45, 0.55) * length;
    object.addBox(Vector3d(cabin_start, -width / 2 + 0.1, body_top),
                  Vector3d(cabin_end, width / 2 - 0.1, body_top + random.uniform(0.45, 0.55)),
                  SurfaceClass::kVehicle);
  }
  const float radius = float(random.uniform(0.3, 0.34)), tyre = 0.22f;
  for (int wheel = 0; wheel < 4; ++wheel) {
    const double x = (wheel & 1) ? length / 2 - 0.8 : -length / 2 + 0.8;
    // Turned so the cylinder's axis (z) points to -y: it spans [y - tyre, y].
    const double y = (wheel & 2) ? width / 2 + 0.01 : -width / 2 + tyre - 0.01;
    const Eigen::Isometry3f pose = Eigen::Translation3f(float(x), float(y), radius) *
                                   Eigen::AngleAxisf(float(M_PI / 2), Eigen::Vector3f::UnitX());
    object.add(makeCylinder(Eigen::Vector3f::Zero(), radius, tyre, 12), SurfaceClass::kVehicle,
               pose);
  }
  return object;
}

// A lamp post on the sidewalk, its arm reaching over the street (direction).
SceneObject lampPost(const Vector3d& base, const Vector2d& direction) {
  SceneObject object;
  const double height = 7.0, arm = 1.2;
  object.add(makeCylinder(base.cast<float>(), 0.08f, float(height), kPoleSegments),
             SurfaceClass::kPole);
  const Vector3d top = base + Vector3d(0, 0, height);
  const Vector3d reach(direction.x() * arm, direction.y() * arm, 0.0);
  object.addBox((top - Vector3d(0.05, 0.05, 0.1)).cwiseMin(top + reach - Vector3d(0.05, 0.05, 0.1)),
                (top + Vector3d(0.05, 0.05, 0.0)).cwiseMax(top + reach + Vector3d(0.05, 0.05, 0.0)),
                SurfaceClass::kPole);
  const Vector3d head = top + reach;
  object.addBox(head - Vector3d(0.25, 0.25, 0.25), head + Vector3d(0.25, 0.25, -0.1),
                SurfaceClass::kPole);
  return object;
}

// A sign: a thin pole and a plate facing along the street (along_axis).
SceneObject signPost(const Vector3d& base, int along_axis) {
  SceneObject object;
  const double height = 2.6;
  object.add(makeCylinder(base.cast<float>(), 0.035f, float(height), kPoleSegments),
             SurfaceClass::kPole);
  const Vector3d half_plate =
      along_axis == 0 ? Vector3d(0.015, 0.3, 0.3) : Vector3d(0.3, 0.015, 0.3);
  const Vector3d centre = base + Vector3d(0, 0, height - 0.3);
  object.addBox(centre - half_plate, centre + half_plate, SurfaceClass::kPole);
  return object;
}

SceneObject bench(const AlignedBox2d& footprint, double ground, int back_axis, bool back_at_high) {
  SceneObject object;
  object.addBox(Vector3d(footprint.min().x(), footprint.min().y(), ground + 0.42),
                Vector3d(footprint.max().x(), footprint.max().y(), ground + 0.47),
                SurfaceClass::kFurniture);
  for (int end = 0; end < 2; ++end) {
    AlignedBox2d leg = footprint;
    const int length_axis = 1 - back_axis;
    if (end == 0)
      leg.max()[length_axis] = leg.min()[length_axis] + 0.06;
    else
      leg.min()[length_axis] = leg.max()[length_axis] - 0.06;
    object.addBox(Vector3d(leg.min().x(), leg.min().y(), ground - 0.1),
                  Vector3d(leg.max().x(), leg.max().y(), ground + 0.42), SurfaceClass::kFurniture);
  }
  AlignedBox2d back = footprint;
  if (back_at_high)
    back.min()[back_axis] = back.max()[back_axis] - 0.05;
  else
    back.max()[back_axis] = back.min()[back_axis] + 0.05;
  object.addBox(Vector3d(back.min().x(), back.min().y(), ground + 0.47),
                Vector3d(back.max().x(), back.max().y(), ground + 0.9), SurfaceClass::kFurniture);
  return object;
}

// ---------------------------------------------------------------- buildings

struct FacadeStyle {
  double bay_width, window_width, window_height, sill, recess;
  double parapet;
  bool bands, pilasters, cornice, shopfront;
  double balcony_probability;
};

FacadeStyle randomStyle(SeededRandom& random) {
  FacadeStyle style;
  style.bay_width = random.uniform(2.6, 3.6);
  style.window_width = random.uniform(0.35, 0.65) * style.bay_width;
  style.window_height = random.uniform(1.2, 1.7);
  style.sill = random.uniform(0.7, 1.0);
  style.recess = random.uniform(0.12, 0.35);
  style.parapet = random.uniform(0.3, 1.1);
  style.bands = chance(random, 0.4);
  style.pilasters = chance(random, 0.3);
  style.cornice = chance(random, 0.5);
  style.shopfront = chance(random, 0.5);
  style.balcony_probability = chance(random, 0.4) ? random.uniform(0.2, 0.7) : 0.0;
  return style;
}

// One side of a building: world point = origin + along * u + z * up, outward n.
struct FacadeFrame {
  Vector3d origin, along, outward;
  double length;
  Vector3d at(double u, double z) const { return origin + u * along + Vector3d(0, 0, z); }
  // An axis-aligned box given in facade coordinates (outward distance, along, height).
  void addBox(SceneObject& object, double u0, double u1, double out0, double out1, double z0,
              double z1) const {
    const Vector3d a = at(u0, z0) + out0 * outward, b = at(u1, z1) + out1 * outward;
    object.addBox(a.cwiseMin(b), a.cwiseMax(b), SurfaceClass::kBuilding);
  }
  void addWall(SceneObject& object, double u0, double u1, double z0, double z1) const {
    if (u1 - u0 < 1e-6 || z1 - z0 < 1e-6) return;
    object.addQuad(at(u0, z0), (u1 - u0) * along, Vector3d(0, 0, z1 - z0), outward,
                   SurfaceClass::kBuilding);
  }
};

FacadeFrame facadeFrame(const AlignedBox2d& footprint, int side) {
  const Vector2d& lo = footprint.min();
  const Vector2d& hi = footprint.max();
  switch (side) {
    case 0:
      return {Vector3d(lo.x(), lo.y(), 0), Vector3d(1, 0, 0), Vector3d(0, -1, 0), hi.x() - lo.x()};
    case 1:
      return {Vector3d(hi.x(), lo.y(), 0), Vector3d(0, 1, 0), Vector3d(1, 0, 0), hi.y() - lo.y()};
    case 2:
      return {Vector3d(hi.x(), hi.y(), 0), Vector3d(-1, 0, 0), Vector3d(0, 1, 0), hi.x() - lo.x()};
    default:
      return {Vector3d(lo.x(), hi.y(), 0), Vector3d(0, -1, 0), Vector3d(-1, 0, 0), hi.y() - lo.y()};
  }
}

// A window recessed into the wall: the wall around it, the pane set back, the
// four reveals.
void addRecessedOpening(SceneObject& object, const FacadeFrame& frame, double cell_u0,
                        double cell_u1, double cell_z0, double cell_z1, double u0, double u1,
                        double z0, double z1, double depth) {
  frame.addWall(object, cell_u0, cell_u1, cell_z0, z0);
  frame.addWall(object, cell_u0, cell_u1, z1, cell_z1);
  frame.addWall(object, cell_u0, u0, z0, z1);
  frame.addWall(object, u1, cell_u1, z0, z1);
  const Vector3d back = -depth * frame.outward;
  const Vector3d width = (u1 - u0) * frame.along, height(0, 0, z1 - z0);
  object.addQuad(frame.at(u0, z0) + back, width, height, frame.outward, SurfaceClass::kBuilding);
  object.addQuad(frame.at(u0, z0) + back, depth * frame.outward, height, frame.along,
                 SurfaceClass::kBuilding);
  object.addQuad(frame.at(u1, z0) + back, depth * frame.outward, height, -frame.along,
                 SurfaceClass::kBuilding);
  object.addQuad(frame.at(u0, z0) + back, width, depth * frame.outward, Vector3d::UnitZ(),
                 SurfaceClass::kBuilding);
  object.addQuad(frame.at(u0, z1) + back, width, depth * frame.outward, -Vector3d::UnitZ(),
                 SurfaceClass::kBuilding);
}

struct Storeys {
  double ground;    // level of the first storey's floor
  double height;    // of one storey
  int first, last;  // storeys [first, last) are in this part
  double bottom() const { return ground + first * height; }
  double top() const { return ground + last * height; }
};

// Bays of windows per storey, the bottom (from `base`) and the parapet plain.
void addDetailedFacade(SceneObject& object, const FacadeFrame& frame, double base,
                       const Storeys& storeys, const FacadeStyle& style, SeededRandom& random) {
  const double roof = storeys.top() + style.parapet;
  const int bays = std::max(1, static_cast<int>((frame.length - 1.0) / style.bay_width));
  const double bay = std::min(style.bay_width, frame.length / bays);
  const double margin = (frame.length - bays * bay) / 2.0;
  frame.addWall(object, 0.0, margin, base, roof);
  frame.addWall(object, frame.length - margin, frame.length, base, roof);
  frame.addWall(object, margin, frame.length - margin, base, storeys.bottom());
  frame.addWall(object, margin, frame.length - margin, storeys.top(), roof);
  for (int storey = storeys.first; storey < storeys.last; ++storey) {
    const double z0 = storeys.ground + storey * storeys.height, z1 = z0 + storeys.height;
    for (int b = 0; b < bays; ++b) {
      const double u0 = margin + b * bay, u1 = u0 + bay, middle = (u0 + u1) / 2;
      if (storey == 0 && style.shopfront) {
        const bool door = chance(random, 0.3);
        const double half_width = door ? 0.6 : 0.4 * bay;
        const double sill = door ? 0.0 : 0.5;
        const double top = std::min(z1 - 0.5, z0 + (door ? 2.4 : 2.8));
        addRecessedOpening(object, frame, u0, u1, z0, z1, middle - half_width, middle + half_width,
                           z0 + sill, top, door ? 0.5 : 0.2);
        continue;
      }
      if (chance(random, 0.08)) {  // a blank bay
        frame.addWall(object, u0, u1, z0, z1);
        continue;
      }
      const double sill = z0 + style.sill, head = std::min(sill + style.window_height, z1 - 0.3);
      addRecessedOpening(object, frame, u0, u1, z0, z1, middle - style.window_width / 2,
                         middle + style.window_width / 2, sill, head, style.recess);
      if (storey > 0 && chance(random, style.balcony_probability)) {
        const double depth = random.uniform(1.0, 1.4);
        frame.addBox(object, u0 + 0.15, u1 - 0.15, 0.0, depth, z0 - 0.15, z0);
        frame.addBox(object, u0 + 0.15, u1 - 0.15, depth - 0.05, depth, z0, z0 + 1.0);
        frame.addBox(object, u0 + 0.15, u0 + 0.2, 0.0, depth - 0.05, z0, z0 + 1.0);
        frame.addBox(object, u1 - 0.2, u1 - 0.15, 0.0, depth - 0.05, z0, z0 + 1.0);
      }
    }
    if (style.bands && storey > storeys.first)
      frame.addBox(object, 0.0, frame.length, -0.05, 0.1, z0 - 0.1, z0 + 0.1);
  }
  if (style.pilasters)
    for (int b = 0; b <= bays; ++b) {
      const double u = margin + b * bay;
      frame.addBox(object, std::max(0.0, u - 0.15), std::min(frame.length, u + 0.15), -0.05, 0.12,
                   storeys.bottom(), storeys.top());
    }
  if (style.cornice)
    frame.addBox(object, -0.35, frame.length + 0.35, -0.05, 0.35, roof - 0.3, roof + 0.1);
}

// One prism of a building: facades on its four sides (detailed where a street
// sees them), a flat roof with some plant on it.
void addBuildingPart(SceneObject& object, const AlignedBox2d& footprint, double base,
                     const Storeys& storeys, const std::array<bool, 4>& street_sides,
                     const FacadeStyle& style, SeededRandom& random) {
  const double roof = storeys.top() + style.parapet;
  for (int side = 0; side < 4; ++side) {
    const FacadeFrame frame = facadeFrame(footprint, side);
    if (street_sides[side] && frame.length >= 4.0)
      addDetailedFacade(object, frame, base, storeys, style, random);
    else
      frame.addWall(object, 0.0, frame.length, base, roof);
  }
  const Vector2d size = footprint.sizes();
  object.addQuad(Vector3d(footprint.min().x(), footprint.min().y(), roof), Vector3d(size.x(), 0, 0),
                 Vector3d(0, size.y(), 0), Vector3d::UnitZ(), SurfaceClass::kBuilding);
  const int units = uniformInteger(random, 0, 2);
  for (int i = 0; i < units; ++i) {
    const Vector2d unit(random.uniform(1.0, 3.0), random.uniform(1.0, 3.0));
    if ((unit.array() > size.array() - 1.0).any()) continue;
    const Vector2d corner =
        footprint.min() + Vector2d(random.uniform(0.5, size.x() - unit.x() - 0.5),
                                   random.uniform(0.5, size.y() - unit.y() - 0.5));
    object.addBox(
        Vector3d(corner.x(), corner.y(), roof - 0.1),
        Vector3d(corner.x() + unit.x(), corner.y() + unit.y(), roof + random.uniform(0.8, 2.5)),
        SurfaceClass::kBuilding);
  }
}

// ---------------------------------------------------------------- the city

class OutdoorGenerator {
 public:
  OutdoorGenerator(uint32_t seed, double extent_m)
      : random_({seed, 0x0D00Full}), half_(extent_m / 2.0), terrain_(random_) {}

  Scene generate() {
    streets_[0] = planStreets(half_, random_);  // at constant x, running along y
    streets_[1] = planStreets(half_, random_);  // at constant y, running along x
    SceneAssembly assembly(planRoute(), kClearance, kPlacementMargin);
    addGround(assembly);
    const std::vector<Interval> blocks_x = blocksBetween(streets_[0], half_);
    const std::vector<Interval> blocks_y = blocksBetween(streets_[1], half_);
    for (const Interval& x : blocks_x)
      for (const Interval& y : blocks_y) addBlock(assembly, x, y);
    addStreetFurniture(assembly);
    addParkedCars(assembly);
    return std::move(assembly).finish();
  }

 private:
  // Road surface under a point; sidewalks are kKerbHeight above it.
  double ground(const Vector2d& at) const { return terrain_.height(at); }
  double sidewalk(const Vector2d& at) const { return terrain_.height(at) + kKerbHeight; }

  // ------------------------------------------------------------ route

  // The boundary of a random set of blocks, grown from one block without
  // holes or corner-only contacts, so the boundary is one simple loop.
  std::vector<Eigen::Vector3d> planRoute() {
    const int columns = int(streets_[0].size()) - 1, rows = int(streets_[1].size()) - 1;
    std::vector<char> inside(columns * rows, 0);
    const auto in = [&](int i, int j) {
      return i >= 0 && j >= 0 && i < columns && j < rows && inside[i * rows + j];
    };
    const int total = columns * rows;
    const int target = uniformInteger(random_, std::max(1, total / 3), total);
    inside[uniformInteger(random_, 0, columns - 1) * rows + uniformInteger(random_, 0, rows - 1)] =
        1;
    for (int grown = 1; grown < target;) {
      std::vector<int> candidates;
      for (int i = 0; i < columns; ++i)
        for (int j = 0; j < rows; ++j)
          if (!in(i, j) && (in(i - 1, j) || in(i + 1, j) || in(i, j - 1) || in(i, j + 1)))
            candidates.push_back(i * rows + j);
      bool added = false;
      while (!candidates.empty() && !added) {
        const int pick = uniformInteger(random_, 0, int(candidates.size()) - 1);
        const int cell = candidates[pick];
        candidates.erase(candidates.begin() + pick);
        inside[cell] = 1;
        if (isSimple(inside, columns, rows)) {
          added = true;
          ++grown;
        } else {
          inside[cell] = 0;
        }
      }
      if (!added) break;
    }

    // Directed boundary edges, counter-clockwise around the set, between
    // intersections (i, j) = (streets_[0][i], streets_[1][j]).
    std::map<std::pair<int, int>, std::pair<int, int>> next;
    for (int i = 0; i < columns; ++i)
      for (int j = 0; j < rows; ++j) {
        if (!in(i, j)) continue;
        if (!in(i, j - 1)) next[{i, j}] = {i + 1, j};
        if (!in(i + 1, j)) next[{i + 1, j}] = {i + 1, j + 1};
        if (!in(i, j + 1)) next[{i + 1, j + 1}] = {i, j + 1};
        if (!in(i - 1, j)) next[{i, j + 1}] = {i, j};
      }
    std::vector<Vector2d> corners;
    const std::pair<int, int> start = next.begin()->first;
    std::pair<int, int> at = start;
    do {
      corners.emplace_back(streets_[0][at.first].centre, streets_[1][at.second].centre);
      at = next.at(at);
    } while (at != start);

    std::vector<Eigen::Vector3d> route;
    for (const Vector2d& point : roundedLoop(corners, kCornerRadius, kRouteSpacing))
      route.emplace_back(point.x(), point.y(), ground(point));
    return route;
  }

  // No corner-only contact between blocks of the set, and no enclosed hole.
  static bool isSimple(const std::vector<char>& inside, int columns, int rows) {
    const auto in = [&](int i, int j) {
      return i >= 0 && j >= 0 && i < columns && j < rows && inside[i * rows + j];
    };
    for (int i = -1; i < columns; ++i)
      for (int j = -1; j < rows; ++j) {
        const bool a = in(i, j), b = in(i + 1, j), c = in(i, j + 1), d = in(i + 1, j + 1);
        if ((a && d && !b && !c) || (b && c && !a && !d)) return false;
      }
    // Everything outside the set must be reachable from beyond the grid.
    const int padded_columns = columns + 2, padded_rows = rows + 2;
    std::vector<char> reached(padded_columns * padded_rows, 0);
    std::vector<std::pair<int, int>> stack{{-1, -1}};
    reached[0] = 1;
    while (!stack.empty()) {
      const auto [i, j] = stack.back();
      stack.pop_back();
      const int steps[4][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
      for (const auto& step : steps) {
        const int ni = i + step[0], nj = j + step[1];
        if (ni < -1 || nj < -1 || ni > columns || nj > rows || in(ni, nj)) continue;
        char& seen = reached[(ni + 1) * padded_rows + (nj + 1)];
        if (!seen) {
          seen = 1;
          stack.emplace_back(ni, nj);
        }
      }
    }
    for (int i = 0; i < columns; ++i)
      for (int j = 0; j < rows; ++j)
        if (!in(i, j) && !reached[(i + 1) * padded_rows + (j + 1)]) return false;
    return true;
  }

  // ------------------------------------------------------------ ground

  // A height field on grid lines that include every kerb twice (road side and
  // sidewalk side), so kerbs are exact vertical steps and no triangle hides
  // under another.
  struct GridLine {
    double position;
    int side;  // -1, +1 for the two copies of a kerb line, 0 otherwise
    bool on_carriageway;
  };

  std::vector<GridLine> gridLines(const std::vector<Street>& streets) const {
    std::vector<GridLine> lines;
    const auto on_carriageway = [&](double position) {
      for (const Street& street : streets)
        if (position > street.carriagewayLow() && position < street.carriagewayHigh()) return true;
      return false;
    };
    const int count = static_cast<int>(std::ceil(2.0 * half_ / kGridSpacing));
    for (int k = 0; k <= count; ++k) {
      const double position = -half_ + 2.0 * half_ * k / count;
      bool near_kerb = false;
      for (const Street& street : streets)
        near_kerb |= std::abs(position - street.carriagewayLow()) < 0.3 ||
                     std::abs(position - street.carriagewayHigh()) < 0.3;
      if (!near_kerb) lines.push_back({position, 0, on_carriageway(position)});
    }
    for (const Street& street : streets) {
      lines.push_back({street.carriagewayLow(), -1, false});
      lines.push_back({street.carriagewayLow(), +1, true});
      lines.push_back({street.carriagewayHigh(), -1, true});
      lines.push_back({street.carriagewayHigh(), +1, false});
    }
    std::sort(lines.begin(), lines.end(), [](const GridLine& a, const GridLine& b) {
      return a.position != b.position ? a.position < b.position : a.side < b.side;
    });
    return lines;
  }

  void addGround(SceneAssembly& assembly) const {
    const std::vector<GridLine> xs = gridLines(streets_[0]), ys = gridLines(streets_[1]);
    const int nx = int(xs.size()), ny = int(ys.size());
    const auto raised = [&](int i, int j) {
      return !xs[i].on_carriageway && !ys[j].on_carriageway;
    };
    TriangleMesh mesh;
    mesh.vertices.reserve(std::size_t(nx) * ny);
    for (int i = 0; i < nx; ++i)
      for (int j = 0; j < ny; ++j) {
        const Vector2d at(xs[i].position, ys[j].position);
        mesh.vertices.emplace_back(float(at.x()), float(at.y()),
                                   float(ground(at) + (raised(i, j) ? kKerbHeight : 0.0)));
      }
    const auto index = [&](int i, int j) { return i * ny + j; };
    for (int i = 0; i + 1 < nx; ++i)
      for (int j = 0; j + 1 < ny; ++j) {
        const bool flat_x = xs[i + 1].position == xs[i].position,
                   flat_y = ys[j + 1].position == ys[j].position;
        if (flat_x && flat_y) continue;
        // A zero-width cell is a kerb face where the heights differ, nothing otherwise.
        if (flat_x && raised(i, j) == raised(i + 1, j) && raised(i, j + 1) == raised(i + 1, j + 1))
          continue;
        if (flat_y && raised(i, j) == raised(i, j + 1) && raised(i + 1, j) == raised(i + 1, j + 1))
          continue;
        mesh.triangles.emplace_back(index(i, j), index(i + 1, j), index(i + 1, j + 1));
        mesh.triangles.emplace_back(index(i, j), index(i + 1, j + 1), index(i, j + 1));
      }
    SceneObject object;
    object.add(mesh, SurfaceClass::kGround);
    assembly.add(object);
  }

  // ------------------------------------------------------------ blocks

  void addBlock(SceneAssembly& assembly, const Interval& x, const Interval& y) {
    const AlignedBox2d block(Vector2d(x.low, y.low), Vector2d(x.high, y.high));
    const std::array<bool, 4> street_sides{y.street_below, x.street_above, y.street_above,
                                           x.street_below};
    if (chance(random_, 0.1)) {
      addPark(assembly, block);
      return;
    }
    std::vector<AlignedBox2d> lots;
    splitLots(block, random_.uniform(20.0, 35.0), lots);
    for (const AlignedBox2d& lot : lots) {
      // A lot side faces a street where it lies on a street side of the block.
      std::array<bool, 4> facing{};
      std::array<bool, 4> on_block_edge{};
      on_block_edge[0] = lot.min().y() == block.min().y();
      on_block_edge[1] = lot.max().x() == block.max().x();
      on_block_edge[2] = lot.max().y() == block.max().y();
      on_block_edge[3] = lot.min().x() == block.min().x();
      for (int side = 0; side < 4; ++side) facing[side] = on_block_edge[side] && street_sides[side];
      if (lot.sizes().minCoeff() < 8.0 || chance(random_, 0.12)) {
        if (lot.sizes().minCoeff() >= 12.0 && chance(random_, 0.5))
          addParkingLot(assembly, lot);
        else
          addPark(assembly, lot);
        continue;
      }
      // Fronts on the building line, gaps and alleys elsewhere (wider than a
      // cornice's overhang, so neighbours and the scene's edge stay clear).
      AlignedBox2d footprint = lot;
      double insets[4];
      for (int side = 0; side < 4; ++side)
        insets[side] = facing[side] ? random_.uniform(0.0, 0.4) : random_.uniform(0.4, 2.0);
      footprint.min() += Vector2d(insets[3], insets[0]);
      footprint.max() -= Vector2d(insets[1], insets[2]);
      addBuilding(assembly, footprint, facing);
    }
  }

  void splitLots(const AlignedBox2d& area, double largest, std::vector<AlignedBox2d>& lots) {
    const Vector2d size = area.sizes();
    const int axis = size.x() >= size.y() ? 0 : 1;
    if (size[axis] <= largest) {
      lots.push_back(area);
      return;
    }
    const double cut = area.min()[axis] + size[axis] * random_.uniform(0.35, 0.65);
    AlignedBox2d low = area, high = area;
    low.max()[axis] = cut;
    high.min()[axis] = cut;
    splitLots(low, largest, lots);
    splitLots(high, largest, lots);
  }

  void addBuilding(SceneAssembly& assembly, const AlignedBox2d& footprint,
                   const std::array<bool, 4>& facing) {
    // The lowest and highest sidewalk level under the footprint.
    double lowest = 1e9, highest = -1e9;
    for (int i = 0; i <= 2; ++i)
      for (int j = 0; j <= 2; ++j) {
        const double level =
            sidewalk(footprint.min() + footprint.sizes().cwiseProduct(Vector2d(i, j) / 2.0));
        lowest = std::min(lowest, level);
        highest = std::max(highest, level);
      }
    const FacadeStyle style = randomStyle(random_);
    Storeys storeys;
    storeys.ground = highest;
    storeys.height = random_.uniform(3.0, 3.4);
    storeys.first = 0;
    storeys.last = std::min(uniformInteger(random_, 2, 9), static_cast<int>(30.0 / storeys.height));
    const double base = lowest - 0.5;

    SceneObject building;
    // Taller buildings may step back above a few storeys.
    const double setback = random_.uniform(2.0, 4.0);
    if (storeys.last >= 5 && chance(random_, 0.3) &&
        footprint.sizes().minCoeff() > 2.0 * setback + 8.0) {
      Storeys lower = storeys, upper = storeys;
      lower.last = upper.first = uniformInteger(random_, 2, storeys.last - 2);
      FacadeStyle lower_style = style;
      lower_style.parapet = 0.0;
      lower_style.cornice = false;
      addBuildingPart(building, footprint, base, lower, facing, lower_style, random_);
      AlignedBox2d top = footprint;
      top.min() += Vector2d(facing[3] ? setback : 0.0, facing[0] ? setback : 0.0);
      top.max() -= Vector2d(facing[1] ? setback : 0.0, facing[2] ? setback : 0.0);
      addBuildingPart(building, top, lower.top() - 0.05, upper, facing, style, random_);
    } else {
      addBuildingPart(building, footprint, base, storeys, facing, style, random_);
    }
    assembly.add(building);
  }

  // Trees, bushes and benches in an open lot or a park block.
  void addPark(SceneAssembly& assembly, const AlignedBox2d& area) {
    const double usable = area.volume();
    const int trees = static_cast<int>(usable / random_.uniform(60.0, 120.0));
    for (int i = 0; i < trees; ++i) {
      const Vector2d at = randomPoint(area, 2.0);
      const AlignedBox2d footprint(at - Vector2d(1.5, 1.5), at + Vector2d(1.5, 1.5));
      if (!occupancy_.isFree(footprint, 0.5)) continue;
      const SceneObject object =
          tree(Vector3d(at.x(), at.y(), sidewalk(at)), random_.uniform(0.8, 1.3), random_);
      if (assembly.addIfClear(object)) occupancy_.take(footprint);
    }
    const int bushes = static_cast<int>(usable / random_.uniform(40.0, 80.0));
    for (int i = 0; i < bushes; ++i) {
      const Vector2d at = randomPoint(area, 1.5);
      const AlignedBox2d footprint(at - Vector2d(1.2, 1.2), at + Vector2d(1.2, 1.2));
      if (!occupancy_.isFree(footprint, 0.3)) continue;
      if (assembly.addIfClear(bush(Vector3d(at.x(), at.y(), sidewalk(at)), random_)))
        occupancy_.take(footprint);
    }
    const int benches = uniformInteger(random_, 0, 3);
    for (int i = 0; i < benches; ++i) {
      const Vector2d at = randomPoint(area, 2.0);
      const int back_axis = uniformInteger(random_, 0, 1), length_axis = 1 - back_axis;
      const AlignedBox2d footprint =
          boxOnAxes(length_axis, at[length_axis] - 0.9, at[length_axis] + 0.9, at[back_axis] - 0.25,
                    at[back_axis] + 0.25);
      if (!occupancy_.isFree(footprint, 0.5)) continue;
      if (assembly.addIfClear(bench(footprint, sidewalk(at), back_axis, chance(random_, 0.5))))
        occupancy_.take(footprint);
    }
  }

  // Rows of cars parked side by side across the lot, aisles between the rows.
  void addParkingLot(SceneAssembly& assembly, const AlignedBox2d& area) {
    const int row_axis = area.sizes().x() >= area.sizes().y() ? 0 : 1, depth_axis = 1 - row_axis;
    const double row_depth = 5.0, aisle = 6.0, bay = 2.6;
    for (double row = area.min()[depth_axis] + 1.0; row + row_depth <= area.max()[depth_axis] - 1.0;
         row += row_depth + aisle) {
      for (double along = area.min()[row_axis] + 1.0; along + bay <= area.max()[row_axis] - 1.0;
           along += bay) {
        if (!chance(random_, 0.75)) continue;
        const bool van = chance(random_, 0.1);
        const double length = van ? random_.uniform(4.8, 5.0) : random_.uniform(3.8, 4.8);
        const double width = van ? random_.uniform(1.9, 2.0) : random_.uniform(1.7, 1.85);
        const Vector2d centre = onAxes(row_axis, along + bay / 2, row + row_depth / 2);
        const double heading = (depth_axis == 0 ? 0.0 : M_PI / 2) +
                               (chance(random_, 0.5) ? M_PI : 0.0) + random_.uniform(-0.05, 0.05);
        const Eigen::Isometry3f pose =
            Eigen::Translation3f(float(centre.x()), float(centre.y()), float(sidewalk(centre))) *
            Eigen::AngleAxisf(float(heading), Eigen::Vector3f::UnitZ());
        SceneObject placed;
        placed.add(car(length, width, van, random_), pose);
        tryPlace(assembly,
                 boxOnAxes(row_axis, along + 0.1, along + bay - 0.1, row, row + row_depth), 0.0,
                 placed);
      }
    }
    const Vector2d lamp = area.center();
    tryPlace(assembly, AlignedBox2d(lamp.array() - 0.2, lamp.array() + 0.2), 0.1,
             lampPost(Vector3d(lamp.x(), lamp.y(), sidewalk(lamp) - 0.1), Vector2d::UnitX()));
  }

  Vector2d randomPoint(const AlignedBox2d& area, double margin) {
    const Vector2d low = area.min().array() + margin, high = area.max().array() - margin;
    if ((high.array() <= low.array()).any()) return area.center();
    return Vector2d(random_.uniform(low.x(), high.x()), random_.uniform(low.y(), high.y()));
  }

  // ------------------------------------------------------------ street furniture

  // Lamp posts, trees, signs and bollards along both sidewalks of every street.
  void addStreetFurniture(SceneAssembly& assembly) {
    for (int axis = 0; axis < 2; ++axis) {
      const int along_axis = 1 - axis;  // streets at constant x run along y
      for (const Street& street : streets_[axis]) {
        for (int side = -1; side <= 1; side += 2) {
          const double kerb = side < 0 ? street.carriagewayLow() : street.carriagewayHigh();
          for (const Interval& stretch : stretchesBetween(streets_[1 - axis], half_)) {
            if (stretch.high - stretch.low < 6.0) continue;
            addAlongSidewalk(assembly, street, along_axis, side, kerb, stretch);
          }
        }
      }
    }
  }

  void addAlongSidewalk(SceneAssembly& assembly, const Street& street, int along_axis, int side,
                        double kerb, const Interval& stretch) {
    const auto at = [&](double along, double from_kerb) {
      return onAxes(along_axis, along, kerb + side * from_kerb);
    };
    const Vector2d toward_street = -side * onAxes(along_axis, 0.0, 1.0);
    // Lamp posts at a regular spacing.
    const double lamp_spacing = random_.uniform(25.0, 35.0);
    for (double along = stretch.low + random_.uniform(3.0, lamp_spacing);
         along < stretch.high - 3.0; along += lamp_spacing) {
      const Vector2d base = at(along, 0.45);
      tryPlace(assembly, AlignedBox2d(base.array() - 0.2, base.array() + 0.2), 0.3,
               lampPost(Vector3d(base.x(), base.y(), sidewalk(base) - 0.1), toward_street));
    }
    // Trees where the sidewalk is wide enough.
    if (street.sidewalk >= 2.3) {
      const double tree_spacing = random_.uniform(8.0, 14.0);
      for (double along = stretch.low + random_.uniform(4.0, 4.0 + tree_spacing);
           along < stretch.high - 4.0; along += tree_spacing * random_.uniform(0.8, 1.2)) {
        const Vector2d base = at(along, 1.0);
        tryPlace(
            assembly, AlignedBox2d(base.array() - 0.6, base.array() + 0.6), 0.5,
            tree(Vector3d(base.x(), base.y(), sidewalk(base)), random_.uniform(0.6, 0.9), random_));
      }
    }
    // Signs and bins here and there.
    const int signs =
        static_cast<int>((stretch.high - stretch.low) / 25.0 * random_.uniform(0.3, 1.0));
    for (int i = 0; i < signs; ++i) {
      const Vector2d base = at(random_.uniform(stretch.low + 2.0, stretch.high - 2.0), 0.35);
      tryPlace(assembly, AlignedBox2d(base.array() - 0.35, base.array() + 0.35), 0.3,
               signPost(Vector3d(base.x(), base.y(), sidewalk(base) - 0.1), along_axis));
    }
    const int bins = uniformInteger(random_, 0, 2);
    for (int i = 0; i < bins; ++i) {
      const Vector2d centre =
          at(random_.uniform(stretch.low + 2.0, stretch.high - 2.0), street.sidewalk - 0.5);
      const AlignedBox2d footprint(centre.array() - 0.25, centre.array() + 0.25);
      SceneObject bin;
      const double level = sidewalk(centre);
      bin.addBox(Vector3d(footprint.min().x(), footprint.min().y(), level - 0.1),
                 Vector3d(footprint.max().x(), footprint.max().y(), level + 1.0),
                 SurfaceClass::kFurniture);
      tryPlace(assembly, footprint, 0.3, bin);
    }
    // Bollards guarding the corners.
    for (const double end : {stretch.low, stretch.high}) {
      if (std::abs(end) >= half_ || !chance(random_, 0.4)) continue;
      const double inward = end == stretch.low ? 1.0 : -1.0;
      for (int k = 0; k < 3; ++k) {
        const Vector2d base = at(end + inward * (1.0 + 1.2 * k), 0.3);
        SceneObject bollard;
        bollard.add(makeCylinder(Eigen::Vector3f(float(base.x()), float(base.y()),
                                                 float(sidewalk(base) - 0.1)),
                                 0.1f, 1.0f, kPoleSegments),
                    SurfaceClass::kPole);
        tryPlace(assembly, AlignedBox2d(base.array() - 0.15, base.array() + 0.15), 0.2, bollard);
      }
    }
  }

  bool tryPlace(SceneAssembly& assembly, const AlignedBox2d& footprint, double gap,
                const SceneObject& object) {
    if (!occupancy_.isFree(footprint, gap) || !assembly.addIfClear(object)) return false;
    occupancy_.take(footprint);
    return true;
  }

  // Rows of cars along the kerbs, away from the intersections.
  void addParkedCars(SceneAssembly& assembly) {
    for (int axis = 0; axis < 2; ++axis) {
      const int along_axis = 1 - axis;
      for (const Street& street : streets_[axis]) {
        if (!street.parking) continue;
        for (int side = -1; side <= 1; side += 2) {
          const double kerb = side < 0 ? street.carriagewayLow() : street.carriagewayHigh();
          for (const Interval& stretch : blocksBetween(streets_[1 - axis], half_)) {
            double along =
                stretch.low + (stretch.street_below ? 3.0 : 1.0) + random_.uniform(0.0, 4.0);
            const double end = stretch.high - (stretch.street_above ? 3.0 : 1.0);
            while (true) {
              const bool van = chance(random_, 0.15);
              const double length = van ? random_.uniform(4.8, 5.6) : random_.uniform(3.8, 4.8);
              const double width = van ? random_.uniform(1.9, 2.0) : random_.uniform(1.7, 1.85);
              if (along + length > end) break;
              if (chance(random_, 0.7)) {
                const Vector2d centre =
                    onAxes(along_axis, along + length / 2, kerb - side * (kParkingGap + width / 2));
                const double heading = (along_axis == 0 ? 0.0 : M_PI / 2) +
                                       (chance(random_, 0.5) ? M_PI : 0.0) +
                                       random_.uniform(-0.03, 0.03);
                const Eigen::Isometry3f pose =
                    Eigen::Translation3f(float(centre.x()), float(centre.y()),
                                         float(ground(centre))) *
                    Eigen::AngleAxisf(float(heading), Eigen::Vector3f::UnitZ());
                SceneObject placed;
                placed.add(car(length, width, van, random_), pose);
                const AlignedBox2d footprint =
                    boxOnAxes(along_axis, along, along + length, centre[1 - along_axis] - width / 2,
                              centre[1 - along_axis] + width / 2);
                tryPlace(assembly, footprint, 0.2, placed);
              }
              along += length + random_.uniform(0.8, 3.0);
            }
          }
        }
      }
    }
  }

  SeededRandom random_;
  double half_;
  Terrain terrain_;
  std::vector<Street> streets_[2];
  Occupancy occupancy_;
};

}  // namespace

Scene generateOutdoorScene(uint32_t seed, double extent_m) {
  return OutdoorGenerator(seed, extent_m).generate();
}

}  // namespace range_image_mapping::simulation
