#pragma once
// Photometric stereo: per-pixel surface normals and albedo from an image set
// (one photo per lamp), Lambertian model I = albedo * intensity * max(0, n . l).
//
//  - distant mode: one light direction and intensity per lamp for the whole
//    image; the pseudo-inverse of the light matrix is computed once.
//  - near mode: the lamps' positions are known, so every pixel gets its own
//    light vectors with 1/r^2 falloff (Light::intensity convention of
//    imageset.hpp). The surface is first assumed on the z = 0 plane, then its
//    depth is refined from the recovered normals and the normals solved again.
//  - robust: per pixel, shadowed (dark relative to the pixel's brightest
//    sample) and saturated samples are dropped; at least 3 must remain or the
//    pixel is unreliable. Pseudo-inverses are cached per "lamps kept" pattern.
//    Coloured pixels are solved on their colour's part off the lamps' colour
//    (PsOptions::diffuse_chroma), where a glossy dielectric's highlight --
//    the lamp's colour -- does not reach.
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::ps {

enum class LightModel {
  automatic,  // near when every light has a position and the camera focal length is known, else distant
  distant,    // one direction per lamp for the whole image
  near,       // per-pixel light vectors from lamp positions, 1/r^2 falloff, depth refined
};
const char* light_model_name(LightModel);  // "automatic" | "distant" | "near"
Expected<LightModel> parse_light_model(const std::string&);

struct PsOptions {
  LightModel light_model = LightModel::automatic;  // see LightModel
  bool robust = true;              // drop shadowed/saturated samples per pixel (false = plain least squares)
  float shadow_fraction = 0.10f;   // robust: a sample below this fraction of the pixel's brightest is shadowed [0, 1)
  float saturation = 0.98f;        // robust: a sample with any channel >= this (1.0 = full scale) is saturated (0, 1]
  float min_signal = 1e-3f;        // pixels whose brightest grey sample is below this are unreliable (>= 0)
  float outlier_fraction = 0.0f;   // robust: after a first fit, the sample farthest from it (a cast shadow,
                                   // a highlight on a grey surface) is dropped and the pixel solved again
                                   // when it is off by more than this fraction of the pixel's brightest
                                   // sample (of 0.2 for darker pixels, whose deviations are mostly noise)
                                   // and 4+ samples remain [0, 1); 0 = off. Off by default since the
                                   // off-grey solve (diffuse_chroma) removes coloured objects' highlights:
                                   // on the quality table's 8 simulated pairs the transfer's exact nearest
                                   // then errs 2.08 degrees without this pass and 2.13 with it (3.20 and 3.71
                                   // before, with and without), and it costs up to 2x
  float penumbra_fraction = 0.10f; // robust: a sample in a partial shadow (a cast shadow's edge blurred by
                                   // the lens and the sensor's low-pass filter, or by the lamp's size) is
                                   // neither dark enough to drop as shadowed nor lit: one such sample turns
                                   // the fit. After a first fit over 5+ samples, the sample whose leaving out
                                   // fits the rest best is dropped and the pixel solved again when the rest
                                   // then fit at least 4x better and the fit without it predicts it brighter
                                   // by more than this fraction of the pixel's brightest sample [0, 1);
                                   // 0 = off. The rig twin's bull at 256x170 (camera optics): normals 8.33 ->
                                   // 6.98 degrees off the truth (mean), 43.7 -> 35.0 at the 95th percentile
  float diffuse_chroma = 0.25f;    // robust: a pixel whose colour is at least this far from grey
                                   // (|sum over its samples of colour - grey| / sum of grey) is solved on
                                   // that off-grey part alone, which a glossy dielectric's highlight (the
                                   // lamps' colour, divided out here) does not reach, so its normals no
                                   // longer lean towards the lamps; greyer pixels are solved on their grey
                                   // [0, 2]; 0 = off. Quality table, 512x340: the exact nearest's normal
                                   // error 3.20 -> 2.08 degrees, with the outlier pass
                                   // then off (bench_ps: red glossy sphere 3.85 -> 0.85)
  bool fill_unreliable = true;     // robust: a pixel left with < 3 lit samples takes its normal from its
                                   // reliable neighbours (diffused inward) instead of the plain fit over
                                   // shadowed samples, which errs by tens of degrees (the bull's far legs)
  bool subtract_ambient = true;    // subtract set.ambient when present
  bool refine_lights = true;       // robust, distant model: refine the lamps' directions and intensities
                                   // from the photos (calibrated rigs are a few degrees off): each lamp's
                                   // vector fitted to the solved normals over the pixels it lights
                                   // clearly, the whole set then brought by one linear map as close as it
                                   // goes to the recorded lamps (the photos fix them only up to such a map),
                                   // and the normals solved again; skipped when the normals do not spread
                                   // enough to fix a lamp. See PsResult::lights_refined
  int refine_iterations = 3;       // rounds of refine-then-solve (1..10)
  double refine_max_deg = 15.0;    // a lamp that would move farther than this is not a calibration error:
                                   // that round is dropped and the last plausible lamps (at first the
                                   // recorded ones) kept
  int near_iterations = 2;         // near: depth refinements after the z = 0 pass (0..5)
  int threads = 0;                 // 0 = all cores (TBB)
  Status check() const;
};

struct PsResult {
  cv::Mat normals;   // CV_32FC3 x,y,z rig frame, unit; (0,0,0) outside the mask or where there is
                     // no signal. A robust pixel with < 3 samples kept takes its neighbours'
                     // normal (PsOptions::fill_unreliable; else the plain least-squares normal)
                     // and is marked unreliable, so maps have no holes.
  cv::Mat albedo;    // CV_32FC3 BGR, relative to lamp intensity (1 = white Lambertian); 0 outside
  cv::Mat mask;      // CV_8UC1, the pixels that were solved (the input mask, or all)
  cv::Mat reliable;  // CV_8UC1, 255 where the normal is trustworthy (>= 3 samples kept, signal present)
  cv::Mat residual;  // CV_32FC1, RMS of the grey fit over kept samples, relative to the pixel's
                     // brightest sample (0 = perfect fit); 0 outside the mask. A confidence map.
  cv::Mat depth;     // CV_32FC1, near mode: estimated depth in metres along -z from the camera
                     // (0 outside); empty in distant mode
  LightModel model_used = LightModel::distant;
  bool lights_refined = false;          // the normals were solved with refined lamps (PsOptions::refine_lights)
  std::vector<io::Light> lights;            // lights_refined: the refined lamps (directions, intensities)
  std::vector<double> light_change_deg; // lights_refined: how far each lamp's direction moved
  int solved_pixels = 0;      // pixels in mask
  int unreliable_pixels = 0;  // pixels in mask that are not reliable
};

// Solves normals for the pixels of `mask` (CV_8UC1 of set.size; empty = every
// pixel). The photos are float or half floats (io::ReadOptions::half_floats:
// each row widened as it is loaded, no float copy). Fails with a message for: fewer than 3 lights, degenerate light
// directions (rank < 3), an empty mask, a mask of the wrong size, near mode
// without lamp positions/focal length, bad options, cancellation.
Expected<PsResult> photometric_stereo(const io::ImageSet& set, const cv::Mat& mask, const PsOptions& options = {},
                                      const Progress& progress = {});

// The same into `result`, reusing its buffers when their size and type fit:
// repeated calls on same-sized sets (live view, benchmarks) allocate nothing,
// which saves the page faults of ~20 MB of fresh output per call at 1024x680.
Status photometric_stereo_into(const io::ImageSet& set, const cv::Mat& mask, const PsOptions& options,
                               const Progress& progress, PsResult& result);

// Angular error of `normals` against `truth` (both CV_32FC3 x,y,z) over the
// pixels of `mask` where both are non-zero.
struct AngularError {
  double mean_deg = 0, median_deg = 0, p95_deg = 0, max_deg = 0;
  int pixels = 0;  // pixels compared
};
AngularError angular_error(const cv::Mat& normals, const cv::Mat& truth, const cv::Mat& mask);

// Pictures: residual as a grey 8-bit picture (black = perfect fit, white = the
// given relative residual or more), red where `reliable` is 0 inside `mask`.
cv::Mat residual_picture(const PsResult& result, float full_scale = 0.1f);

}  // namespace veneer::ps
