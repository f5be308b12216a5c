#pragma once
// Relighting without the live video (beyond the thesis): the source's photos
// under the rig's lamps say how each source pixel answers to light. A
// biquadratic polynomial texture map (PTM, Malzbender et al. 2001) is fitted
// per source pixel and colour channel over the lamps' directions,
//   I(l) = a0 lu^2 + a1 lv^2 + a2 lu lv + a3 lu + a4 lv + a5,
// with one pseudo-inverse for the whole image. Carried through the map, it
// shows the destination under any virtual light direction in the source's
// material.
//
// The biquadratic basis needs lamps at several elevations: on a rig whose
// lamps sit on one ring (the thesis rig), lu^2 + lv^2 is the same for every
// lamp and the fit is degenerate. Then the basis falls back to the five terms
// such a ring does determine, (lx, ly, lz, lx ly, lx^2 - ly^2) — a Lambertian
// pseudo-normal plus the second-order terms that carry highlights' shape.
//
// Each pixel is fitted only over the lamps that light it: a sample in shadow
// (attached or cast, below 2 % of the pixel's brightest) does not follow a
// smooth model, and fitted anyway the other lamps' shadows came back as
// ghost rings about the object and the fit went negative at the terminator
// (black speckle). A ridge keeps the second-order terms from amplifying
// noise, and they are not extrapolated beyond the lamps' reach (the
// Lambertian terms are); pixels lit by fewer than 4 lamps stay as captured. Only the object (the set's mask, else its
// segmentation) is relit: the background, whose look under a new light
// depends on the object's cast shadow, is left as captured (the photos'
// per-pixel median), and render() shows the caller's backdrop where the
// destination is not mapped.
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::repaint {

using match::Map;

class Relighter {
 public:
  // Fits the source's PTM from its photos (ambient removed when present).
  static Expected<Relighter> fit(const io::ImageSet& source);

  // The source itself under a light from `direction` (unit, rig frame):
  // linear BGR CV_32FC3 at the source size; the object relit, the rest as captured.
  cv::Mat render_source(const cv::Vec3d& direction) const;
  // The destination relit: each mapped pixel shows its source pixel's PTM at
  // `direction`; unmapped pixels come from `backdrop` (linear BGR, may be empty = black).
  cv::Mat render(const Map& map, const cv::Vec3d& direction, const cv::Mat& backdrop = {}) const;

  cv::Size source_size() const { return size_; }
  // RMS of the fit over the relit pixels and the lamps that light them
  // (linear units), a measure of how well the model explains the source
  // (specular highlights fit worst).
  double fit_rms() const { return fit_rms_; }
  // What is relit and what is not, for the user.
  static const char* background_note() { return "object relit; background as captured (not relit)"; }
  const char* basis_name() const { return basis_ == Basis::ptm6 ? "biquadratic PTM" : "ring (lx, ly, lz, lx ly, lx^2-ly^2)"; }

 private:
  cv::Size size_;
  enum class Basis { ptm6, ring5 };
  static int terms(Basis b) { return b == Basis::ptm6 ? 6 : 5; }
  static void basis(Basis b, const cv::Vec3d& d, double* out);
  Basis basis_ = Basis::ptm6;
  cv::Mat relit(const cv::Vec3d& direction) const;  // the model everywhere, clamped at 0
  std::vector<cv::Mat> coeffs_;  // one plane per basis term, each CV_32FC3
  cv::Mat captured_;             // the photos' per-pixel median (CV_32FC3): what is not relit
  cv::Mat object_;               // CV_8UC1: the object, the part that is relit
  cv::Mat fitted_;               // CV_8UC1: the pixels the fit could relight (the object lit by enough lamps)
  double fit_rms_ = 0;
  double reach_ = 0;             // the lamps' largest |(lx, ly)|: second-order terms are not carried beyond it
};

// The light direction for a point (u, v) on a unit disc as the user drags it
// over a sphere picture: (u, v, sqrt(1 - u^2 - v^2)), clamped onto the sphere.
cv::Vec3d direction_on_sphere(double u, double v);

}  // namespace veneer::repaint
