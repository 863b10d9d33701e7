// Range images as the PCL baselines take them: the valid points of the
// image, voxel-downsampled (one point per occupied voxel, at its centroid).
#pragma once

#include "range_image_mapping/range_image.h"

#include <pcl/filters/voxel_grid.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

namespace range_image_mapping::benchmark_support {

inline pcl::PointCloud<pcl::PointXYZ>::Ptr downsampledCloud(const RangeImage& image, double voxel_m) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
  for (const Eigen::Vector3f& point : image.unprojectAll()) cloud->push_back(pcl::PointXYZ(point.x(), point.y(), point.z()));
  pcl::PointCloud<pcl::PointXYZ>::Ptr downsampled(new pcl::PointCloud<pcl::PointXYZ>);
  pcl::VoxelGrid<pcl::PointXYZ> grid;
  grid.setLeafSize(float(voxel_m), float(voxel_m), float(voxel_m));
  grid.setInputCloud(cloud);
  grid.filter(*downsampled);
  return downsampled;
}

}  // namespace range_image_mapping::benchmark_support
