#pragma once
// A relightable model of one object's shading, fitted from its photos (one
// per lamp) and evaluated at any lamp direction as one dot product per pixel:
//
//   S(p, l) = sum_k c_k(p) b_k(l)
//
// b_k the basis' functions of the lamp direction l (unit, rig frame), c_k(p)
// per-pixel coefficients fitted by ridge-regularised least squares over the
// captured lamps. The model is what the live view (live_look.hpp) shades the
// destination with at a light the rig never captured; it carries what the
// photos hold (cast shadows, gloss), not only Lambert on normals. Which basis
// is the default was chosen by leave-one-lamp-out on real pairs
// (tools/prototypes/live/README.md).
//
// The hemispherical-harmonics basis (hsh_basis) is also what an .rti export
// writes; fit_coefficients is that fit, reusable on its own.
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::repaint {

enum class RelightBasis {
  hsh,            // hemispherical harmonics of `order` (order^2 terms)
  ptm,            // polynomial texture map: lu^2, lv^2, lu lv, lu, lv, 1 (6 terms)
  lambert_ratio,  // max(0, n.l) times a per-pixel ratio interpolated over the lamps (radial basis); see .cpp
};
const char* relight_basis_name(RelightBasis basis);
Expected<RelightBasis> parse_relight_basis(std::string_view name);

// The hemispherical harmonics of `order` (1..4) at unit direction `l` (z toward
// the camera; l.z <= 0 is clamped to the horizon): order^2 values into `out`,
// the basis of the RTI format's HSH (Gautron et al. 2004).
void hsh_basis(const cv::Vec3d& l, int order, float* out);
// The PTM basis at `l`: lu^2, lv^2, lu lv, lu, lv, 1 (6 values).
void ptm_basis(const cv::Vec3d& l, float* out);

struct RelightableOptions {
  RelightBasis basis = RelightBasis::hsh;  // see above; default chosen by measurement (README)
  int order = 2;              // HSH order, 1..4 (order^2 terms); default 2
  double ridge = 1e-3;        // added to the normal equations' diagonal (relative to their trace / terms),
                              // [0, 10]; default 1e-3
  double kernel_deg = 20;     // lambert_ratio: the Gaussian width over the lamps' angles, degrees, (0, 180];
                              // default 20
  Status check() const;
};

// Per pixel of `mask`, the coefficients c_k of `photos` (CV_32FC1 or CV_32FC3;
// the grey is fitted) over `directions` (unit, one per photo) in the basis of
// `terms` functions given per lamp by `basis` (lamps x terms, CV_32FC1):
// CV_32FC(terms), 0 outside the mask. Fails on sizes that do not fit or fewer
// lamps than terms without a ridge.
Expected<cv::Mat> fit_coefficients(const std::vector<cv::Mat>& photos, const cv::Mat& mask, const cv::Mat& basis,
                                   double ridge, const Progress& progress = {});

class RelightableModel {
 public:
  // `photos` linear (CV_32FC3 or CV_32FC1), ambient removed, one per lamp;
  // `normals` CV_32FC3 (the lambert_ratio basis uses them); `mask` CV_8UC1.
  static Expected<RelightableModel> fit(const std::vector<cv::Mat>& photos, const cv::Mat& normals,
                                        const cv::Mat& mask, const std::vector<cv::Vec3d>& directions,
                                        const RelightableOptions& options = {}, const Progress& progress = {});
  // The basis at direction `l` (terms() values).
  std::vector<float> basis(const cv::Vec3d& l) const;
  int terms() const { return terms_; }
  // Per-pixel coefficients (CV_32FC(terms())), 0 outside the mask.
  const cv::Mat& coefficients() const { return coefficients_; }
  // Pixel (x, y)'s shading at basis values `b`: the dot product, at least 0.
  float at(int x, int y, const float* b) const;
  // The whole picture's grey shading at direction `l` (CV_32FC1, 0 outside the mask).
  cv::Mat evaluate(const cv::Vec3d& l) const;
  const RelightableOptions& options() const { return options_; }

 private:
  RelightableOptions options_;
  int terms_ = 0;
  cv::Mat coefficients_;
  cv::Mat normals_;                  // lambert_ratio only
  std::vector<cv::Vec3d> lamps_;     // lambert_ratio only
};

}  // namespace veneer::repaint
