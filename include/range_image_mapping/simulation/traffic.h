// The traffic scenario: stop-and-go driving on a straight city road between
// two large trucks that move at about the ego car's speed, with a car ahead
// and one behind, oncoming cars, traffic crossing at an intersection while the
// ego waits, and pedestrians. The static world, the ego trajectory and the
// actors come together, deterministic for a seed, with exact ground truth.
#pragma once

#include "range_image_mapping/simulation/moving_actors.h"
#include "range_image_mapping/simulation/scene_generator.h"
#include "range_image_mapping/simulation/trajectory.h"

#include <memory>
#include <vector>

namespace range_image_mapping::simulation {

struct TrafficOptions {
  uint32_t seed = 1;              // buildings, street furniture, actor sizes, oncoming and walking actors
  double duration_s = 40.0;       // the ego trajectory covers [0, duration_s]; within (0, 600]
  double sensor_height_m = 1.8;   // on the ego car's roof, above the road; within [0.5, 4]
};

// The layout, in the world frame of the scenario (x along the road, y left, z up, road at z = 0).
struct TrafficLayout {
  static constexpr double kLaneWidthM = 3.5;
  static constexpr double kEgoLaneY = 0.0;        // the ego drives +x on the lane centre
  static constexpr double kTruckLaneOffsetM = 3.3;  // trucks at +-3.3 m: 2 m from the ego's centre line to their sides
  static constexpr double kOncomingLaneY = 7.0;   // -x
  static constexpr double kCarriagewayLowY = -5.25, kCarriagewayHighY = 8.75;
  static constexpr double kSidewalkWidthM = 4.0;
  static constexpr double kKerbHeightM = 0.14;
  double cross_street_low_x = 0.0;   // the crossing carriageway spans [low, low + 11] m in x
  double first_stop_x = 0.0, second_stop_x = 0.0;  // where the ego waits (sensor x)
};

struct TrafficScenario {
  // The static world only (ground, kerbs, buildings, lamp posts, trees):
  // surface ground truth is sampled from it, so it never holds an actor. Its
  // route is empty: the ego motion is the scenario's own.
  Scene scene;
  TrafficLayout layout;
  // T_world_lidar: the ego car from x = 0 along the lane centre, standing
  // 2.5 s, to ~9 m/s and braking to a stop before the intersection (stand 4 s
  // while traffic crosses), to ~8 m/s and a second stop, then cycles of
  // standing 3 s and driving to ~9 m/s and back to a stop. Pitches with the
  // acceleration (about 0.3 deg per m/s^2) and vibrates lightly while moving.
  std::unique_ptr<Trajectory> ego;
  // truck_left and truck_right (semi-trailers alongside, one leading, one
  // lagging the ego's profile by a fraction of a second), car_ahead and
  // car_behind in the ego's lane, car_crossing and truck_crossing on the cross
  // street, oncoming_* on the opposite lane, and pedestrians crossing the road
  // (crossing_*) and walking the sidewalks (walker_*). No two actors, nor an
  // actor and the ego car (4.6 x 1.9 m around the sensor), ever overlap.
  std::vector<MovingActor> actors;
  // The ego car's body, for overlap checks only (never cast).
  MovingActor ego_body;
};

// Throws std::invalid_argument for options out of range.
TrafficScenario makeTrafficScenario(const TrafficOptions& options);

// Whether the footprints of two actors (their bounds, grown by gap_m / 2 each)
// overlap at any multiple of step_s within [start_s, end_s]: actors drive on
// the ground, so footprints decide.
bool actorsOverlap(const MovingActor& first, const MovingActor& second, double start_s, double end_s,
                   double step_s, double gap_m);

}  // namespace range_image_mapping::simulation
