#pragma once
// The shaded look (issue 35): the destination repainted with the source's
// texture kept whole, in the chunks the map carries it in, while each lamp
// shades it as it shades the destination's own shape, and the source's gloss
// sits where the destination's normals put the highlights.
//
// Copying the source's photo per lamp (repaint.hpp) shades each chunk by the
// source's normals at the match: good shading wants small chunks of exact
// normals, whole texture wants large ones. Here the two are separated:
//
//   T(p)   = Sd(m(p)) * clip((c_d(p) + e) / (c_s(m(p)) + e), 1/x, x)
//   R_l(p) = T(p) * Dd_l(p) / Dd(p) + k_s(m(p)) (n_d(p).h_l)^alpha_s
//
// m the map; Sd the median of the source's photos less its fitted gloss
// (gloss.hpp): its texture and its shading; c_d, c_s the median over the
// lamps of n.l on each object's normals smoothed over `normal_smoothing` px,
// the shading at that coarse scale, so T carries the source's texture and
// fine relief under the destination's coarse shading; Dd_l the destination's
// photo under lamp l less its own gloss and Dd their median, both grey: the
// exact shading lamp l gives the destination's shape (its cast shadows
// included; grey, as the lamps are white, so a channel the destination
// barely reflects adds no noise);
// k_s, alpha_s the source's gloss lobe, placed by the destination's normals.
//
// Where chunks meet, T steps where the Lambert model misjudges the median
// shading: log T is re-solved there (screened Poisson, `seam_feather` px):
// inside chunks its gradients are T's own, across a seam those the source
// has around both sides' matches, so texture stays and the steps spread out.
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/match/matcher.hpp"
#include "veneer/repaint/gloss.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::repaint {

using match::Map;
using match::ObjectView;

// How a transfer repaints: `shaded` (the look above, the default) or `copy`
// (each lamp's source photo pasted through the map, the thesis's repaint).
enum class Look { shaded, copy };
const char* look_name(Look look);
Expected<Look> parse_look(std::string_view name);

struct LookOptions {
  double normal_smoothing = 4;   // s: normals smoothed over this Gaussian sigma for the coarse shading, px,
                                 // [0, 64]; default 4 (finer relief stays the source's texture). 0 re-shades
                                 // all relief by the destination's normals, as the simulator's truth defines
                                 // a material (colour and gloss; the relief is the shape's): the demo pair's
                                 // live spiral then scores plain error 1.30x the pixel copy's (1.94x at 4),
                                 // one exposure 0.70x (0.78x), but the source's fine detail in the result
                                 // (look.py's texture_corr) falls on real pairs 0.89 -> 0.59 (cat <- buddha)
  bool unoccluded_median = true; // Dd never below a_d c_d / 1.25 (a_d the destination's grey albedo from the
                                 // lamps that light it, c_d the median over the lamps of max(0, n.l) on its
                                 // normals): where other parts block the median lamp (under the belly, between
                                 // the legs) T, shaded by the unoccluded model, was lifted by Dd_l / Dd; with it
                                 // T Dd_l / Dd is about a_s Dd_l / a_d there. Default on (the demo pair's still
                                 // median against the truth's: 0.052 -> 0.045 at s = 4; the live spiral, one
                                 // exposure, 0.88x -> 0.79x the pixel copy)
  double shading_floor = 0.05;   // e added to both coarse shadings before their ratio, [0.001, 1]; default 0.05
  double max_correction = 5;     // the ratio clipped to [1/x, x], [1, 100]; default 5
  double ratio_headroom = 2;     // a lamp's shading ratio Dd_l / Dd at most this x the Lambert model's on the
                                 // destination's normals (and at least 2), [1, 100]: where the median lamp
                                 // is in a cast shadow, T (shaded by the model) times the measured ratio
                                 // blows up (inside the bull's legs 30-100x); smaller guards more but errs
                                 // from the destination's shading more (bull <- orange 512x340: 1.5 0.58x
                                 // the linear copy's shading error, 5 0.45x, off 0.27x); default 2
  bool source_gloss = true;      // fit the source's gloss, take it off its texture and place it by the
                                 // destination's normals; default on
  bool destination_gloss = true; // fit the destination's own gloss and take it off its shading ratio; default on
  double seam_feather = 0;       // steps of T at chunk seams spread over about this many px (screened
                                 // Poisson), [0, 64]; 0 = off, the default: it softens seams but the
                                 // result's fine detail then follows the source through the map less
                                 // (bull <- orange 512x340: texture correlation 0.67 -> 0.47 at 8 px)
  int seam_iterations = 80;      // at most this many conjugate-gradient steps per channel, 1..2000; default 80
  GlossOptions gloss;            // the lobe fits
  Status check() const;
};

// One side of a pair: its object and the direction of each photo's lamp (unit, rig frame).
struct LookSide {
  const ObjectView& view;
  const std::vector<cv::Vec3d>& lamps;
  cv::Vec3d camera{0, 0, 0};  // the camera's focal length and principal point at the view's scale (focal_px, cx,
                              // cy; 0 = not known): with the lamps' positions the live light is fitted as a lamp at
                              // a place (live_look.hpp)
};

class ShadedLook {
 public:
  // Works out T, the destination's shading medians and the glosses, once per
  // map. Fails, naming it, on a map of another size than the destination,
  // views whose photos, normals or masks do not fit, lamps that do not match
  // the photos, or options out of range; "cancelled" when progress cancels.
  static Expected<ShadedLook> make(const LookSide& destination, const LookSide& source, const Map& map,
                                   const LookOptions& options = {}, const Progress& progress = {});

  // R_l: the destination's photo under lamp `lamp` (linear CV_32FC3, ambient
  // removed, as the view's) repainted; unmapped pixels keep the photo.
  Expected<cv::Mat> paint(size_t lamp, const cv::Mat& destination_photo) const;
  // The per-pixel, per-channel median of paint() over all lamps (`photos` one per lamp).
  Expected<cv::Mat> median(const std::vector<cv::Mat>& destination_photos) const;

  const cv::Mat& texture() const { return texture_; }  // T (CV_32FC3), 0 where unmapped
  double source_exponent() const { return source_exponent_; }
  double destination_exponent() const { return destination_exponent_; }
  size_t lamps() const { return lamp_.size(); }
  // Seams the feathering found (neighbour pairs whose matches do not continue each other).
  size_t seams() const { return seams_; }

  // What the live look (live_look.hpp) shades with, per destination pixel:
  const cv::Mat& map_xy() const { return xy_; }                      // the map (CV_32FC2)
  const cv::Mat& shading_median() const { return shading_median_; }  // Dd + ratio_floor() (CV_32FC1)
  const cv::Mat& destination_gloss_weight() const { return destination_weight_; }  // k_d, may be empty
  const cv::Mat& source_gloss_weight() const { return source_weight_; }  // k_s(m(p)), may be empty
  const cv::Mat& destination_normals() const { return normals_; }
  const cv::Mat& model_median() const { return model_median_; }      // median of max(0, n_d.l) (CV_32FC1)
  float headroom() const { return headroom_; }
  static constexpr float ratio_floor() { return 1e-4f; }  // added to a lamp's grey shading and to Dd

 private:
  cv::Mat xy_;                   // the map's source coordinates (CV_32FC2)
  cv::Mat texture_;              // T
  cv::Mat shading_median_;       // Dd, of the grey (CV_32FC1)
  cv::Mat destination_weight_;   // k_d (CV_32FC1), empty without destination gloss
  cv::Mat source_weight_;        // k_s(m(p)) (CV_32FC1), empty without source gloss
  cv::Mat normals_;              // n_d
  cv::Mat model_median_;         // the median over the lamps of max(0, n_d.l) (CV_32FC1)
  float headroom_ = 2.f;
  std::vector<cv::Vec3f> lamp_, half_;
  double source_exponent_ = 0, destination_exponent_ = 0;
  size_t seams_ = 0;

  // R_l at pixel (x, y), channel-wise, for a mapped pixel and lamp l's photo value `d`
  cv::Vec3f shade(int x, int y, size_t lamp, const cv::Vec3f& d) const;
};

}  // namespace veneer::repaint
