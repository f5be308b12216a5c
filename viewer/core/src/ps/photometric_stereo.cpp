// Photometric stereo (see photometric_stereo.hpp).
//
// Speed: every full-resolution pass works on one image row at a time with
// structure-of-arrays buffers (per lamp: B, G, R, grey), so the inner loops run
// over pixels and vectorise. The distant model multiplies by one
// pseudo-inverse per "lamps kept" pattern (computed once, at most 2^n); the
// near model forms the 3x3 normal equations per pixel from its own light
// vectors. The near model's depth refinement runs on a sub-sampled grid; the
// full-resolution image is read exactly once.
//
// The row solver is in row_solver.cpp, light self-calibration in
// light_calibration.cpp, the evaluation helpers in ps_evaluation.cpp.
#include "veneer/ps/photometric_stereo.hpp"

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "depth.hpp"
#include "row_solver.hpp"
#include "veneer/io/big_buffers.hpp"
#include "veneer/util/enum_names.hpp"
#include "veneer/util/log.hpp"

namespace veneer::ps {

// "auto" is an alias of "automatic".
constexpr EnumName<LightModel> kLightModelNames[] = {{LightModel::automatic, "automatic"},
                                                     {LightModel::distant, "distant"},
                                                     {LightModel::near, "near"},
                                                     {LightModel::automatic, "auto"}};

const char* light_model_name(LightModel m) { return name_of(kLightModelNames, m, "automatic"); }

Expected<LightModel> parse_light_model(const std::string& s) { return parse_name(kLightModelNames, s, "light model"); }

Status PsOptions::check() const {
  if (!(shadow_fraction >= 0.f && shadow_fraction < 1.f))
    return make_error("shadow_fraction must be in [0, 1), got " + std::to_string(shadow_fraction));
  if (!(saturation > 0.f && saturation <= 1.f))
    return make_error("saturation must be in (0, 1], got " + std::to_string(saturation));
  if (!(min_signal >= 0.f)) return make_error("min_signal must be >= 0, got " + std::to_string(min_signal));
  if (!(penumbra_fraction >= 0.f && penumbra_fraction < 1.f))
    return make_error("penumbra_fraction must be in [0, 1), got " + std::to_string(penumbra_fraction));
  if (!(outlier_fraction >= 0.f && outlier_fraction < 1.f))
    return make_error("outlier_fraction must be in [0, 1), got " + std::to_string(outlier_fraction));
  if (!(diffuse_chroma >= 0.f && diffuse_chroma <= 2.f))
    return make_error("diffuse_chroma must be in [0, 2], got " + std::to_string(diffuse_chroma));
  if (refine_iterations < 1 || refine_iterations > 10)
    return make_error("refine_iterations must be in 1..10, got " + std::to_string(refine_iterations));
  if (!(refine_max_deg > 0 && refine_max_deg <= 45))
    return make_error("refine_max_deg must be in (0, 45], got " + std::to_string(refine_max_deg));
  if (near_iterations < 0 || near_iterations > 5)
    return make_error("near_iterations must be in 0..5, got " + std::to_string(near_iterations));
  if (threads < 0) return make_error("threads must be >= 0, got " + std::to_string(threads));
  return Status::success();
}

namespace detail {
namespace {

// Pixels that kept fewer than 3 lit samples (cast shadows on most lamps) have
// no normal of their own: the plain fit over shadowed samples errs by tens of
// degrees. They take the mean normal of their already-known 8-neighbours,
// nearest reliable pixels first (a breadth-first diffusion inside the mask),
// which follows a limb or a leg's curvature from where it is lit.
void fill_from_neighbours(cv::Mat& normals, const cv::Mat& mask, const cv::Mat& reliable) {
  const int W = normals.cols, H = normals.rows;
  cv::Mat known(normals.size(), CV_8UC1, cv::Scalar(0));
  std::vector<cv::Point> front, next;
  for (int y = 0; y < H; ++y) {
    const uint8_t* m = mask.ptr<uint8_t>(y);
    const uint8_t* r = reliable.ptr<uint8_t>(y);
    uint8_t* k = known.ptr<uint8_t>(y);
    for (int x = 0; x < W; ++x) k[x] = (m[x] && r[x]) ? 1 : 0;
  }
  // First ring: unknown pixels with a known neighbour.
  auto ring_of = [&](const std::vector<cv::Point>* from, std::vector<cv::Point>& out) {
    out.clear();
    auto consider = [&](int x, int y) {
      if (x < 0 || y < 0 || x >= W || y >= H) return;
      if (!mask.at<uint8_t>(y, x) || known.at<uint8_t>(y, x)) return;
      known.at<uint8_t>(y, x) = 2;  // queued
      out.push_back({x, y});
    };
    if (!from) {
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x)
          if (known.at<uint8_t>(y, x) == 1)
            for (int dy = -1; dy <= 1; ++dy)
              for (int dx = -1; dx <= 1; ++dx) consider(x + dx, y + dy);
    } else {
      for (const cv::Point& p : *from)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) consider(p.x + dx, p.y + dy);
    }
  };
  ring_of(nullptr, front);
  while (!front.empty()) {
    std::vector<cv::Vec3f> value(front.size());
    for (size_t i = 0; i < front.size(); ++i) {
      const cv::Point p = front[i];
      cv::Vec3f sum(0, 0, 0);
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int x = p.x + dx, y = p.y + dy;
          if (x < 0 || y < 0 || x >= W || y >= H || known.at<uint8_t>(y, x) != 1) continue;
          sum += normals.at<cv::Vec3f>(y, x);
        }
      const float len = static_cast<float>(cv::norm(sum));
      value[i] = len > 0 ? sum / len : normals.at<cv::Vec3f>(p);
    }
    for (size_t i = 0; i < front.size(); ++i) {
      normals.at<cv::Vec3f>(front[i]) = value[i];
      known.at<uint8_t>(front[i]) = 1;
    }
    ring_of(&front, next);
    front.swap(next);
  }
}

// The solver's thresholds from the options, for n lamps over images of
// `size`; the robust-only ones are off without `robust`. The lamps, the
// pseudo-inverses and the images are the caller's to fill in.
Setup setup_for(const PsOptions& o, int n, cv::Size size) {
  return Setup{.n = n, .width = size.width, .height = size.height, .robust = o.robust,
               .shadow_fraction = o.shadow_fraction, .saturation = o.saturation, .min_signal = o.min_signal,
               .outlier_fraction = o.outlier_fraction, .penumbra_fraction = o.penumbra_fraction, .diffuse_chroma = o.robust ? o.diffuse_chroma : 0.f};
}

}  // namespace

Status solve_once(const io::ImageSet& set, const cv::Mat& mask_in, const PsOptions& options, const Progress& progress,
                  PsResult& result) {
  if (Status st = options.check(); !st) return make_error("photometric stereo options: " + st.message());
  const int n = static_cast<int>(set.images.size());
  if (n < 3)
    return make_error("photometric stereo needs at least 3 lights, the set has " + std::to_string(n));
  if (set.lights.size() != set.images.size())
    return make_error("the set has " + std::to_string(set.images.size()) + " images but " +
                      std::to_string(set.lights.size()) + " lights");
  const cv::Size size = set.images[0].size();
  if (size.width <= 0 || size.height <= 0) return make_error("the set's images are empty");
  // float photos, or half floats (io::ReadOptions::half_floats), every one alike
  const int type = set.images[0].type();
  if (type != CV_32FC3 && type != CV_16FC3)
    return make_error("image 0 is not CV_32FC3 or CV_16FC3 (linear float or half-float BGR)");
  for (int i = 0; i < n; ++i) {
    const cv::Mat& im = set.images[i];
    if (im.type() != type) return make_error("image " + std::to_string(i) + " is not of image 0's type");
    if (im.size() != size)
      return make_error("image " + std::to_string(i) + " is " + std::to_string(im.cols) + "x" +
                        std::to_string(im.rows) + ", image 0 is " + std::to_string(size.width) + "x" +
                        std::to_string(size.height));
  }
  cv::Mat mask;
  if (mask_in.empty()) {
    mask = cv::Mat(size, CV_8UC1, cv::Scalar(255));
  } else {
    if (mask_in.type() != CV_8UC1) return make_error("the mask is not CV_8UC1");
    if (mask_in.size() != size)
      return make_error("the mask is " + std::to_string(mask_in.cols) + "x" + std::to_string(mask_in.rows) +
                        ", the images are " + std::to_string(size.width) + "x" + std::to_string(size.height));
    mask = mask_in;
  }
  const int solved = cv::countNonZero(mask);
  if (solved == 0) return make_error("the mask is empty: no object pixels to solve");

  Setup s = setup_for(options, n, size);
  s.dir.resize(size_t(n) * 3);
  s.inv_e.resize(size_t(n) * 3);
  bool have_positions = true;
  for (int i = 0; i < n; ++i) {
    const io::Light& l = set.lights[i];
    const double len = cv::norm(l.direction);
    if (!(len > 0.5 && len < 1.5))
      return make_error("light " + std::to_string(i) + " has a direction of length " + std::to_string(len));
    for (int c = 0; c < 3; ++c) s.dir[i * 3 + c] = static_cast<float>(l.direction[c] / len);
    for (int c = 0; c < 3; ++c) {
      const float e = l.intensity[2 - c];  // intensity is [r,g,b]; channel 0 is B
      if (!(e > 0.f)) return make_error("light " + std::to_string(i) + " has a non-positive intensity");
      s.inv_e[i * 3 + c] = 1.f / e;
    }
    if (!l.position_m) have_positions = false;
  }
  LightModel model = options.light_model;
  const bool near_possible = have_positions && set.camera.focal_px > 0;
  if (model == LightModel::automatic) model = near_possible ? LightModel::near : LightModel::distant;
  if (model == LightModel::near) {
    if (!have_positions) return make_error("the near-light model needs every lamp's position_m; the set lacks some");
    if (!(set.camera.focal_px > 0)) return make_error("the near-light model needs the camera focal length (camera.focal_px)");
    if (n > kMaxNearLights) return make_error("the near-light model supports at most 32 lamps, the set has " + std::to_string(n));
  }
  s.near = model == LightModel::near;
  if (Status st = check_directions(s.dir, n, "light directions"); !st) return make_error(st.message());
  if (s.near) {
    s.pos.resize(size_t(n) * 3);
    s.pos_norm2.resize(n);
    std::vector<float> pdir(size_t(n) * 3);
    for (int i = 0; i < n; ++i) {
      const cv::Vec3d p = *set.lights[i].position_m;
      const double r = cv::norm(p);
      if (!(r > 1e-6)) return make_error("lamp " + std::to_string(i) + " sits at the rig origin");
      for (int c = 0; c < 3; ++c) {
        s.pos[i * 3 + c] = static_cast<float>(p[c]);
        pdir[i * 3 + c] = static_cast<float>(p[c] / r);
      }
      s.pos_norm2[i] = static_cast<float>(r * r);
    }
    if (Status st = check_directions(pdir, n, "lamp positions"); !st) return make_error(st.message());
    s.f = static_cast<float>(set.camera.focal_px);
    s.cx = static_cast<float>(set.camera.cx > 0 ? set.camera.cx : (size.width - 1) * 0.5);
    s.cy = static_cast<float>(set.camera.cy > 0 ? set.camera.cy : (size.height - 1) * 0.5);
  }
  s.full = n >= 32 ? 0xffffffffu : ((1u << n) - 1u);
  if (!s.near) {
    s.use_cache = n <= kMaxPatternLights;
    if (s.use_cache) {
      const size_t patterns = size_t(1) << n;
      s.pinv.assign(patterns * 3 * n, 0.f);
      s.pinv_ok.assign(patterns, 0);
      if (s.robust) {
        for (uint32_t p = 0; p < patterns; ++p)
          if (std::popcount(p) >= 3) s.pinv_ok[p] = pattern_pinv(s.dir, n, p, s.pinv.data() + size_t(p) * 3 * n);
      } else {
        s.pinv_ok[s.full] = pattern_pinv(s.dir, n, s.full, s.pinv.data() + size_t(s.full) * 3 * n);
      }
    } else if (!s.robust) {
      // Too many lamps for a pattern cache: the one pseudo-inverse of all of them.
      cv::Mat L(n, 3, CV_64F);
      for (int i = 0; i < n; ++i)
        for (int c = 0; c < 3; ++c) L.at<double>(i, c) = s.dir[i * 3 + c];
      cv::Mat P;
      cv::invert(L, P, cv::DECOMP_SVD);
      s.pinv.assign(size_t(3) * n, 0.f);
      for (int r = 0; r < 3; ++r)
        for (int i = 0; i < n; ++i) s.pinv[size_t(r) * n + i] = static_cast<float>(P.at<double>(r, i));
    }
  }
  const bool half = type == CV_16FC3;
  if (half) s.half_images.resize(n);
  else s.images.resize(n);
  std::vector<cv::Mat> holders;  // continuous copies when needed
  holders.reserve(n);
  for (int i = 0; i < n; ++i) {
    const cv::Mat* im = &set.images[i];
    if (!im->isContinuous()) {
      holders.push_back(im->clone());
      im = &holders.back();
    }
    if (half) s.half_images[i] = im->ptr<cv::float16_t>();
    else s.images[i] = im->ptr<float>();
  }
  cv::Mat ambient;
  if (options.subtract_ambient && !set.ambient.empty()) {
    if (set.ambient.type() != type || set.ambient.size() != size)
      return make_error("the ambient frame does not match the images (type or size)");
    ambient = set.ambient.isContinuous() ? set.ambient : set.ambient.clone();
    if (half) s.half_ambient = ambient.ptr<cv::float16_t>();
    else s.ambient = ambient.ptr<float>();
  }

  result.model_used = model;
  if (result.mask.data != mask.data) mask.copyTo(result.mask);
  result.solved_pixels = solved;
  // Every pixel is written by solve_rows (zeros outside the mask). Fresh
  // full-resolution results are prefaulted in one call (big_buffers.hpp).
  for (cv::Mat* m : {&result.normals, &result.albedo, &result.residual})
    if (m->empty()) m->allocator = io::prefault_allocator();
  result.normals.create(size, CV_32FC3);
  result.albedo.create(size, CV_32FC3);
  result.residual.create(size, CV_32FC1);
  result.reliable.create(size, CV_8UC1);

  std::atomic<bool> cancelled{false};
  cv::Mat zfull;
  bool failed_depth = false;
  run_parallel(options.threads, [&] {
    if (s.near) {
      // Depth refinement on a sub-sampled grid: z = 0 first, then integrate the
      // normals into a depth map and solve again.
      progress.report(0.0, "near light: depth");
      DepthGrid grid = make_depth_grid(size, mask, s.f, s.cx, s.cy);
      std::vector<float> zrow;
      for (int it = 0; it <= options.near_iterations; ++it) {
        if (progress.cancelled()) {
          cancelled = true;
          return;
        }
        tbb::parallel_for(tbb::blocked_range<int>(0, grid.rows, 2), [&](const tbb::blocked_range<int>& r) {
          Scratch sc;
          sc.resize(s.n, grid.cols);
          std::vector<float> zr(grid.cols);
          for (int gyi = r.begin(); gyi < r.end(); ++gyi) {
            const int y = grid.y0 + gyi * grid.step;
            for (int k = 0; k < grid.cols; ++k) zr[k] = grid.z.at<float>(gyi, k);
            RowOut out;
            out.normals = grid.normals.ptr<float>(gyi);
            out.reliable = grid.reliable.ptr<uint8_t>(gyi);
            solve_row(s, sc, y, grid.x0, grid.step, grid.cols, zr.data(), mask.ptr<uint8_t>(y) + grid.x0, out);
          }
        });
        if (it == options.near_iterations) break;
        if (!integrate_depth(grid)) {
          failed_depth = true;
          break;
        }
        progress.report(0.3 * (it + 1) / std::max(1, options.near_iterations), "near light: depth");
      }
      zfull = upsample_depth(grid, size);
    }
    const int batches = 8;
    for (int bi = 0; bi < batches; ++bi) {
      if (progress.cancelled()) {
        cancelled = true;
        return;
      }
      const int y0 = size.height * bi / batches, y1 = size.height * (bi + 1) / batches;
      solve_rows(s, mask, s.near ? &zfull : nullptr, y0, y1, result);
      progress.report((s.near ? 0.3 : 0.0) + (s.near ? 0.7 : 1.0) * (bi + 1) / batches, "normals");
    }
  });
  if (cancelled) return make_error("photometric stereo cancelled");
  if (failed_depth) VLOG_WARN("PS", "near-light depth refinement did not converge; kept the previous depth");
  if (s.near) {
    result.depth.create(size, CV_32FC1);
    result.depth.setTo(0);
    // Depth along -z from the camera at z = 1.
    cv::subtract(cv::Scalar(1.0), zfull, result.depth, mask);
  } else {
    result.depth.release();
  }
  result.unreliable_pixels = solved - cv::countNonZero(result.reliable);
  if (options.robust && options.fill_unreliable && result.unreliable_pixels > 0)
    fill_from_neighbours(result.normals, mask, result.reliable);
  progress.report(1.0, "normals");
  return Status::success();
}

}  // namespace detail

Expected<PsResult> photometric_stereo(const io::ImageSet& set, const cv::Mat& mask, const PsOptions& options,
                                      const Progress& progress) {
  PsResult result;
  if (Status st = photometric_stereo_into(set, mask, options, progress, result); !st) return st.error();
  return result;
}

}  // namespace veneer::ps
