#pragma once
// Cast shadows of an object on itself for any light direction, from its
// normals alone (issue 47): the live look's moving lamp darkens what the
// object's own shape hides from it, not only what the captured lamps' photos
// had dark.
//
//   1. A height field: the normals' slopes integrated over the mask (least
//      squares, coarse to fine), z toward the camera in pixels. Orthographic:
//      the rig's camera sees an 8 cm object from 1 m, its rays within a few
//      degrees of parallel.
//   2. Horizon maps, once: for `azimuths` directions in the image, per pixel
//      the elevation (degrees above the image plane) of the highest surface
//      point seen along that direction -- one sweep per line of the rotated
//      grid keeping the upper convex hull of the heights behind (O(n log n)
//      per line), the surface within `near_px` left out (its own slope: the
//      attached shadow is the shading's business).
//   3. Per frame: a pixel is in the lamp's cast shadow when the light's
//      elevation is below its horizon at the light's azimuth (interpolated
//      between the two nearest azimuths), softened over `softness_deg`.
//
// Heights come from the normals, so a depth step the normals do not show (a
// leg in front of the body, seen edge-on) is as deep as the slopes at its
// outline say, clipped at `max_slope`.
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::repaint {

struct ShadowOptions {
  int azimuths = 32;           // horizon directions around each pixel, 8..256; default 32
  double softness_deg = 4;     // the visibility ramps from 0 to 1 over this band of the light's elevation, centred
                               // on the horizon, degrees, [0.1, 45]; default 4 (lightpath.sh, the spiral: 2 and a
                               // floor of 0.03 gave about the same, see min_visibility)
  double max_slope = 30;       // the height field's slope |dz/dx| at most this (grazing normals), [1, 1000];
                               // default 30 (the bull, 1024x680, against the truth's depth: median error 1.6 px,
                               // shadows at the rig's lamps IoU 0.145; at 10: 2.5 px, 0.100; at 200: 1.8, 0.238
                               // but precision 0.58)
  int max_cells = 250000;      // the height field is solved on a grid of at most this many object cells (each
                               // cell a square of whole pixels), 1000..10^8; default 250000
  double near_px = 2;          // the surface nearer than this (image pixels) does not shadow a pixel, [0, 64];
                               // default 2
  double min_visibility = 0.03;     // the visibility at least this (a shadow's floor: light bounced in), [0, 1];
                                    // default 0.03. Measured (lightpath.sh orange spiral 24, the bull): on the
                                    // lamp's cast shadows live/copy 0.48 at 0, 0.49 at 0.02, 0.50 at 0.03 (softness
                                    // 4), 0.54 at 0.05; painted black where the truth is lit 0.87 %, 0.74 %, 0.53 %,
                                    // 0.51 % (the copy 0.23 %): a wrong shadow is painted dark, not black
  double observed_window_deg = 5;   // ShadowMap::observe: a captured lamp's shadow (or light) holds for lights
                                    // whose azimuth is at most this much farther from it than from the nearest
                                    // lamp's (and within 90 degrees), [0, 180]; default 5
  double observed_reach_deg = 15;   // ShadowMap::observe: and at most this far from the lamp's azimuth, [0, 180];
                                    // default 15. Measured (lightpath.sh orange spiral 24, on the helper's
                                    // branch): at 90 (across the rig's empty bottom socket) on the lamp's cast
                                    // shadows live/copy 0.50, but shading with one exposure 0.95x, its worst frame
                                    // 1.24x; at 30: 0.56, 0.88x, 1.09x (without the shadows: 0.62, 0.98x, 1.13x).
                                    // On merged main (frame-exposed, the light as a place), shading / worst frame /
                                    // cast shadows: 30: spiral 0.91x / 1.22x / 0.56, circle on the lamps' cone
                                    // 0.96x / 1.90x (halfway between two lamps a photo's shadow darkened what the
                                    // light lit); 15: spiral 0.88x / 1.14x / 0.69, circle 0.75x / 1.00x, stone
                                    // 0.78x -> 0.76x, apple 0.85x -> 0.84x; 5: spiral 0.86x / 1.05x / 0.87
  double observed_below_deg = 90;   // ShadowMap::observe: a photo's shadow holds for lights down to this many degrees
                                    // below its lamp's elevation (then fades out over 10 more), [0, 90]; 90 = a
                                    // height field's (what a lamp's elevation shadows, any lower one does); less
                                    // for overhangs (a horn's shadow moves off as the lamp sinks). Default 90
  double observed_margin_deg = 3;   // ShadowMap::observe: a pixel the photo shows in shadow gets its horizon at
                                    // least this far above the lamp, one it shows lit at least this far below,
                                    // degrees, [0, 30]; default 3 (beyond half the softness)
  Status check() const;
};

// The object's height toward the camera in pixels (CV_32FC1 of the mask's
// size, 0 outside the mask), integrated from `normals` (CV_32FC3 x, y, z in
// the rig frame: x right, y up, z toward the camera; the image's y goes
// down) over `mask` (CV_8UC1) on a grid of `step` pixels (1 = every pixel;
// the grid's heights bilinearly spread to the pixels). Each connected part
// is anchored with its outline at 0. Fails on types or sizes that do not fit,
// an empty mask, or "cancelled".
Expected<cv::Mat> height_from_normals(const cv::Mat& normals, const cv::Mat& mask, int step = 1,
                                      double max_slope = 30, const Progress& progress = {});

// The horizons of a set of pixels, compact (what a live frame reads): one
// byte per pixel and azimuth.
// What the photos show of cast shadows, per captured lamp (`lamps`, rig
// frame, toward the lamp; `photos` linear CV_32FC3 or CV_32FC1, ambient
// removed, one per lamp): among the pixels of `mask` facing the lamp
// (n.l > 0.2 on `normals`), `shadowed` where the photo is below `dark` x what
// the pixel's albedo (the 70th percentile of photo / n.l over the lamps facing
// it: up to half of them may be shadowed)
// predicts, `lit` where it is above `bright` x that (CV_8UC1, 255). Fails on
// sizes or types that do not fit.
struct PhotoShadows {
  std::vector<cv::Mat> shadowed, lit;
  cv::Mat albedo;  // CV_32FC1: the grey albedo estimate (0 where no lamp faces the pixel)
};
Expected<PhotoShadows> photo_shadows(const std::vector<cv::Mat>& photos, const cv::Mat& normals, const cv::Mat& mask,
                                     const std::vector<cv::Vec3d>& lamps, double dark = 0.35, double bright = 0.6);

class PixelHorizons {
 public:
  // Visibility in [0, 1] (0: in the cast shadow) at light direction `l`
  // (rig frame, toward the lamp; need not be unit) of pixels [from, from +
  // count) of pixels(), into `out`. About a nanosecond per pixel.
  void visibility(const cv::Vec3d& l, int from, int count, float* out) const;
  // The same for all pixels.
  std::vector<float> visibility(const cv::Vec3d& l) const;
  const std::vector<int>& pixels() const { return pixels_; }  // y * width + x
  int azimuths() const { return planes_.rows; }
  bool empty() const { return pixels_.empty(); }

 private:
  friend class ShadowMap;
  std::vector<int> pixels_;
  cv::Mat planes_;  // azimuths x pixels, CV_8UC1: the horizon's elevation, 0..90 degrees in 255 steps
  float softness_deg_ = 2;
  float min_visibility_ = 0;
  cv::Mat observed_;  // azimuths x pixels, CV_8UC1: the photos' shadows, the lamp's elevation (as planes_), 0 = none
  float observed_below_deg_ = 90, observed_margin_deg_ = 3;
};

class ShadowMap {
 public:
  // From the object's normals and mask (as height_from_normals), the grid
  // chosen so that at most options.max_cells object cells are solved. Fails,
  // naming it, on types or sizes that do not fit, an empty mask, options out
  // of range, or "cancelled".
  static Expected<ShadowMap> make(const cv::Mat& normals, const cv::Mat& mask, const ShadowOptions& options = {},
                                  const Progress& progress = {});
  // From a height field already made (CV_32FC1 in pixels, as
  // height_from_normals gives; a test's oracle), on a grid of `step` pixels.
  static Expected<ShadowMap> from_height(const cv::Mat& height, const cv::Mat& mask, int step,
                                         const ShadowOptions& options = {}, const Progress& progress = {});

  // Agreement with the photos: at each captured lamp (`lamps`, rig frame,
  // toward the lamp), the pixels its photo shows in a cast shadow
  // (`shadowed`, CV_8UC1 of size(), non-zero) get their horizon at least
  // observed_margin_deg above the lamp's elevation, and those it shows lit
  // (`lit`) at most that far below it, at the azimuths nearer the lamp's than
  // any other lamp's (give or take observed_window_deg; the shadow wins where
  // two lamps' azimuths overlap). Heights from normals miss depth steps the normals do
  // not show (a far leg behind a near one); the photos saw them. Fails on
  // sizes that do not fit.
  Status observe(const std::vector<cv::Vec3d>& lamps, const std::vector<cv::Mat>& shadowed,
                 const std::vector<cv::Mat>& lit);

  // The horizons of `pixels` (y * width + x, each inside the image).
  PixelHorizons at(const std::vector<int>& pixels) const;
  // Visibility at `l` of every pixel (CV_32FC1 of size(); 1 outside the mask).
  cv::Mat visibility(const cv::Vec3d& l) const;
  // The horizon's elevation (degrees) at pixel (x, y) toward image azimuth
  // `k` of azimuths() (direction (cos, sin) of 2 pi k / azimuths in the
  // image, y down).
  float horizon_deg(int x, int y, int k) const;

  cv::Size size() const { return size_; }
  int step() const { return step_; }
  int azimuths() const { return static_cast<int>(planes_.size()); }
  const cv::Mat& height() const { return height_; }  // the grid's heights in pixels (CV_32FC1, 0 outside)
  const ShadowOptions& options() const { return options_; }

 private:
  ShadowOptions options_;
  cv::Size size_;
  int step_ = 1;
  cv::Rect box_;                 // the grid cells holding the object
  cv::Mat height_, cells_;       // grid: heights (pixels), object cells (CV_8UC1)
  std::vector<cv::Mat> planes_;  // per azimuth, over box_: the horizon's elevation, CV_8UC1 (0..90 deg in 255 steps)
  std::vector<cv::Mat> observed_;  // per azimuth, over box_: the elevation of the lamp whose photo shows the cell in
                                   // shadow (the highest), CV_8UC1 as planes_, 0 = none; empty before observe()
  // the horizon at pixel (x, y), azimuth k, in bytes: bilinear over the object cells about it
  float code_at(int x, int y, int k) const;
  float code_at(const std::vector<cv::Mat>& planes, int x, int y, int k) const;
  Status sweep_all(const Progress& progress);
};

}  // namespace veneer::repaint
