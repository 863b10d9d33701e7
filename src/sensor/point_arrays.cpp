#include "range_image_mapping/point_arrays.h"

#include "range_image_mapping/lidar_intrinsics.h"

namespace range_image_mapping {

RANGE_IMAGE_MAPPING_SIMD_CLONES
void transformToArrays(const float* points, std::size_t count, const float* transform, float* __restrict x,
                       float* __restrict y, float* __restrict z) {
  float* const moved[3] = {x, y, z};
  for (std::size_t k = 0; k < count; ++k) {
    const float* point = points + 3 * k;
    for (int axis = 0; axis < 3; ++axis)
      moved[axis][k] =
          ((transform[axis] * point[0] + transform[4 + axis] * point[1]) + transform[8 + axis] * point[2]) +
          transform[12 + axis];
  }
}

}  // namespace range_image_mapping
