#pragma once
// Near-light depth refinement (internal): a sub-sampled grid of the image on
// which photometric stereo is solved, its normals integrated into a depth map,
// and the depth map brought back to full resolution.
#include <opencv2/core.hpp>

namespace veneer::ps {

struct DepthGrid {
  int step = 1;          // image pixels per grid cell
  int x0 = 0, y0 = 0;    // image position of cell (0, 0)
  int cols = 0, rows = 0;
  float f = 1, cx = 0, cy = 0;  // camera intrinsics [px]
  cv::Mat mask;          // CV_8UC1 grid: object cells
  cv::Mat z;             // CV_32FC1 grid: surface z in the rig frame [m]
  cv::Mat normals;       // CV_32FC3 grid: last solved normals
  cv::Mat reliable;      // CV_8UC1 grid
  cv::Mat full_mask;     // CV_8UC1 full-resolution object mask (shared, not copied)
};

// A grid at most ~64 cells wide (the depth only steers the light vectors,
// which vary slowly) over `size`, mask point-sampled, z = 0.
DepthGrid make_depth_grid(cv::Size size, const cv::Mat& mask, float f, float cx, float cy);

// Integrates grid.normals into grid.z (least squares over neighbouring object
// cells). Each connected part is anchored so that its occluding contour (the
// mask's edge) lies on the z = 0 plane, the object's nominal position: a
// silhouette cell a distance d inside the contour, where the surface slopes
// by s, sits 2*d*s above it (a smooth contour is locally parabolic). False when
// nothing was solvable.
bool integrate_depth(DepthGrid& grid);

// Full-resolution z map (CV_32FC1) by bilinear interpolation; cells outside the
// object take the value of the nearest object cell.
cv::Mat upsample_depth(const DepthGrid& grid, cv::Size size);

}  // namespace veneer::ps
