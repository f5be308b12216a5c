#pragma once
// The gloss of an object's material, fitted from its photos and normals: a
// Blinn-Phong lobe k(p) (n.h)^alpha seen from the camera (+z) over a diffuse
// albedo. The shaded look (look.hpp) takes the source's lobe off the
// source's photos and puts it back where the destination's normals place
// the highlights.
//
// Per pixel, the diffuse albedo is the median over the lamps that light it
// (n.l > 0.1) of I_l / (n.l) -- a highlight is one lamp of several, so the
// median passes it by. What the grey photos hold above albedo x (n.l) is the
// residual; one exponent alpha for the whole object (the one of `exponents`
// whose lobes explain the residual best) and a weight k per pixel (least
// squares, k >= 0, with a ridge toward the object's k0 -- a pixel no
// highlight reached has the object's gloss), smoothed over a couple of pixels.
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::repaint {

struct GlossOptions {
  std::vector<double> exponents{4, 8, 16, 32, 64, 128};  // alpha tried, each in [1, 1000]; default 4..128
  double ridge = 0.05;        // added to sum (n.h)^2alpha before k is solved, > 0; default 0.05
  double lit = 0.1;           // a lamp lights a pixel for the albedo when n.l exceeds this, [0, 0.9]; default 0.1
  double smoothing = 2.0;     // k smoothed within the object over this Gaussian sigma, px, [0, 16]; default 2
  Status check() const;
};

struct Gloss {
  double exponent = 32;   // alpha, the whole object's
  cv::Mat weight;         // k per pixel (CV_32FC1, linear units of the photos' grey), 0 outside the object
  cv::Mat albedo;         // diffuse albedo per pixel (CV_32FC3, the photos' channels), 0 where no lamp lit it
  double object_weight = 0;  // k0: the lobe's weight fitted over the whole object, what k tends to where
                             // no lamp's highlight fell (the ridge pulls toward it)
  double residual = 0;    // RMS of what the lobe leaves of the residual, over the object and lamps
  // k (n.h)^alpha for lamp direction `l` (unit) at normal `n`, 0 when n.l <= 0.
  static float lobe(const cv::Vec3f& n, const cv::Vec3f& l, const cv::Vec3f& half, double exponent);
};

// The half vector between a lamp direction and the camera's (0, 0, 1).
cv::Vec3f half_vector(const cv::Vec3d& lamp_direction);

// `photos`: linear CV_32FC3, one per lamp, ambient removed; `normals`:
// CV_32FC3 x, y, z; `mask`: CV_8UC1 (255 = object); `directions`: unit, one
// per photo. Fails, naming it, on sizes or types that do not fit, fewer than
// 3 lamps, or options out of range; "cancelled" when progress cancels.
Expected<Gloss> fit_gloss(const std::vector<cv::Mat>& photos, const cv::Mat& normals, const cv::Mat& mask,
                          const std::vector<cv::Vec3d>& directions, const GlossOptions& options = {},
                          const Progress& progress = {});

// `image` (CV_32FC1 or CV_32FC3) averaged over the pixels of `mask` within a
// Gaussian of `sigma` px (the mask's edge does not pull in the outside);
// unchanged for sigma <= 0, 0 where no mask pixel is near.
cv::Mat masked_blur(const cv::Mat& image, const cv::Mat& mask, double sigma);

// Whether `photo` is one a look reads: CV_32FC3, or CV_16FC3 (the half
// floats pipeline::PrepareOptions::half_photos keeps, issue 42).
bool readable_photo(const cv::Mat& photo);
// Row y of each photo as float pixels: a CV_32FC3 photo's own row, a
// CV_16FC3 one's widened into a buffer of this reader (one per thread), so
// photos kept in half floats are never widened whole.
class PhotoRows {
 public:
  explicit PhotoRows(const std::vector<cv::Mat>& photos);
  const cv::Vec3f* const* row(int y);  // one pointer per photo, valid until the next call
 private:
  const std::vector<cv::Mat>& photos_;
  std::vector<std::vector<cv::Vec3f>> buffers_;
  std::vector<const cv::Vec3f*> rows_;
};

}  // namespace veneer::repaint
