#include "range_image_mapping/simulation/scene_generator.h"

#include "procedural_scenes.h"

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace range_image_mapping::simulation {
namespace {

struct ExtentLimits {
  const char* kind;
  double default_m, minimum_m, maximum_m;
};

ExtentLimits extentLimitsOf(SceneKind kind) {
  switch (kind) {
    // Below the minimum the corridor ring or the street grid does not fit; above
    // the maximum the mesh outgrows what a simulation run should hold in memory.
    case SceneKind::kIndoor:
      return {"indoor", 40.0, 20.0, 150.0};
    case SceneKind::kOutdoor:
      return {"outdoor", 300.0, 120.0, 1000.0};
  }
  throw std::invalid_argument("generateScene: unknown scene kind " +
                              std::to_string(static_cast<int>(kind)));
}

}  // namespace

Scene generateScene(const SceneOptions& options) {
  const ExtentLimits limits = extentLimitsOf(options.kind);
  const double extent = options.extent_m == 0.0 ? limits.default_m : options.extent_m;
  if (!(extent >= limits.minimum_m && extent <= limits.maximum_m)) {
    std::ostringstream message;
    message << "generateScene: " << limits.kind << " extent_m must be 0 (default "
            << limits.default_m << " m) or within [" << limits.minimum_m << ", " << limits.maximum_m
            << "] m, got " << options.extent_m;
    throw std::invalid_argument(message.str());
  }
  return options.kind == SceneKind::kIndoor ? generateIndoorScene(options.seed, extent)
                                            : generateOutdoorScene(options.seed, extent);
}

}  // namespace range_image_mapping::simulation
