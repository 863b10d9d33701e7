#include "range_image_mapping/simulation/ray_caster.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace range_image_mapping::simulation {
namespace {

// Rays handed to Embree per stream call: enough for its SIMD packets to fill,
// small enough to live on the stack (80 bytes each).
constexpr std::size_t kStreamChunk = 64;

constexpr float kNoHit = std::numeric_limits<float>::quiet_NaN();

void validateMesh(const TriangleMesh& mesh) {
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i)
    if (!mesh.vertices[i].allFinite())
      throw std::invalid_argument("RayCaster: mesh vertex " + std::to_string(i) + " is not finite");
  const int vertex_count = static_cast<int>(mesh.vertices.size());
  if (mesh.vertices.size() > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw std::invalid_argument("RayCaster: mesh has more vertices than int indices can address");
  for (std::size_t i = 0; i < mesh.triangles.size(); ++i)
    for (int corner = 0; corner < 3; ++corner) {
      const int index = mesh.triangles[i][corner];
      if (index < 0 || index >= vertex_count)
        throw std::invalid_argument("RayCaster: triangle " + std::to_string(i) + " has vertex index " +
                                    std::to_string(index) + ", mesh has " +
                                    std::to_string(vertex_count) + " vertices");
    }
}

[[noreturn]] void failEmbree(RTCDevice device, const std::string& step) {
  const RTCError code = device ? rtcGetDeviceError(device) : RTC_ERROR_UNKNOWN;
  throw std::runtime_error("RayCaster: Embree failed to " + step + " (error code " +
                           std::to_string(static_cast<int>(code)) + ")");
}

RTCRay makeRay(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction, float near,
               float far) {
  RTCRay ray;
  ray.org_x = origin.x();
  ray.org_y = origin.y();
  ray.org_z = origin.z();
  ray.tnear = near;
  ray.dir_x = direction.x();
  ray.dir_y = direction.y();
  ray.dir_z = direction.z();
  ray.time = 0.0f;
  ray.tfar = far;
  ray.mask = ~0u;
  ray.id = 0;
  ray.flags = 0;
  return ray;
}

// Embree's unnormalised Ng faces the side from which the triangle's corners
// run counter-clockwise, as TriangleMesh's winding defines "outside".
Eigen::Vector3f outsideNormal(const RTCHit& hit) {
  return Eigen::Vector3f(hit.Ng_x, hit.Ng_y, hit.Ng_z).normalized();
}

}  // namespace

struct RayCaster::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;

  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }
};

RayCaster::RayCaster(const TriangleMesh& mesh) : impl_(std::make_unique<Impl>()) {
  validateMesh(mesh);
  Impl& impl = *impl_;
  impl.device = rtcNewDevice(nullptr);
  if (!impl.device) failEmbree(nullptr, "create a device");
  impl.scene = rtcNewScene(impl.device);
  if (!impl.scene) failEmbree(impl.device, "create a scene");
  // Static scene, queried millions of times: spend more on the build. Robust
  // traversal so rays through shared edges (room corners) never slip through.
  rtcSetSceneBuildQuality(impl.scene, RTC_BUILD_QUALITY_HIGH);
  rtcSetSceneFlags(impl.scene, RTC_SCENE_FLAG_ROBUST);
  if (!mesh.triangles.empty()) {
    RTCGeometry geometry = rtcNewGeometry(impl.device, RTC_GEOMETRY_TYPE_TRIANGLE);
    if (!geometry) failEmbree(impl.device, "create the triangle geometry");
    // Copies (not shared buffers): Embree reads 16 bytes per vertex, which a
    // packed Vector3f array does not guarantee at its end.
    auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
        geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float),
        mesh.vertices.size()));
    auto* indices = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned),
        mesh.triangles.size()));
    if (!vertices || !indices) {
      rtcReleaseGeometry(geometry);
      failEmbree(impl.device, "allocate the mesh buffers");
    }
    for (std::size_t i = 0; i < mesh.vertices.size(); ++i)
      for (int axis = 0; axis < 3; ++axis) vertices[3 * i + axis] = mesh.vertices[i][axis];
    for (std::size_t i = 0; i < mesh.triangles.size(); ++i)
      for (int corner = 0; corner < 3; ++corner)
        indices[3 * i + corner] = static_cast<unsigned>(mesh.triangles[i][corner]);
    rtcCommitGeometry(geometry);
    rtcAttachGeometry(impl.scene, geometry);
    rtcReleaseGeometry(geometry);  // the scene holds it
  }
  rtcCommitScene(impl.scene);
  if (rtcGetDeviceError(impl.device) != RTC_ERROR_NONE) failEmbree(impl.device, "build the scene");
}

RayCaster::~RayCaster() = default;

void RayCaster::cast(const Eigen::Vector3f* origins, const Eigen::Vector3f* directions,
                     std::size_t count, float near, float far, float* distances,
                     Eigen::Vector3f* normals) const {
  // A context per call: concurrent calls share nothing but the committed scene.
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  // Neighbouring beams of a column point almost the same way.
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  RTCRayHit batch[kStreamChunk];
  for (std::size_t first = 0; first < count; first += kStreamChunk) {
    const std::size_t size = std::min(kStreamChunk, count - first);
    for (std::size_t i = 0; i < size; ++i) {
      batch[i].ray = makeRay(origins[first + i], directions[first + i], near, far);
      batch[i].hit.geomID = RTC_INVALID_GEOMETRY_ID;
      batch[i].hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    }
    rtcIntersect1M(impl_->scene, &context, batch, static_cast<unsigned>(size), sizeof(RTCRayHit));
    for (std::size_t i = 0; i < size; ++i) {
      const bool hit = batch[i].hit.geomID != RTC_INVALID_GEOMETRY_ID;
      distances[first + i] = hit ? batch[i].ray.tfar : kNoHit;
      if (normals) normals[first + i] = hit ? outsideNormal(batch[i].hit) : Eigen::Vector3f::Zero();
    }
  }
}

float RayCaster::castOne(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction, float near,
                         float far, Eigen::Vector3f* normal) const {
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit ray_hit;
  ray_hit.ray = makeRay(origin, direction, near, far);
  ray_hit.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  ray_hit.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &context, &ray_hit);
  const bool hit = ray_hit.hit.geomID != RTC_INVALID_GEOMETRY_ID;
  if (normal) *normal = hit ? outsideNormal(ray_hit.hit) : Eigen::Vector3f::Zero();
  return hit ? ray_hit.ray.tfar : kNoHit;
}

}  // namespace range_image_mapping::simulation
