#include "traffic_street.h"

#include "random_choice.h"
#include "scene_assembly.h"

#include <algorithm>
#include <cmath>

namespace range_image_mapping::simulation {
namespace {

using Eigen::Vector3d;

constexpr double kCrossStreetWidthM = 11.0;
constexpr double kCrossStreetReachM = 150.0;  // the cross street runs this far either side
constexpr double kBackLotDepthM = 30.0;       // ground behind the facades, seen through alleys
constexpr double kMaxSetbackM = 1.5;          // facades step back from the sidewalk up to this

// Horizontal ground quad facing up.
void addGround(SceneObject& object, double x0, double x1, double y0, double y1, double z) {
  if (x1 <= x0 || y1 <= y0) return;
  object.addQuad(Vector3d(x0, y0, z), Vector3d(x1 - x0, 0, 0), Vector3d(0, y1 - y0, 0), Vector3d::UnitZ(),
                 SurfaceClass::kGround);
}

// A vertical kerb face along x (at y, facing normal_y) or along y (at x, facing normal_x).
void addKerbAlongX(SceneObject& object, double x0, double x1, double y, double facing_y, double height) {
  if (x1 <= x0) return;
  object.addQuad(Vector3d(x0, y, 0), Vector3d(x1 - x0, 0, 0), Vector3d(0, 0, height), Vector3d(0, facing_y, 0),
                 SurfaceClass::kGround);
}
void addKerbAlongY(SceneObject& object, double y0, double y1, double x, double facing_x, double height) {
  if (y1 <= y0) return;
  object.addQuad(Vector3d(x, y0, 0), Vector3d(0, y1 - y0, 0), Vector3d(0, 0, height), Vector3d(facing_x, 0, 0),
                 SurfaceClass::kGround);
}

// One building of a row: a block with pilasters and floor bands on its street
// face, which give the odometry structure along the road, and a cornice.
// side: -1 for the row at low y (street face toward +y), +1 at high y.
void addBuilding(SceneObject& object, double x0, double x1, double facade_y, int side, double base_z,
                 SeededRandom& random) {
  const double depth = random.uniform(12.0, 20.0);
  const double height = random.uniform(7.0, 24.0);
  const double back_y = facade_y + side * depth;
  object.addBox(Vector3d(x0, std::min(facade_y, back_y), base_z), Vector3d(x1, std::max(facade_y, back_y), base_z + height),
                SurfaceClass::kBuilding);
  const double toward_street = -side;  // +y for the low row
  const auto relief = [&](double rx0, double rx1, double z0, double z1, double protrusion) {
    const double y_out = facade_y + toward_street * protrusion;
    object.addBox(Vector3d(rx0, std::min(facade_y, y_out), z0), Vector3d(rx1, std::max(facade_y, y_out), z1),
                  SurfaceClass::kBuilding);
  };
  const double pilaster_spacing = random.uniform(3.0, 6.0);
  const double pilaster_width = random.uniform(0.25, 0.5);
  for (double x = x0 + 0.5 * pilaster_spacing; x + pilaster_width < x1 - 0.3; x += pilaster_spacing)
    relief(x, x + pilaster_width, base_z, base_z + height, random.uniform(0.15, 0.3));
  const double floor_height = random.uniform(3.0, 3.6);
  for (double z = base_z + floor_height; z < base_z + height - 1.0; z += floor_height)
    relief(x0, x1, z, z + 0.2, 0.12);
  relief(x0, x1, base_z + height - 0.5, base_z + height, 0.4);  // cornice
}

// A row of buildings along x over [x0, x1], its street face at facade_y (+ setback).
void addBuildingRow(SceneObject& object, double x0, double x1, double facade_y, int side, double base_z,
                    SeededRandom& random) {
  double x = x0;
  while (x1 - x > 6.0) {
    const double length = std::min(random.uniform(10.0, 28.0), x1 - x);
    const double setback = chance(random, 0.5) ? 0.0 : random.uniform(0.3, kMaxSetbackM);
    addBuilding(object, x, x + length, facade_y + side * setback, side, base_z, random);
    x += length + (chance(random, 0.3) ? random.uniform(2.0, 4.0) : 0.0);  // an alley now and then
  }
}

void addLampPost(SceneObject& object, double x, double y, double base_z, double toward_y) {
  object.add(makeCylinder(Eigen::Vector3f(float(x), float(y), float(base_z)), 0.1f, 7.0f, 10), SurfaceClass::kPole);
  const double arm_end = y + toward_y * 1.6;
  object.addBox(Vector3d(x - 0.06, std::min(y, arm_end), base_z + 6.8), Vector3d(x + 0.06, std::max(y, arm_end), base_z + 6.95),
                SurfaceClass::kPole);
}

void addTree(SceneObject& object, double x, double y, double base_z, SeededRandom& random) {
  const double trunk_height = random.uniform(2.6, 3.2);
  const double crown_radius = random.uniform(0.9, 1.3);  // clear of the trucks' lane and the walkers
  object.add(makeCylinder(Eigen::Vector3f(float(x), float(y), float(base_z)), 0.18f, float(trunk_height + 0.5), 10),
             SurfaceClass::kVegetation);
  object.add(makeSphere(Eigen::Vector3f(float(x), float(y), float(base_z + trunk_height + crown_radius)),
                        float(crown_radius), 2),
             SurfaceClass::kVegetation);
}

}  // namespace

Scene buildTrafficStreet(const TrafficLayout& layout, double road_start_x, double road_end_x, uint32_t seed) {
  SeededRandom random({seed, 0x7472616666696373ull});  // "traffics"
  SceneObject street;
  const double kerb = TrafficLayout::kKerbHeightM;
  const double low_y = TrafficLayout::kCarriagewayLowY, high_y = TrafficLayout::kCarriagewayHighY;
  const double walk = TrafficLayout::kSidewalkWidthM;
  const double cross_low = layout.cross_street_low_x, cross_high = cross_low + kCrossStreetWidthM;
  const double far_low_y = low_y - walk - kMaxSetbackM - kBackLotDepthM;
  const double far_high_y = high_y + walk + kMaxSetbackM + kBackLotDepthM;

  // Carriageways at z = 0: the main road, then the cross street either side.
  addGround(street, road_start_x, road_end_x, low_y, high_y, 0.0);
  addGround(street, cross_low, cross_high, low_y - kCrossStreetReachM, low_y, 0.0);
  addGround(street, cross_low, cross_high, high_y, high_y + kCrossStreetReachM, 0.0);
  // Sidewalks and back lots at kerb height, in the four blocks around the
  // intersection; kerbs wherever a block meets a carriageway.
  for (const int side : {-1, 1}) {
    const double kerb_y = side < 0 ? low_y : high_y;
    const double outer_y = side < 0 ? far_low_y : far_high_y;
    const double cross_outer_y = side < 0 ? low_y - kCrossStreetReachM : high_y + kCrossStreetReachM;
    const double y0 = std::min(kerb_y, outer_y), y1 = std::max(kerb_y, outer_y);
    addGround(street, road_start_x, cross_low, y0, y1, kerb);
    addGround(street, cross_high, road_end_x, y0, y1, kerb);
    addKerbAlongX(street, road_start_x, cross_low, kerb_y, -side, kerb);
    addKerbAlongX(street, cross_high, road_end_x, kerb_y, -side, kerb);
    // The cross street's own sidewalks beyond the back lots.
    const double c0 = std::min(outer_y, cross_outer_y), c1 = std::max(outer_y, cross_outer_y);
    addGround(street, cross_low - walk, cross_low, c0, c1, kerb);
    addGround(street, cross_high, cross_high + walk, c0, c1, kerb);
    const double k0 = std::min(kerb_y, cross_outer_y), k1 = std::max(kerb_y, cross_outer_y);
    addKerbAlongY(street, k0, k1, cross_low, 1.0, kerb);
    addKerbAlongY(street, k0, k1, cross_high, -1.0, kerb);

    // Buildings along the main road, leaving the corners of the cross street's sidewalks free.
    const double facade_y = kerb_y + side * walk;
    addBuildingRow(street, road_start_x, cross_low - walk, facade_y, side, kerb, random);
    addBuildingRow(street, cross_high + walk, road_end_x, facade_y, side, kerb, random);
    // And a few along the cross street, seen through the intersection.
    for (const double x_side : {-1.0, 1.0}) {
      const double face_x = x_side < 0 ? cross_low - walk : cross_high + walk;
      const double start = kerb_y + side * (walk + kMaxSetbackM + kBackLotDepthM + 2.0);
      double y = start;
      for (int k = 0; k < 4; ++k) {
        const double length = random.uniform(12.0, 25.0);
        const double next = y + side * length;
        const double depth = random.uniform(10.0, 18.0);
        const double back_x = face_x + x_side * depth;
        street.addBox(Vector3d(std::min(face_x, back_x), std::min(y, next), kerb),
                      Vector3d(std::max(face_x, back_x), std::max(y, next), kerb + random.uniform(8.0, 20.0)),
                      SurfaceClass::kBuilding);
        y = next + side * (chance(random, 0.4) ? random.uniform(3.0, 6.0) : 0.0);
      }
    }

    // Lamp posts near the kerb, trees between them; both out of the walkers' strip.
    const double lamp_y = kerb_y - side * 0.5;
    const double tree_y = kerb_y - side * 1.35;
    const double lamp_spacing = random.uniform(22.0, 30.0);
    for (double x = road_start_x + random.uniform(2.0, lamp_spacing); x < road_end_x - 2.0; x += lamp_spacing) {
      if (x > cross_low - walk - 1.0 && x < cross_high + walk + 1.0) continue;
      addLampPost(street, x, lamp_y, kerb, -side);
      if (chance(random, 0.7)) {
        const double tree_x = x + 0.5 * lamp_spacing + random.uniform(-2.0, 2.0);
        if (tree_x < road_end_x - 2.0 && !(tree_x > cross_low - walk - 2.0 && tree_x < cross_high + walk + 2.0))
          addTree(street, tree_x, tree_y, kerb, random);
      }
    }
  }

  Scene scene;
  scene.mesh = std::move(street.mesh);
  scene.triangle_classes = std::move(street.classes);
  return scene;
}

}  // namespace range_image_mapping::simulation
