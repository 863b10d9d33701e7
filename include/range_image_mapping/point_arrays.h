// Points as plain coordinate arrays, for the loops that vectorise (the
// projection, the registration's and the model's passes).
#pragma once

#include <cstddef>

namespace range_image_mapping {

// xyz triples moved by an isometry (its 4 x 4 column-major matrix, as
// Eigen's Isometry3f::matrix().data()) into x, y and z arrays, rounded as
// Eigen's Isometry3f * Vector3f (left to right, no FMA), so the same floats.
// Cloned for AVX2 and AVX-512.
void transformToArrays(const float* points, std::size_t count, const float* transform, float* x, float* y, float* z);

}  // namespace range_image_mapping
