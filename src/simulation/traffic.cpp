#include "range_image_mapping/simulation/traffic.h"

#include "random_choice.h"
#include "traffic_street.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace range_image_mapping::simulation {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

constexpr double kPedestrianLiftM = 0.15;  // feet just above the kerb, so crossing the kerb line is no collision
constexpr double kEgoHalfLengthM = 2.3, kEgoHalfWidthM = 0.95;
constexpr double kCheckStepS = 0.05;
constexpr double kVehicleGapM = 0.6;  // the least distance between two footprints

ActorBox boxFromTo(const Vector3d& minimum, const Vector3d& maximum) {
  return {0.5 * (minimum + maximum), 0.5 * (maximum - minimum)};
}

// Car: a lower body on a 0.2 m ground clearance and a cabin set back.
std::vector<ActorBox> carBoxes(double length, double width, double height) {
  return {boxFromTo(Vector3d(-length / 2, -width / 2, 0.2), Vector3d(length / 2, width / 2, 0.95)),
          boxFromTo(Vector3d(-0.32 * length, -width / 2 + 0.1, 0.95), Vector3d(0.2 * length, width / 2 - 0.1, height))};
}

// Semi-trailer truck: trailer, cab, chassis between them, wheel sets.
std::vector<ActorBox> semiTruckBoxes(double trailer_length, double height) {
  const double cab = 2.3, gap = 0.6;
  const double half = 0.5 * (trailer_length + gap + cab);
  const double trailer_front = -half + trailer_length;
  return {boxFromTo(Vector3d(-half, -1.275, 1.15), Vector3d(trailer_front, 1.275, height)),       // trailer
          boxFromTo(Vector3d(half - cab, -1.25, 0.35), Vector3d(half, 1.25, 3.6)),               // cab
          boxFromTo(Vector3d(trailer_front - 3.5, -1.15, 0.45), Vector3d(half - cab, 1.15, 1.15)),  // chassis
          boxFromTo(Vector3d(-half + 0.8, -1.225, 0.05), Vector3d(-half + 4.4, 1.225, 1.15)),    // trailer axles
          boxFromTo(Vector3d(half - cab, -1.225, 0.05), Vector3d(half, 1.225, 0.35))};           // cab wheels
}

// Rigid (box) truck, 8 m.
std::vector<ActorBox> boxTruckBoxes() {
  return {boxFromTo(Vector3d(-4.0, -1.225, 0.9), Vector3d(1.8, 1.225, 3.5)),
          boxFromTo(Vector3d(2.0, -1.2, 0.35), Vector3d(4.0, 1.2, 3.0)),
          boxFromTo(Vector3d(-3.6, -1.1, 0.05), Vector3d(2.0, 1.1, 0.9)),
          boxFromTo(Vector3d(2.0, -1.15, 0.05), Vector3d(4.0, 1.15, 0.35))};
}

// Pedestrian: legs, torso, head, scaled to their height.
std::vector<ActorBox> pedestrianBoxes(double height) {
  const double s = height / 1.75, z = kPedestrianLiftM;
  return {boxFromTo(Vector3d(-0.14, -0.17, z), Vector3d(0.14, 0.17, z + 0.84 * s)),
          boxFromTo(Vector3d(-0.13, -0.24, z + 0.84 * s), Vector3d(0.13, 0.24, z + 1.48 * s)),
          boxFromTo(Vector3d(-0.1, -0.09, z + 1.48 * s), Vector3d(0.11, 0.09, z + 1.75 * s))};
}

MovingActor makeActor(ActorKind kind, std::string name, std::vector<ActorBox> boxes, const Vector3d& start,
                      double heading, SpeedProfile motion, double delay_s = 0.0) {
  MovingActor actor;
  actor.kind = kind;
  actor.name = std::move(name);
  actor.boxes = std::move(boxes);
  actor.start_m = start;
  actor.heading_rad = heading;
  actor.motion = std::move(motion);
  actor.delay_s = delay_s;
  return actor;
}

// The ego car's speed: see TrafficScenario::ego.
SpeedProfile egoProfile(double duration_s) {
  SpeedProfile profile(0.0, 0.0, 0.0);
  profile.hold(2.5).changeSpeed(6.0, 9.0).hold(2.0).changeSpeed(5.0, 0.0);  // first stop: 67.5 m at 15.5 s
  profile.hold(4.0).changeSpeed(5.0, 8.0).changeSpeed(4.5, 0.0);            // second: 105.5 m at 29 s
  while (profile.endTime() < duration_s + 1.0)
    profile.hold(3.0).changeSpeed(6.0, 9.0).hold(2.0).changeSpeed(5.0, 0.0);
  return profile;
}

// The pose of the lidar on the ego car: along the lane, pitching with the
// acceleration, a light vibration growing with the speed.
class StopAndGoTrajectory : public Trajectory {
 public:
  StopAndGoTrajectory(SpeedProfile profile, double duration_s, double height_m, uint32_t seed)
      : profile_(std::move(profile)), duration_s_(duration_s), height_m_(height_m) {
    SeededRandom random({seed, 0x65676full});  // "ego"
    for (Wave& wave : waves_) {
      wave.frequency_hz = random.uniform(1.2, 2.4);
      wave.phase = random.uniform(0.0, 2.0 * M_PI);
    }
  }

  Eigen::Isometry3d pose(double time_s) const override {
    if (!(time_s >= 0.0 && time_s <= duration_s_)) {
      std::ostringstream message;
      message.precision(12);
      message << "trajectory: time " << time_s << " s is outside [0, " << duration_s_ << "] s";
      throw std::out_of_range(message.str());
    }
    const double shake = std::min(profile_.speed(time_s) / 10.0, 1.0);  // none at a standstill
    const auto wave = [&](int k) { return shake * std::sin(2.0 * M_PI * waves_[k].frequency_hz * time_s + waves_[k].phase); };
    constexpr double kPitchPerAcceleration = 0.005;  // rad per m/s^2: the nose dips when braking
    const double pitch = -kPitchPerAcceleration * profile_.acceleration(time_s) + 0.0008 * wave(0);
    const double roll = 0.0008 * wave(1);
    Eigen::Isometry3d world_from_lidar = Eigen::Isometry3d::Identity();
    world_from_lidar.translation() =
        Vector3d(profile_.distance(time_s), TrafficLayout::kEgoLaneY, height_m_ + 0.003 * wave(2));
    world_from_lidar.linear() = (Eigen::AngleAxisd(pitch, Vector3d::UnitY()) *
                                 Eigen::AngleAxisd(roll, Vector3d::UnitX())).toRotationMatrix();
    return world_from_lidar;
  }
  double startTime() const override { return 0.0; }
  double endTime() const override { return duration_s_; }

 private:
  struct Wave {
    double frequency_hz = 1.0, phase = 0.0;
  };
  SpeedProfile profile_;
  double duration_s_, height_m_;
  Wave waves_[3];
};

// The footprint rectangle of an actor at a time: centre, unit axes and half sizes.
struct Footprint {
  Vector2d centre, axis_x, axis_y;
  double half_x, half_y;
};

Footprint footprintAt(const MovingActor& actor, double time_s, double grow_m) {
  const Eigen::Isometry3d world_from_actor = actor.worldFromActor(time_s);
  const Eigen::AlignedBox3d bounds = actor.boundsInActor();
  Footprint footprint;
  footprint.centre = (world_from_actor * bounds.center()).head<2>();
  footprint.axis_x = world_from_actor.linear().col(0).head<2>().normalized();
  footprint.axis_y = Vector2d(-footprint.axis_x.y(), footprint.axis_x.x());
  footprint.half_x = 0.5 * bounds.sizes().x() + grow_m;
  footprint.half_y = 0.5 * bounds.sizes().y() + grow_m;
  return footprint;
}

// Separating axis test for two rectangles.
bool footprintsOverlap(const Footprint& a, const Footprint& b) {
  const Vector2d offset = b.centre - a.centre;
  for (const Vector2d& axis : {a.axis_x, a.axis_y, b.axis_x, b.axis_y}) {
    const double reach_a = a.half_x * std::abs(a.axis_x.dot(axis)) + a.half_y * std::abs(a.axis_y.dot(axis));
    const double reach_b = b.half_x * std::abs(b.axis_x.dot(axis)) + b.half_y * std::abs(b.axis_y.dot(axis));
    if (std::abs(offset.dot(axis)) > reach_a + reach_b) return false;
  }
  return true;
}

class ActorPlacer {
 public:
  ActorPlacer(TrafficScenario& scenario, double end_s) : scenario_(scenario), end_s_(end_s) {}

  // Actors the layout makes collision-free: an overlap is a bug.
  void place(MovingActor actor) {
    if (!tryPlace(actor))
      throw std::logic_error("makeTrafficScenario: " + actor.name + " overlaps another actor");
  }
  // Random actors: kept only when they overlap nothing.
  bool tryPlace(MovingActor& actor) {
    if (actorsOverlap(actor, scenario_.ego_body, 0.0, end_s_, kCheckStepS, kVehicleGapM)) return false;
    for (const MovingActor& other : scenario_.actors)
      if (actorsOverlap(actor, other, 0.0, end_s_, kCheckStepS, kVehicleGapM)) return false;
    scenario_.actors.push_back(std::move(actor));
    return true;
  }

 private:
  TrafficScenario& scenario_;
  double end_s_;
};

// A pedestrian standing at the kerb until start_s, then crossing a distance
// at walking speed and standing again.
SpeedProfile crossingWalk(double start_s, double distance_m, double speed_mps) {
  constexpr double kRamp = 0.8;  // s to get going, and to stop
  SpeedProfile walk(start_s, 0.0, 0.0);
  walk.changeSpeed(kRamp, speed_mps).hold(std::max((distance_m - kRamp * speed_mps) / speed_mps, 0.1)).changeSpeed(kRamp, 0.0);
  return walk;
}

}  // namespace

bool actorsOverlap(const MovingActor& first, const MovingActor& second, double start_s, double end_s,
                   double step_s, double gap_m) {
  for (double time = start_s; time <= end_s; time += step_s)
    if (footprintsOverlap(footprintAt(first, time, 0.5 * gap_m), footprintAt(second, time, 0.5 * gap_m)))
      return true;
  return false;
}

TrafficScenario makeTrafficScenario(const TrafficOptions& options) {
  if (!(options.duration_s > 0.0 && options.duration_s <= 600.0))
    throw std::invalid_argument("makeTrafficScenario: duration_s must be within (0, 600] s, got " +
                                std::to_string(options.duration_s));
  if (!(options.sensor_height_m >= 0.5 && options.sensor_height_m <= 4.0))
    throw std::invalid_argument("makeTrafficScenario: sensor_height_m must be within [0.5, 4] m, got " +
                                std::to_string(options.sensor_height_m));
  TrafficScenario scenario;
  // Actors are planned (and checked for overlaps) over at least 40 s whatever
  // the duration, so a shorter sequence sees the same actors.
  const double end_s = std::max(options.duration_s, 40.0);
  const SpeedProfile ego = egoProfile(end_s);
  TrafficLayout& layout = scenario.layout;
  layout.first_stop_x = ego.distance(15.5);
  layout.second_stop_x = ego.distance(29.0);
  // The car ahead stops with its front 11.3 m ahead of the ego's sensor; the
  // crosswalk (2 m wide) and the cross street follow.
  layout.cross_street_low_x = layout.first_stop_x + 15.5;
  const double crosswalk_x = layout.cross_street_low_x - 2.0;
  scenario.scene = buildTrafficStreet(layout, -150.0, ego.distance(end_s) + 150.0, options.seed);
  scenario.ego = std::make_unique<StopAndGoTrajectory>(ego, options.duration_s, options.sensor_height_m, options.seed);
  scenario.ego_body = makeActor(ActorKind::kCar, "ego", carBoxes(2 * kEgoHalfLengthM, 2 * kEgoHalfWidthM, 1.5),
                                Vector3d(0, TrafficLayout::kEgoLaneY, 0), 0.0, ego);

  SeededRandom random({options.seed, 0x6163746f7273ull});  // "actors"
  ActorPlacer placer(scenario, end_s);
  const double truck_y = TrafficLayout::kTruckLaneOffsetM;
  // Alongside: delayed copies of the ego's profile, one truck leading and one
  // lagging, so they stop and go with the ego at about its speed.
  placer.place(makeActor(ActorKind::kTruck, "truck_left", semiTruckBoxes(random.uniform(12.5, 13.6), random.uniform(3.9, 4.1)),
                         Vector3d(2.0, truck_y, 0), 0.0, ego, -0.4));
  placer.place(makeActor(ActorKind::kTruck, "truck_right", semiTruckBoxes(random.uniform(12.5, 13.6), random.uniform(3.9, 4.1)),
                         Vector3d(-1.0, -truck_y, 0), 0.0, ego, 0.5));
  placer.place(makeActor(ActorKind::kCar, "car_ahead", carBoxes(random.uniform(4.0, 4.6), 1.8, random.uniform(1.4, 1.5)),
                         Vector3d(9.0, 0, 0), 0.0, ego, -0.8));
  placer.place(makeActor(ActorKind::kCar, "car_behind", carBoxes(random.uniform(4.0, 4.6), 1.8, random.uniform(1.4, 1.5)),
                         Vector3d(-9.0, 0, 0), 0.0, ego, 0.8));

  // Crossing the intersection while the ego waits at the first stop: constant
  // speed, at the main road's centre line at the given time.
  const double road_middle_y = 0.5 * (TrafficLayout::kCarriagewayLowY + TrafficLayout::kCarriagewayHighY);
  const auto crossing = [&](ActorKind kind, const char* name, std::vector<ActorBox> boxes, double lane_x,
                            double heading, double speed, double middle_time) {
    const Vector3d direction(std::cos(heading), std::sin(heading), 0.0);
    const Vector3d start = Vector3d(lane_x, road_middle_y, 0) - speed * middle_time * direction;
    return makeActor(kind, name, std::move(boxes), start, heading, SpeedProfile(0.0, 0.0, speed));
  };
  {
    placer.place(crossing(ActorKind::kCar, "car_crossing", carBoxes(4.4, 1.8, 1.45), layout.cross_street_low_x + 2.75,
                          M_PI / 2, random.uniform(8.0, 11.0), 16.5));
    placer.place(crossing(ActorKind::kTruck, "truck_crossing", boxTruckBoxes(), layout.cross_street_low_x + 8.25,
                          -M_PI / 2, random.uniform(7.0, 9.0), 18.0));
  }

  // Pedestrians crossing the main road in front of the waiting traffic: at the
  // crosswalk before the cross street during the first stop, and ahead of the
  // second stop. They wait at the kerb, cross, and stop on the far sidewalk.
  const double low_walk_y = TrafficLayout::kCarriagewayLowY - 3.15;   // walkers' strip, clear of posts and trees
  const double high_walk_y = TrafficLayout::kCarriagewayHighY + 3.15;
  const double crossing_distance = high_walk_y - low_walk_y;
  struct Crossing {
    double x, earliest_s, latest_s;
  };
  const Crossing crossings[] = {{crosswalk_x, 4.0, 7.0}, {crosswalk_x + 1.2, 5.0, 7.5},
                                {layout.second_stop_x + 19.0, 19.0, 22.0}};
  int crossing_count = 0;
  for (const Crossing& place : crossings) {
    for (int attempt = 0; attempt < 20; ++attempt) {
      const bool northward = chance(random, 0.5);
      const double speed = random.uniform(1.2, 1.5);
      MovingActor pedestrian = makeActor(
          ActorKind::kPedestrian, "crossing_" + std::to_string(crossing_count + 1),
          pedestrianBoxes(random.uniform(1.55, 1.9)), Vector3d(place.x, northward ? low_walk_y : high_walk_y, 0),
          northward ? M_PI / 2 : -M_PI / 2,
          crossingWalk(random.uniform(place.earliest_s, place.latest_s), crossing_distance, speed));
      if (placer.tryPlace(pedestrian)) {
        ++crossing_count;
        break;
      }
    }
  }

  // Oncoming traffic at constant speed, passing the ego at random times.
  int oncoming_count = 0;
  for (int attempt = 0; attempt < 60 && oncoming_count < 4; ++attempt) {
    const double speed = random.uniform(9.0, 13.0);
    const double passing_s = random.uniform(1.0, std::max(end_s - 1.0, 1.5));
    const bool van = chance(random, 0.25);
    std::vector<ActorBox> boxes =
        van ? std::vector<ActorBox>{boxFromTo(Vector3d(-2.7, -1.0, 0.25), Vector3d(2.7, 1.0, 2.3))}
            : carBoxes(random.uniform(3.9, 4.8), random.uniform(1.7, 1.85), random.uniform(1.4, 1.55));
    MovingActor car = makeActor(ActorKind::kCar, "oncoming_" + std::to_string(oncoming_count + 1), std::move(boxes),
                                Vector3d(ego.distance(passing_s) + speed * passing_s, TrafficLayout::kOncomingLaneY, 0),
                                M_PI, SpeedProfile(0.0, 0.0, speed));
    if (placer.tryPlace(car)) ++oncoming_count;
  }

  // Walkers along the sidewalks, near where the ego drives, never reaching the
  // cross street (the kerb drops there).
  int walker_count = 0;
  const double block_end_x = layout.cross_street_low_x - TrafficLayout::kSidewalkWidthM - 0.5;
  const double block_start_x = layout.cross_street_low_x + 11.0 + TrafficLayout::kSidewalkWidthM + 0.5;
  for (int attempt = 0; attempt < 60 && walker_count < 5; ++attempt) {
    const bool low_side = chance(random, 0.5);
    const bool forward = chance(random, 0.5);
    const double speed = random.uniform(1.0, 1.6);
    const double start_x = random.uniform(-10.0, ego.distance(end_s) + 20.0);
    const double end_x = start_x + (forward ? 1.0 : -1.0) * speed * end_s;
    const double lowest = std::min(start_x, end_x) - 1.0, highest = std::max(start_x, end_x) + 1.0;
    if (highest > block_end_x && lowest < block_start_x) continue;  // would step onto the cross street
    MovingActor walker = makeActor(ActorKind::kPedestrian, "walker_" + std::to_string(walker_count + 1),
                                   pedestrianBoxes(random.uniform(1.55, 1.9)),
                                   Vector3d(start_x, low_side ? low_walk_y : high_walk_y, 0), forward ? 0.0 : M_PI,
                                   SpeedProfile(0.0, 0.0, speed));
    if (placer.tryPlace(walker)) ++walker_count;
  }
  return scenario;
}

}  // namespace range_image_mapping::simulation
