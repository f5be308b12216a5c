// Photometric stereo's row solver (internal to veneer_ps): the per-pixel
// least-squares fit of normals and albedo over one image row at a time, in
// structure-of-arrays buffers so that the inner loops run over pixels and
// vectorise. photometric_stereo.cpp sets it up (Setup) from an ImageSet and
// the options; light_calibration.cpp re-solves with refined lamps.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <tbb/task_arena.h>

#include "veneer/ps/photometric_stereo.hpp"

namespace veneer::ps::detail {

constexpr int kMaxPatternLights = 12;  // cache every pattern up to 2^12 (distant model)
constexpr int kMaxNearLights = 32;

// Every member has an initializer, so that setup_for (photometric_stereo.cpp)
// can name only the ones it sets.
struct Setup {
  int n = 0;
  int width = 0, height = 0;
  bool near = false;
  bool robust = true;
  float shadow_fraction = 0.1f, saturation = 0.98f, min_signal = 1e-3f, outlier_fraction = 0.0f;
  float penumbra_fraction = 0.0f;  // see PsOptions::penumbra_fraction
  float diffuse_chroma = 0.0f;   // see PsOptions::diffuse_chroma
  std::vector<float> dir{};      // n*3 distant directions
  std::vector<float> pos{};      // n*3 lamp positions (near)
  std::vector<float> pos_norm2{};  // n: |position|^2 (intensity reference distance)
  std::vector<float> inv_e{};    // n*3 BGR 1/intensity
  float f = 1, cx = 0, cy = 0;   // intrinsics (near)
  // Distant model: pseudo-inverse (3 x n, zero columns for dropped lamps) per pattern.
  bool use_cache = false;
  std::vector<float> pinv{};     // (1 << n) * 3 * n, or only the full pattern when !use_cache
  std::vector<uint8_t> pinv_ok{};
  uint32_t full = 0;
  std::vector<const float*> images{};  // n, continuous CV_32FC3
  const float* ambient = nullptr;
  // Or the photos in half floats (continuous CV_16FC3, io::ReadOptions::half_floats): then these are
  // set, images and ambient are not, and each row is widened as it is loaded.
  std::vector<const cv::float16_t*> half_images{};
  const cv::float16_t* half_ambient = nullptr;
};

// Pseudo-inverse of the rows of `dir` selected by `pattern`: (L^T L)^-1 L^T,
// in double. False when the kept directions do not span 3-D.
bool pattern_pinv(const std::vector<float>& dir, int n, uint32_t pattern, float* out);

// Per-task scratch: structure-of-arrays rows.
struct Scratch {
  int cap = 0, n = 0;
  std::vector<float> C;    // n*3*cap normalised B,G,R
  std::vector<float> Y;    // n*cap grey
  std::vector<float> W;    // n*cap weights (0/1)
  std::vector<float> V;    // n*3*cap light vectors (near)
  std::vector<float> acc;  // 12*cap: A00 A01 A02 A11 A12 A22 b0 b1 b2 gx gy gz
  std::vector<float> M, K, a, nx, ny, nz, ok, den, px, py, pz;
  std::vector<uint32_t> pat;
  std::vector<float> sat;  // n*cap: 1 where a channel is saturated
  std::vector<float> wide, wide_ambient;  // 3*cap: a half-float row's pixels widened (Setup::half_images)
  void resize(int n_, int cap_) {
    n = n_;
    cap = cap_;
    C.assign(size_t(n) * 3 * cap, 0.f);
    Y.assign(size_t(n) * cap, 0.f);
    W.assign(size_t(n) * cap, 0.f);
    V.assign(size_t(n) * 3 * cap, 0.f);
    acc.assign(size_t(12) * cap, 0.f);
    for (auto* v : {&M, &K, &a, &nx, &ny, &nz, &ok, &den, &px, &py, &pz}) v->assign(cap, 0.f);
    pat.assign(cap, 0);
    sat.assign(size_t(n) * cap, 0.f);
    wide.assign(size_t(3) * cap, 0.f);
    wide_ambient.assign(size_t(3) * cap, 0.f);
  }
};
// Output pointers for one row of `count` pixels.
struct RowOut {
  float* normals = nullptr;   // count*3
  float* albedo = nullptr;    // count*3 (may be null)
  float* residual = nullptr;  // count (may be null)
  uint8_t* reliable = nullptr;  // count (may be null)
};
// Solves `count` pixels of row y: x = x0 + k*step. `z` gives each pixel's
// surface z (rig frame) for the near model (null = 0). `mask`: the row's mask
// from x0, sampled with the same step.
void solve_row(const Setup& s, Scratch& b, int y, int x0, int step, int count, const float* z,
               const uint8_t* mask, const RowOut& out);

// Solves every row in [y0, y1) (step 1) in parallel, writing into `result`.
void solve_rows(const Setup& s, const cv::Mat& mask, const cv::Mat* zmap, int y0, int y1, PsResult& result);

// An error naming `what` when the n directions (n*3) do not span 3-D.
Status check_directions(const std::vector<float>& dir, int n, const std::string& what);

template <class F>
void run_parallel(int threads, F&& f) {
  if (threads > 0) {
    tbb::task_arena arena(threads);
    arena.execute(f);
  } else {
    f();
  }
}
// One solve of the whole set with its recorded lamps (photometric_stereo.cpp).
Status solve_once(const io::ImageSet& set, const cv::Mat& mask_in, const PsOptions& options, const Progress& progress,
                  PsResult& result);

}  // namespace veneer::ps::detail
