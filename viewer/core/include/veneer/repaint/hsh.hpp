#pragma once
// Hemispherical harmonics (HSH; Gautron, Krivanek, Pattanaik, Bouatouch 2004),
// the basis of the HSH .rti files RTIViewer and Relight open: a pixel's value
// under a light from direction d is sum_k c_k H_k(d), the c_k fitted by least
// squares to photos under known lamps.
//
// `order` is the RTI files' order: order * order terms (1, 4 or 9; order
// 3 = 9 terms is RTIBuilder's usual HSH, "second degree" in spherical-harmonic
// terms). With theta the angle off the camera's axis (cos theta = d.z) and
// phi = atan2(d.y, d.x) (x right, y up: the rig frame), s = sqrt(cos theta -
// cos^2 theta), c = cos theta:
//   H0 = 1/sqrt(2 pi)
//   H1 = sqrt(6/pi) cos(phi) s         H2 = sqrt(3/(2 pi)) (2c - 1)       H3 = sqrt(6/pi) sin(phi) s
//   H4 = sqrt(30/pi) cos(2 phi) (c^2 - c)   H5 = sqrt(30/pi) cos(phi) (2c - 1) s
//   H6 = sqrt(5/(2 pi)) (6c^2 - 6c + 1)     H7 = sqrt(30/pi) sin(phi) (2c - 1) s
//   H8 = sqrt(30/pi) sin(2 phi) (c^2 - c)
// (Order 4's third-degree terms are left out: viewers' sources disagree on
// them -- an exponent 3/2 written in integer arithmetic -- so a file of that
// order would not look the same everywhere.)
// A direction below the horizon (d.z <= 0) is evaluated at the horizon.
//
// Lamps on one cone around the camera (a ring rig's) do not tell the terms
// that vary with theta alone apart (H0, H2, H6 are then one constant), so the
// fit is the least-norm solution (SVD pseudo-inverse), which still fits the
// lamps' photos as well as the basis can.
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"

namespace veneer::repaint {

// order * order: the coefficients per channel.
int hsh_terms(int order);

// The order * order basis values at `direction` (any length > 0; normalised
// here), in the files' term order. Order 1..3; outside that, empty.
std::vector<double> hsh_basis(const cv::Vec3d& direction, int order);

struct HshFit {
  int order = 0;
  std::vector<cv::Mat> coefficients;  // one per image channel (in the images' channel order), CV_32FC(terms)
  double rms = 0;                     // residual of the fit over every pixel, channel and image, in image units
  std::vector<double> rms_per_image;  // the same per image
};

// Least-squares fit of `images` (CV_32F, 1..4 channels, one size and type)
// lit from `directions` (one per image, unit or not, z > 0). Fails with one
// message on: no images, a count mismatch, an order outside 1..3, fewer
// images than order * order coefficients, a zero or below-horizon direction,
// or images of different sizes or types.
Expected<HshFit> fit_hsh(const std::vector<cv::Mat>& images, const std::vector<cv::Vec3d>& directions, int order);

// The fitted image under a light from `direction` (CV_32FC(channels)).
cv::Mat evaluate_hsh(const HshFit& fit, const cv::Vec3d& direction);

// The highest order whose terms the lamps determine by count (order^2 <=
// lamps), at most `max_order`; 0 for no lamp. 7 lamps: 2.
int hsh_order_for(size_t lamps, int max_order = 3);

}  // namespace veneer::repaint
