#pragma once
// A relightable model of one object's shading, fitted from its photos (one
// per lamp) and evaluated at any lamp direction as one dot product per pixel:
//
//   S(p, l) = sum_k c_k(p) b_k(l) + sum_i w_i(l) r_i(p)
//
// b_k the basis' functions of the lamp direction l (unit, rig frame), c_k(p)
// per-pixel coefficients fitted by ridge-regularised least squares over the
// captured lamps; r_i(p) what the fit leaves of the photo under captured lamp
// i, and w_i(l) a narrow Gaussian radial basis over the lamps' directions
// interpolating it (exact at a captured lamp, 0 far from all of them).
//
// The model is what the live view (live_look.hpp) shades the destination with
// at a light the rig never captured; it carries what the photos hold (cast
// shadows, gloss), not only Lambert on normals. The default was chosen by
// leaving one lamp out on the real cat and buddha, scored as livelook.py
// scores the live view (tools/prototypes/live/README.md): HSH order 3 + a
// 5 deg residual 0.0770, HSH 3 alone 0.0792, PTM 0.0795, Lambert on normals
// 0.0793, an exact radial basis over the lamps 0.0889.
//
// The hemispherical-harmonics basis is hsh.hpp's (hsh_basis), the one an
// .rti export writes; fit_coefficients is a ridge-regularised fit in any
// basis, reusable on its own.
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::repaint {

enum class RelightBasis {
  hsh,  // hemispherical harmonics of `order` (order^2 terms)
  ptm,  // polynomial texture map: lu^2, lv^2, lu lv, lu, lv, 1 (6 terms)
};
const char* relight_basis_name(RelightBasis basis);
Expected<RelightBasis> parse_relight_basis(std::string_view name);

// The PTM basis at `l`: lu^2, lv^2, lu lv, lu, lv, 1 (6 values).
void ptm_basis(const cv::Vec3d& l, float* out);

struct RelightableOptions {
  RelightBasis basis = RelightBasis::hsh;  // see above; default chosen by measurement (README)
  int order = 3;              // HSH order, 1..3 (order^2 terms); default 3
  double ridge = 0.05;        // added to the normal equations' diagonal, times their mean diagonal, [0, 10];
                              // default 0.05 (order 3 without it overshoots: 0.0996 against 0.0792)
  double residual_deg = 5;    // the residuals' radial basis width over the lamps' angles, degrees, [0, 90];
                              // 0 = no residual (the smooth fit alone); default 5 (2: 0.0790, 3: 0.0782)
  Status check() const;
};

// Per pixel of `mask`, the coefficients c_k of `photos` (the grey of CV_32FC3;
// for one channel, pass that channel's CV_32FC1 photos) in the basis of
// `terms` functions given per lamp by `basis` (lamps x terms, CV_32FC1; e.g.
// hsh_basis of each lamp's direction), the ridge times the normal equations'
// mean diagonal: CV_32FC(terms), 0 outside the mask. Fails on sizes that do
// not fit, more than 64 terms, or fewer lamps than terms without a ridge.
Expected<cv::Mat> fit_coefficients(const std::vector<cv::Mat>& photos, const cv::Mat& mask, const cv::Mat& basis,
                                   double ridge, const Progress& progress = {});

class RelightableModel {
 public:
  // `photos` linear (CV_32FC3 or CV_32FC1; the grey is fitted), ambient
  // removed, one per lamp of `directions` (unit); `mask` CV_8UC1.
  static Expected<RelightableModel> fit(const std::vector<cv::Mat>& photos, const cv::Mat& mask,
                                        const std::vector<cv::Vec3d>& directions,
                                        const RelightableOptions& options = {}, const Progress& progress = {});
  // The weights at direction `l` (terms() values: the basis, then the residuals' w_i).
  std::vector<float> weights(const cv::Vec3d& l) const;
  int terms() const { return terms_; }
  int basis_terms() const { return basis_terms_; }
  // Per-pixel coefficients (CV_32FC(terms()): c_k, then r_i), 0 outside the mask.
  const cv::Mat& coefficients() const { return coefficients_; }
  // The whole picture's grey shading at direction `l` (CV_32FC1, at least 0; 0 outside the mask).
  cv::Mat evaluate(const cv::Vec3d& l) const;
  const RelightableOptions& options() const { return options_; }
  // Releases the per-pixel coefficients (for a caller that keeps them in its
  // own layout); weights() still works, evaluate() then gives 0.
  void drop_coefficients() { coefficients_ = cv::Mat(); }

 private:
  RelightableOptions options_;
  int basis_terms_ = 0, terms_ = 0;
  cv::Mat coefficients_;
  std::vector<cv::Vec3d> lamps_;
  cv::Mat kernel_inverse_;  // (K + lambda I)^-1 over the lamps (CV_64FC1), empty without residuals
};

}  // namespace veneer::repaint
