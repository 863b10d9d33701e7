// Procedural scenes with a seed: the same seed gives the same scene.
#pragma once

#include "range_image_mapping/triangle_mesh.h"

#include <cstdint>
#include <vector>

namespace range_image_mapping::simulation {

enum class SceneKind { kIndoor, kOutdoor };

struct SceneOptions {
  SceneKind kind = SceneKind::kOutdoor;
  uint32_t seed = 1;
  // Outdoor: a grid of streets between building blocks; indoor: rooms and corridors.
  // Side of the square scene; 0: a sensible default per kind (outdoor 300 m, indoor 40 m).
  // Accepted: outdoor [120, 1000] m, indoor [20, 150] m.
  double extent_m = 0.0;
};

// What a triangle belongs to: ground truth for per-class evaluation.
enum class SurfaceClass : uint8_t {
  kGround,      // terrain, roads, sidewalks and kerbs, floors
  kBuilding,    // walls, facades, balconies, roofs, ceilings, stairs, pillars
  kFurniture,   // tables, shelves, boxes, benches, bins, lights
  kPole,        // thin poles, lamp posts, signs, bollards, railings
  kVehicle,     // parked cars
  kVegetation,  // tree trunks and crowns, bushes
};

// The space kept free around the route for the sensor and its carrier: no
// triangle other than kGround comes within distance_m of any point between
// lowest_m and highest_m above the route.
struct RouteClearance {
  double distance_m = 0.0;
  double lowest_m = 0.0;
  double highest_m = 0.0;
};

struct Scene {
  TriangleMesh mesh;
  std::vector<SurfaceClass> triangle_classes;  // one per mesh.triangles entry
  // A closed path on the floor or road surface (trajectories add the sensor
  // height): street centre lines turning at intersections outdoors, corridors
  // and rooms indoors. Corners are already rounded (arcs sampled every few
  // degrees), so a smoothed trajectory stays on it; route.back() == route.front().
  std::vector<Eigen::Vector3d> route;
  RouteClearance route_clearance;
};

// Outdoor: ground with gentle slopes (at most 4 %) and kerbs, blocks of
// buildings 6-30 m tall with facade relief (recessed windows, balconies,
// bands, cornices, setbacks), lamp posts and signs, parked cars, trees and
// bushes. Indoor: rooms around a corridor ring under a 2.7-3 m ceiling, doors,
// furniture, a stair flight with railing, thin (5 cm) poles, pillars.
// Throws std::invalid_argument for an extent outside the accepted range.
Scene generateScene(const SceneOptions& options);

}  // namespace range_image_mapping::simulation
