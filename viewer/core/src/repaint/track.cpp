#include "veneer/repaint/track.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include <opencv2/imgproc.hpp>

namespace veneer::repaint {

namespace {

// The linear grey of an 8-bit sRGB frame in one pass: each channel through
// the inverse sRGB curve, weighted as cv::cvtColor's BGR2GRAY weights them.
cv::Mat linear_gray(const cv::Mat& frame, bool srgb) {
  if (frame.depth() != CV_8U || !srgb || (frame.channels() != 1 && frame.channels() != 3)) return cv::Mat();
  static const std::array<std::array<float, 256>, 4> lut = [] {
    std::array<std::array<float, 256>, 4> t{};
    const float weight[4] = {0.114f, 0.587f, 0.299f, 1.0f};  // B, G, R, grey
    for (int i = 0; i < 256; ++i) {
      const float c = i / 255.0f;
      const float l = c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
      for (int k = 0; k < 4; ++k) t[k][i] = weight[k] * l;
    }
    return t;
  }();
  cv::Mat out(frame.size(), CV_32F);
  for (int y = 0; y < frame.rows; ++y) {
    const uint8_t* in = frame.ptr<uint8_t>(y);
    float* o = out.ptr<float>(y);
    if (frame.channels() == 1) {
      for (int x = 0; x < frame.cols; ++x) o[x] = lut[3][in[x]];
    } else {
      for (int x = 0; x < frame.cols; ++x, in += 3) o[x] = lut[0][in[0]] + lut[1][in[1]] + lut[2][in[2]];
    }
  }
  return out;
}

cv::Mat to_gray32(const cv::Mat& image) {
  cv::Mat gray = image;
  if (image.channels() == 3) cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  cv::Mat out;
  gray.convertTo(out, CV_32F, gray.depth() == CV_8U ? 1.0 / 255.0 : 1.0);
  return out;
}

// The pictures ECC compares: a slight blur (as ECC's own 3x3 Gaussian) minus
// the shading the relit template still misses, which is smooth (a difference
// of Gaussians); texture and outline stay.
cv::Mat high_pass(const cv::Mat& image, double sigma) {
  cv::Mat fine, coarse;
  cv::GaussianBlur(image, fine, cv::Size(3, 3), 0, 0, cv::BORDER_REPLICATE);
  if (sigma <= 0) return fine;
  cv::GaussianBlur(image, coarse, cv::Size(), sigma, sigma, cv::BORDER_REPLICATE);
  return fine - coarse;
}

// Bilinear sample with the border replicated (the picture at least 2x2).
inline float sample(const cv::Mat& image, float x, float y) {
  x = std::min(std::max(x, 0.0f), static_cast<float>(image.cols) - 1.001f);
  y = std::min(std::max(y, 0.0f), static_cast<float>(image.rows) - 1.001f);
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const float fx = x - static_cast<float>(x0), fy = y - static_cast<float>(y0);
  const float* r0 = image.ptr<float>(y0);
  const float* r1 = image.ptr<float>(y0 + 1);
  return (r0[x0] * (1 - fx) + r0[x0 + 1] * fx) * (1 - fy) + (r1[x0] * (1 - fx) + r1[x0 + 1] * fx) * fy;
}

cv::Matx33d to33(const cv::Matx23d& a) { return {a(0, 0), a(0, 1), a(0, 2), a(1, 0), a(1, 1), a(1, 2), 0, 0, 1}; }
cv::Matx23d to23(const cv::Matx33d& a) { return {a(0, 0), a(0, 1), a(0, 2), a(1, 0), a(1, 1), a(1, 2)}; }

// A warp between full-size pixels as one between the pixels of a level
// `factor` times smaller (level pixel i covers full pixels [i f, (i+1) f)).
cv::Matx23d to_level(const cv::Matx23d& w, int factor) {
  const double f = factor, c = (f - 1) / 2;
  const cv::Matx33d up(f, 0, c, 0, f, c, 0, 0, 1), down(1 / f, 0, -c / f, 0, 1 / f, -c / f, 0, 0, 1);
  return to23(down * to33(w) * up);
}
cv::Matx23d to_full(const cv::Matx23d& w, int factor) {
  const double f = factor, c = (f - 1) / 2;
  const cv::Matx33d up(f, 0, c, 0, f, c, 0, 0, 1), down(1 / f, 0, -c / f, 0, 1 / f, -c / f, 0, 0, 1);
  return to23(up * to33(w) * down);
}

// Gathers picture values at points: row i of the result holds `images[i]` there.
cv::Mat gather(const std::vector<cv::Mat>& images, const std::vector<cv::Point2f>& points) {
  cv::Mat out(static_cast<int>(images.size()), static_cast<int>(points.size()), CV_32F);
  for (int i = 0; i < out.rows; ++i) {
    float* o = out.ptr<float>(i);
    for (size_t j = 0; j < points.size(); ++j) o[j] = images[i].at<float>(cvRound(points[j].y), cvRound(points[j].x));
  }
  return out;
}

// sum_i w[i] rows.row(i) into `out`
void combine(const cv::Mat& rows, const std::vector<double>& w, std::vector<float>& out) {
  out.assign(static_cast<size_t>(rows.cols), 0.0f);
  for (int i = 0; i < rows.rows; ++i) {
    const float wi = static_cast<float>(w[static_cast<size_t>(i)]);
    const float* r = rows.ptr<float>(i);
    for (int j = 0; j < rows.cols; ++j) out[static_cast<size_t>(j)] += wi * r[j];
  }
}

}  // namespace

Status TrackOptions::check() const {
  if (!(min_correlation >= 0 && min_correlation <= 1)) return make_error("min_correlation: expected 0..1");
  if (!(seed_correlation >= 0 && seed_correlation <= 1)) return make_error("seed_correlation: expected 0..1");
  if (!(shadow_min_correlation >= 0 && shadow_min_correlation <= 1))
    return make_error("shadow_min_correlation: expected 0..1");
  if (iterations < 1 || iterations > 1000) return make_error("iterations: expected 1..1000");
  if (!(epsilon > 0)) return make_error("epsilon: expected > 0");
  if (margin_px < 0) return make_error("margin_px: expected >= 0");
  if (max_region_px < 16) return make_error("max_region_px: expected >= 16");
  if (search_px < 0) return make_error("search_px: expected >= 0");
  if (max_levels < 1 || max_levels > 6) return make_error("max_levels: expected 1..6");
  if (!(highpass_sigma_px >= 0 && highpass_sigma_px <= 64)) return make_error("highpass_sigma_px: expected 0..64");
  if (relight_rounds < 1 || relight_rounds > 4) return make_error("relight_rounds: expected 1..4");
  if (!(lit_fraction >= 0 && lit_fraction <= 0.5)) return make_error("lit_fraction: expected 0..0.5");
  if (lit_speck_px < 0) return make_error("lit_speck_px: expected >= 0");
  if (!(stills_lit_fraction >= 0 && stills_lit_fraction <= 1)) return make_error("stills_lit_fraction: expected 0..1");
  if (ecc_points < 64) return make_error("ecc_points: expected >= 64");
  if (relight_points < 64) return make_error("relight_points: expected >= 64");
  return {};
}

Tracker::Tracker(const std::vector<cv::Mat>& photos, const cv::Mat& mask, const TrackOptions& options)
    : options_(options) {
  if (photos.empty() || photos[0].empty() || !options_.check()) return;
  const cv::Mat& still = photos[0];
  cv::Rect box = mask.empty() ? cv::Rect() : cv::boundingRect(mask);
  if (box.area() == 0) box = cv::Rect(0, 0, still.cols, still.rows);
  box.x -= options_.margin_px;
  box.y -= options_.margin_px;
  box.width += 2 * options_.margin_px;
  box.height += 2 * options_.margin_px;
  crop_ = box & cv::Rect(0, 0, still.cols, still.rows);
  // the finest level: the object's region at most max_region_px across
  int finest = 1;
  while (std::max(crop_.width, crop_.height) / finest > options_.max_region_px) finest *= 2;
  // Sides a multiple of the coarsest factor, so that each level is exactly
  // the full-size crop reduced (an uneven resize would shift it by a pixel).
  const int coarsest = finest << (options_.max_levels - 1);
  crop_.width = std::min(still.cols - crop_.x, (crop_.width + coarsest - 1) / coarsest * coarsest) / finest * finest;
  crop_.height = std::min(still.rows - crop_.y, (crop_.height + coarsest - 1) / coarsest * coarsest) / finest * finest;
  if (crop_.width < 8 * finest || crop_.height < 8 * finest) return;
  crop_mask_ = mask.empty() ? cv::Mat(crop_.size(), CV_8U, cv::Scalar(255)) : mask(crop_).clone();
  std::vector<cv::Mat> basis_full;  // CV_32F grey crops of the photos at full size
  for (const auto& p : photos) {
    if (p.size() != still.size()) return;
    basis_full.push_back(to_gray32(p(crop_)));
  }
  cv::Mat grown_full = crop_mask_;
  if (options_.mask_dilate_px > 0)
    cv::dilate(crop_mask_, grown_full,
               cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * options_.mask_dilate_px + 1,
                                                                     2 * options_.mask_dilate_px + 1)));
  for (int level = 0, factor = finest; level < options_.max_levels; ++level, factor *= 2) {
    if (level > 0 && (crop_.width / factor < options_.coarse_min_width || crop_.width % factor || crop_.height % factor))
      break;
    const double shrink = 1.0 / factor;
    cv::Mat object, grown;
    std::vector<cv::Mat> basis, hp, gx, gy;
    if (factor == 1) object = crop_mask_, grown = grown_full;
    else {
      cv::resize(crop_mask_, object, cv::Size(), shrink, shrink, cv::INTER_NEAREST);
      cv::resize(grown_full, grown, cv::Size(), shrink, shrink, cv::INTER_NEAREST);
    }
    cv::Mat strength = cv::Mat::zeros(grown.size(), CV_32F);
    for (const auto& b : basis_full) {
      cv::Mat r = b;
      if (factor > 1) cv::resize(b, r, cv::Size(), shrink, shrink, cv::INTER_AREA);
      basis.push_back(r);
      hp.push_back(high_pass(r, std::max(2.0, options_.highpass_sigma_px / factor) * (options_.highpass_sigma_px > 0)));
      cv::Mat dx, dy;
      cv::Sobel(hp.back(), dx, CV_32F, 1, 0, 3, 1.0 / 8, 0, cv::BORDER_REPLICATE);
      cv::Sobel(hp.back(), dy, CV_32F, 0, 1, 3, 1.0 / 8, 0, cv::BORDER_REPLICATE);
      gx.push_back(dx);
      gy.push_back(dy);
      strength += cv::abs(dx) + cv::abs(dy);
    }
    // ECC's pixels: the region's strongest gradients (a picture's flat parts
    // add nothing to the normal equations but their cost)
    std::vector<std::pair<float, cv::Point2f>> candidates;
    for (int y = 1; y + 1 < grown.rows; ++y)
      for (int x = 1; x + 1 < grown.cols; ++x)
        if (grown.at<uint8_t>(y, x)) candidates.push_back({strength.at<float>(y, x), cv::Point2f(float(x), float(y))});
    const size_t keep = std::min(candidates.size(), static_cast<size_t>(options_.ecc_points));
    std::nth_element(candidates.begin(), candidates.begin() + static_cast<long>(keep), candidates.end(),
                     [](const auto& a, const auto& b) { return a.first > b.first; });
    Level l;
    l.factor = factor;
    for (size_t i = 0; i < keep; ++i) l.points.push_back(candidates[i].second);
    if (l.points.size() < 16) {
      if (level == 0) return;
      break;
    }
    l.hp = gather(hp, l.points);
    l.gx = gather(gx, l.points);
    l.gy = gather(gy, l.points);
    if (level == 0) {
      // the relight's pixels: a grid over the object; the correlation's: every pixel of the region
      const int n = cv::countNonZero(object);
      const int step = std::max(1, static_cast<int>(std::sqrt(double(n) / options_.relight_points)));
      for (int y = 0; y < object.rows; y += step)
        for (int x = 0; x < object.cols; x += step)
          if (object.at<uint8_t>(y, x)) relight_points_.emplace_back(float(x), float(y));
      relight_basis_ = gather(basis, relight_points_).t();
      for (int y = 0; y < grown.rows; ++y)
        for (int x = 0; x < grown.cols; ++x)
          if (grown.at<uint8_t>(y, x)) region_points_.emplace_back(float(x), float(y));
      region_hp_ = gather(hp, region_points_);
    }
    levels_.push_back(std::move(l));
  }
  if (options_.stills_lit_fraction > 0) {
    // where some still is lit: the brightest photo at least this share of its object's 90th percentile
    cv::Mat brightest = basis_full[0].clone();
    for (const auto& b : basis_full) cv::max(brightest, b, brightest);
    std::vector<float> v;
    for (int y = 0; y < crop_mask_.rows; ++y)
      for (int x = 0; x < crop_mask_.cols; ++x)
        if (crop_mask_.at<uint8_t>(y, x)) v.push_back(brightest.at<float>(y, x));
    if (!v.empty()) {
      auto b = v.begin() + static_cast<long>(0.9 * static_cast<double>(v.size() - 1));
      std::nth_element(v.begin(), b, v.end());
      stills_lit_ = brightest >= options_.stills_lit_fraction * double(*b);
    }
  }
  weights_.assign(photos.size() + 1, 1.0);  // the photos' sum until the first frame relights it
  weights_.back() = 0.0;
}

namespace {

// min |A x - b|^2 with x_i >= 0 for i < free_index (x[free_index] unconstrained), from the normal
// equations `ata` x = `atb` (CV_64F, m x m and m x 1): Lawson and Hanson's active set (1974).
// Empty when a system could not be solved.
std::vector<double> nonnegative_least_squares(const cv::Mat& ata, const cv::Mat& atb, int free_index) {
  const int m = ata.rows;
  std::vector<char> passive(static_cast<size_t>(m), 0);
  passive[static_cast<size_t>(free_index)] = 1;
  std::vector<double> x(static_cast<size_t>(m), 0.0);
  auto solve_passive = [&](std::vector<double>& z) {
    std::vector<int> idx;
    for (int i = 0; i < m; ++i)
      if (passive[static_cast<size_t>(i)]) idx.push_back(i);
    const int n = static_cast<int>(idx.size());
    cv::Mat a(n, n, CV_64F), b(n, 1, CV_64F), sol;
    for (int r = 0; r < n; ++r) {
      b.at<double>(r) = atb.at<double>(idx[static_cast<size_t>(r)]);
      for (int c = 0; c < n; ++c) a.at<double>(r, c) = ata.at<double>(idx[static_cast<size_t>(r)], idx[static_cast<size_t>(c)]);
    }
    if (!cv::solve(a, b, sol, cv::DECOMP_SVD)) return false;
    z.assign(static_cast<size_t>(m), 0.0);
    for (int r = 0; r < n; ++r) z[static_cast<size_t>(idx[static_cast<size_t>(r)])] = sol.at<double>(r);
    return true;
  };
  if (!solve_passive(x)) return {};
  double scale = 0;
  for (int i = 0; i < m; ++i) scale = std::max(scale, std::abs(atb.at<double>(i)));
  const double tol = 1e-10 * std::max(scale, 1e-300);
  std::vector<double> z;
  for (int outer = 0; outer < 3 * m; ++outer) {
    int best = -1;
    double best_g = tol;
    for (int j = 0; j < m; ++j) {
      if (passive[static_cast<size_t>(j)]) continue;
      double g = atb.at<double>(j);
      for (int i = 0; i < m; ++i) g -= ata.at<double>(j, i) * x[static_cast<size_t>(i)];
      if (g > best_g) best_g = g, best = j;
    }
    if (best < 0) break;
    passive[static_cast<size_t>(best)] = 1;
    for (int inner = 0; inner < 3 * m; ++inner) {
      if (!solve_passive(z)) return {};
      double alpha = 2;
      for (int i = 0; i < m; ++i)
        if (i != free_index && passive[static_cast<size_t>(i)] && z[static_cast<size_t>(i)] <= 0)
          alpha = std::min(alpha, x[static_cast<size_t>(i)] / std::max(1e-300, x[static_cast<size_t>(i)] - z[static_cast<size_t>(i)]));
      if (alpha > 1) {
        x = z;
        break;
      }
      for (int i = 0; i < m; ++i) {
        x[static_cast<size_t>(i)] += alpha * (z[static_cast<size_t>(i)] - x[static_cast<size_t>(i)]);
        if (i != free_index && x[static_cast<size_t>(i)] <= 0) passive[static_cast<size_t>(i)] = 0, x[static_cast<size_t>(i)] = 0;
      }
    }
  }
  return x;
}

}  // namespace

void Tracker::relight(const cv::Mat& frame_linear, const cv::Mat& lit, const cv::Matx23d& w, const cv::Mat& frame_hp) {
  const int k = relight_basis_.cols;
  const int n = relight_basis_.rows;
  if (n < 4 * (k + 1)) return;
  // weighted normal equations of [photos 1] x = frame, (k+1) x (k+1), on the pixels the frame lights
  cv::Mat ata = cv::Mat::zeros(k + 1, k + 1, CV_64F), atb = cv::Mat::zeros(k + 1, 1, CV_64F);
  std::vector<double> row(static_cast<size_t>(k + 1));
  double count = 0;
  for (int j = 0; j < n; ++j) {
    const cv::Point2f p = relight_points_[static_cast<size_t>(j)];
    const float x = static_cast<float>(w(0, 0) * p.x + w(0, 1) * p.y + w(0, 2));
    const float y = static_cast<float>(w(1, 0) * p.x + w(1, 1) * p.y + w(1, 2));
    const double weight = lit.empty() ? 1.0 : sample(lit, x, y);
    if (!(weight > 0)) continue;
    count += weight;
    const double v = sample(frame_linear, x, y);
    const float* a = relight_basis_.ptr<float>(j);
    for (int i = 0; i < k; ++i) row[static_cast<size_t>(i)] = a[i];
    row[static_cast<size_t>(k)] = 1.0;
    for (int r = 0; r <= k; ++r) {
      double* m = ata.ptr<double>(r);
      const double ar = weight * row[static_cast<size_t>(r)];
      for (int c = r; c <= k; ++c) m[c] += ar * row[static_cast<size_t>(c)];
      atb.at<double>(r) += ar * v;
    }
  }
  if (count < 4 * (k + 1)) return;  // too little of the object lit: the last weights stay
  for (int r = 0; r <= k; ++r)
    for (int c = 0; c < r; ++c) ata.at<double>(r, c) = ata.at<double>(c, r);
  cv::Mat x;
  if (!cv::solve(ata, atb, x, cv::DECOMP_SVD)) return;
  std::vector<double> ls(static_cast<size_t>(k + 1));
  for (int i = 0; i <= k; ++i) ls[static_cast<size_t>(i)] = x.at<double>(i);
  weights_ = ls;
  if (!options_.nonnegative_relight || frame_hp.empty()) return;
  // The mix with no photo taken negatively: where the least squares
  // subtract photos to fit a light beyond them, a glossy source's
  // highlights (which no mix places right) turn its texture over
  // (issue 47: the apple on the arc 72 deg off the axis, correlation 0.2
  // at the truth with the least squares, 0.8 without negative weights).
  // Whichever of the two matches the frame's texture and outline better.
  bool negative = false;
  for (int i = 0; i < k; ++i) negative = negative || ls[static_cast<size_t>(i)] < 0;
  if (!negative) return;
  std::vector<double> nn = nonnegative_least_squares(ata, atb, k);
  if (nn.empty()) return;
  double share = 0;
  const double rho_ls = correlation(frame_hp, lit, w, &share, 3);
  weights_ = nn;
  const double rho_nn = correlation(frame_hp, lit, w, &share, 3);
  if (!(rho_nn > rho_ls)) weights_ = ls;
}

bool Tracker::align(const Level& level, const cv::Mat& frame_hp, const cv::Mat& lit, int iterations,
                    cv::Matx23d& w) const {
  const size_t n = level.points.size();
  std::vector<float> t, gx, gy, value(n), pw(n, 1.0f);
  combine(level.hp, weights_, t);
  combine(level.gx, weights_, gx);
  combine(level.gy, weights_, gy);
  // each pixel's weight: the frame lit there, at the estimate the level starts from
  double weight_sum = 0;
  for (size_t j = 0; j < n; ++j) {
    if (!lit.empty()) {
      const float x = level.points[j].x, y = level.points[j].y;
      pw[j] = sample(lit, float(w(0, 0) * x + w(0, 1) * y + w(0, 2)), float(w(1, 0) * x + w(1, 1) * y + w(1, 2)));
    }
    weight_sum += pw[j];
  }
  if (!(weight_sum >= 16)) return false;
  double mean = 0;
  for (size_t j = 0; j < n; ++j) mean += double(pw[j]) * t[j];
  mean /= weight_sum;
  double t_norm = 0;
  for (size_t j = 0; j < n; ++j) {
    t[j] -= static_cast<float>(mean);
    t_norm += double(pw[j]) * t[j] * t[j];
  }
  t_norm = std::sqrt(t_norm);
  if (!(t_norm > 0)) return false;
  // steepest descent images of the affine warp [1+p0 p2 p4; p1 1+p3 p5] and the Hessian
  cv::Matx66d h = cv::Matx66d::zeros();
  std::vector<cv::Vec6f> sd(n);
  for (size_t j = 0; j < n; ++j) {
    const float x = level.points[j].x, y = level.points[j].y;
    sd[j] = cv::Vec6f(gx[j] * x, gy[j] * x, gx[j] * y, gy[j] * y, gx[j], gy[j]);
    for (int r = 0; r < 6; ++r)
      for (int c = r; c < 6; ++c) h(r, c) += double(pw[j]) * sd[j][r] * sd[j][c];
  }
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < r; ++c) h(r, c) = h(c, r);
  cv::Matx66d h_inv;
  if (cv::invert(h, h_inv, cv::DECOMP_CHOLESKY) == 0) return false;
  // the farthest the update can move a pixel of the level's crop
  float extent_x = 0, extent_y = 0;
  for (const auto& p : level.points) extent_x = std::max(extent_x, p.x), extent_y = std::max(extent_y, p.y);
  for (int it = 0; it < iterations; ++it) {
    const float a00 = float(w(0, 0)), a01 = float(w(0, 1)), a02 = float(w(0, 2)), a10 = float(w(1, 0)),
                a11 = float(w(1, 1)), a12 = float(w(1, 2));
    double sum = 0;
    for (size_t j = 0; j < n; ++j) {
      const float x = level.points[j].x, y = level.points[j].y;
      value[j] = sample(frame_hp, a00 * x + a01 * y + a02, a10 * x + a11 * y + a12);
      sum += double(pw[j]) * value[j];
    }
    const float m = static_cast<float>(sum / weight_sum);
    double i_norm = 0;
    for (size_t j = 0; j < n; ++j) {
      value[j] -= m;
      i_norm += double(pw[j]) * value[j] * value[j];
    }
    i_norm = std::sqrt(i_norm);
    if (!(i_norm > 0)) return false;
    const float gain = static_cast<float>(t_norm / i_norm);
    cv::Vec6d b(0, 0, 0, 0, 0, 0);
    for (size_t j = 0; j < n; ++j) {
      const double e = double(pw[j]) * (gain * value[j] - t[j]);
      for (int r = 0; r < 6; ++r) b[r] += sd[j][r] * e;
    }
    const cv::Vec6d d = h_inv * b;
    if (!std::isfinite(d[0] + d[1] + d[2] + d[3] + d[4] + d[5])) return false;
    const cv::Matx33d step(1 + d[0], d[2], d[4], d[1], 1 + d[3], d[5], 0, 0, 1);
    w = to23(to33(w) * step.inv());
    const double moved = std::max({std::hypot(d[4], d[5]), std::hypot(d[0] * extent_x + d[4], d[1] * extent_x + d[5]),
                                   std::hypot(d[2] * extent_y + d[4], d[3] * extent_y + d[5]),
                                   std::hypot(d[0] * extent_x + d[2] * extent_y + d[4],
                                              d[1] * extent_x + d[3] * extent_y + d[5])});
    if (moved < options_.epsilon) break;
  }
  return std::isfinite(w(0, 0) + w(0, 1) + w(0, 2) + w(1, 0) + w(1, 1) + w(1, 2));
}

double Tracker::correlation(const cv::Mat& frame_hp, const cv::Mat& lit, const cv::Matx23d& w,
                            double* lit_share, int stride) const {
  std::vector<float> t;
  combine(region_hp_, weights_, t);
  const size_t n = t.size();
  *lit_share = 0;
  if (n < 2) return 0;
  // over the pixels the frame lights, and (the figure before issue 47) over every pixel: the better one
  double sw = 0, st = 0, si = 0, stt = 0, sii = 0, sti = 0;
  double a_st = 0, a_si = 0, a_stt = 0, a_sii = 0, a_sti = 0;
  size_t counted = 0;
  for (size_t j = 0; j < n; j += static_cast<size_t>(std::max(1, stride))) {
    ++counted;
    const float x = region_points_[j].x, y = region_points_[j].y;
    const float fx = float(w(0, 0) * x + w(0, 1) * y + w(0, 2)), fy = float(w(1, 0) * x + w(1, 1) * y + w(1, 2));
    const double p = lit.empty() ? 1.0 : sample(lit, fx, fy);
    const double v = sample(frame_hp, fx, fy);
    a_st += t[j];
    a_si += v;
    a_stt += double(t[j]) * t[j];
    a_sii += v * v;
    a_sti += t[j] * v;
    if (!(p > 0)) continue;
    sw += p;
    st += p * t[j];
    si += p * v;
    stt += p * t[j] * t[j];
    sii += p * v * v;
    sti += p * t[j] * v;
  }
  *lit_share = sw / static_cast<double>(counted);
  auto rho = [](double s, double st, double si, double stt, double sii, double sti) {
    const double cov = sti - st * si / s, vt = stt - st * st / s, vi = sii - si * si / s;
    return s > 2 && vt > 0 && vi > 0 ? cov / std::sqrt(vt * vi) : 0.0;
  };
  return std::max(rho(sw, st, si, stt, sii, sti), rho(static_cast<double>(counted), a_st, a_si, a_stt, a_sii, a_sti));
}

TrackResult Tracker::track(const cv::Mat& frame) {
  TrackResult r;
  r.still_to_frame = last_;
  if (!ready() || frame.empty()) {
    r.lost = true;
    return r;
  }
  // The warp estimated maps the crop's pixels to the frame's:
  // W_crop = [L | L o + t] for the crop's offset o.
  const cv::Matx22d l0(last_(0, 0), last_(0, 1), last_(1, 0), last_(1, 1));
  const cv::Vec2d o(crop_.x, crop_.y);
  const cv::Vec2d t0 = l0 * o + cv::Vec2d(last_(0, 2), last_(1, 2));
  // Only the part of the frame where the object can be is read: the crop
  // carried by the last estimate, grown by the motion allowed per frame.
  // Its corner and sides are multiples of the coarsest factor, so the levels
  // reduce it exactly.
  const int coarsest = levels_.back().factor;
  cv::Rect roi;
  {
    std::vector<cv::Point2f> corners;
    for (cv::Point2d c : {cv::Point2d(0, 0), cv::Point2d(crop_.width, 0), cv::Point2d(0, crop_.height),
                          cv::Point2d(crop_.width, crop_.height)})
      corners.emplace_back(float(l0(0, 0) * c.x + l0(0, 1) * c.y + t0[0]), float(l0(1, 0) * c.x + l0(1, 1) * c.y + t0[1]));
    cv::Rect box = cv::boundingRect(corners);
    const int grow = options_.search_px + coarsest;
    int x0 = std::max(0, box.x - grow) / coarsest * coarsest, y0 = std::max(0, box.y - grow) / coarsest * coarsest;
    int x1 = std::min(frame.cols, box.x + box.width + grow), y1 = std::min(frame.rows, box.y + box.height + grow);
    roi = cv::Rect(x0, y0, std::max(0, (x1 - x0) / coarsest * coarsest), std::max(0, (y1 - y0) / coarsest * coarsest));
  }
  if (roi.width < 8 * coarsest || roi.height < 8 * coarsest) {
    r.lost = true;  // the object has left the frame
    return r;
  }
  cv::Mat gray = linear_gray(frame(roi), options_.frames_srgb);
  if (gray.empty()) gray = to_gray32(frame(roi));
  // crop -> ROI at full size
  cv::Matx23d w(l0(0, 0), l0(0, 1), t0[0] - roi.x, l0(1, 0), l0(1, 1), t0[1] - roi.y);
  std::vector<cv::Mat> frame_levels(levels_.size()), frame_hp(levels_.size());
  for (size_t i = 0; i < levels_.size(); ++i) {
    const int f = levels_[i].factor;
    if (f == 1) frame_levels[i] = gray;
    else  // an exact reduction: the sides are multiples of f
      cv::resize(gray, frame_levels[i], cv::Size(gray.cols / f, gray.rows / f), 0, 0, cv::INTER_AREA);
    frame_hp[i] = high_pass(frame_levels[i],
                            std::max(2.0, options_.highpass_sigma_px / f) * (options_.highpass_sigma_px > 0));
  }
  // Where the frame is lit (issue 47): a pixel counts when the darkest pixel
  // within the high-pass's reach is lit, so that a shadow's edge (attached
  // or cast, which no mix of the stills makes) is left out with the shadow.
  //
  // Measured (probe_track_light on lightpath.sh's sequences: 1024x680, 24
  // frames, the sources orange, stone, cup-dots, apple; lost frames / median
  // correlation / median error of the tracked frames against the truth):
  //   every pixel (before)     arc 51-72 deg: all 4 sources lose 24/24 (corr 0.40-0.72); spiral: apple 3 (at
  //                            46-48 deg, up to 1.5 px off), cup-dots 1; circle: none
  //   lit pixels (this)        arc: stone 0 (0.04 px), cup-dots 7 (where the lamp is overhead and only the
  //                            rim is bright), orange 24 (corr 0.63-0.84, yet 1.1-1.6 px off toward the lamp:
  //                            the peel's pits shade as crescents under a grazing lamp), apple 24; spiral and
  //                            circle: none lost, every source, 0.01-0.11 px median
  // With the relight per level (below) and lit_fraction 0.03: cup-dots' arc
  // 1 lost (0.42 px max), the rest as above. The correlation reported is the
  // better of the lit pixels' and every pixel's (the small orange's spiral,
  // 256x170 x2.5, at 48 deg: 0.73 lit, 0.80 every pixel; 0.93 at 0.03).
  // Tried and left out (no gain on the arc, cost per frame): the photos'
  // Lambertian part as the basis (uncalibrated photometric stereo, 3
  // pictures, highlights and shadows reweighted out): orange 0.77, apple
  // worse (0.05); the relit template clamped at 0 before the high-pass
  // (made per frame): orange 0.79, cup-dots 3 lost, apple 0.51, 2-3x the
  // time; the relight reweighted against highlights (Huber, 2 rounds):
  // cup-dots 10 lost; a threshold of 0.2 / 0.05 / 0.03 of the bright level:
  // cup-dots 12 / 8 / 3 lost (0.03: one frame 3.7 px off); the reach 1 sigma
  // rather than 2: cup-dots 9; the region eroded 4-8 px (outline left out):
  // orange still 1.1 px off.
  //
  // Issue 47 item 6 (s25-track; repaint::light_robust_track_options): the
  // same 12 sequences (probe_track_light, lost / worst error of the tracked):
  //   defaults                     arcs: all 4 sources 24/24 lost; apple spiral 3, cup-dots spiral 1
  //   lit_fraction 0.03            arcs: orange 24, apple 24 (corr 0-0.66, 9 px off from frame 12),
  //                                cup-dots 1, stone 0; spirals 0
  //   + non-negative relight       apple arc: corr 0.2 -> 0.82 at the truth (the least squares' mix
  //                                subtracts photos, and the apple's highlights turn its stripes over);
  //                                18 lost at 0.85 but within 0.5 px
  //   + stills_lit_fraction 0.25   orange arc 0 lost, corr 0.89-0.92, 0.8 px worst (the backdrop the
  //                                stills leave dark, dim beside the lit peel, no longer weighs the
  //                                outline out)
  //   + lit_speck_px 256           the viewer's small clipped orange: its dark rim (129 px, 11 % of the
  //                                object) no longer weighs half of it out (drifted 3 px before)
  //   + shadow_min_correlation 0.3 apple arc 0 lost (corr 0.61-0.85 at lit 0.49-0.56, 0.78 px worst);
  //                                every sequence 0 lost, worst 1.7 px (cup-dots arc, lamp overhead)
  // Tried and left out: the closing of the frame (grey, 1-3 px) in place of
  // the speck's area: noise in the dark half opened the shadows (cup-dots
  // arc 8-20 lost); a speck as a share of the object (0.05-0.15): cup-dots'
  // handle shadows left in (11 lost at 0.15); photometric-stereo (rank 3,
  // Cauchy-reweighted) basis: apple at the truth 0.20 (as the photos);
  // log-intensity high-pass (the mean of the photos' logs): apple 0.74-0.89
  // but the orange 0.19-0.42; a ridge toward the mean; contrast-normalised
  // high-pass: orange 0.80-0.83, apple 0.04 with the least squares.
  // A covered object (a smooth bright patch over 80 %) correlates 0.18-0.33
  // and its share lit stays high, so the bar stays near min_correlation
  // (Track.ACoveredObjectUnderASideLampIsLostAndFoundAgain); a black cover
  // is as a shadow: what stays visible is registered.
  std::vector<cv::Mat> lit(levels_.size());
  if (options_.lit_fraction > 0 && !relight_points_.empty()) {
    const cv::Matx23d w0 = to_level(w, levels_[0].factor);
    std::vector<float> values;
    values.reserve(relight_points_.size());
    for (const auto& p : relight_points_)
      values.push_back(sample(frame_levels[0], float(w0(0, 0) * p.x + w0(0, 1) * p.y + w0(0, 2)),
                              float(w0(1, 0) * p.x + w0(1, 1) * p.y + w0(1, 2))));
    const auto bright = values.begin() + static_cast<long>(0.9 * static_cast<double>(values.size() - 1));
    std::nth_element(values.begin(), bright, values.end());
    const double lo = options_.lit_fraction * std::max(1e-4, double(*bright)), hi = 2 * lo;
    // the stills' lit part carried into the frame at the estimate so far (full size, the ROI)
    cv::Mat stills_lit;
    if (!stills_lit_.empty())
      cv::warpAffine(stills_lit_, stills_lit, cv::Mat(w), gray.size(), cv::INTER_NEAREST, cv::BORDER_CONSTANT,
                     cv::Scalar(0));
    for (size_t i = 0; i < levels_.size(); ++i) {
      const int f = levels_[i].factor;
      const double sigma = std::max(2.0, options_.highpass_sigma_px / f) * (options_.highpass_sigma_px > 0);
      const int reach = std::max(1, static_cast<int>(std::ceil(2 * sigma)));
      cv::Mat level = frame_levels[i], darkest;
      if (!stills_lit.empty()) {  // darkness where no still is lit is no shadow: made bright
        cv::Mat unlit;
        if (f == 1) unlit = stills_lit == 0;
        else {
          cv::Mat small;
          cv::resize(stills_lit, small, level.size(), 0, 0, cv::INTER_AREA);
          unlit = small == 0;
        }
        level = level.clone();
        level.setTo(cv::Scalar::all(1e3), unlit);
      }
      // a dark speck (a pit of the peel, a dot, a sliver of shadow) is no
      // shadow to leave out: dark patches (below twice the threshold)
      // smaller than lit_speck_px are made bright
      const int speck = options_.lit_speck_px / (f * f);
      if (speck > 0) {
        cv::Mat dark = level < hi, labels, stats, centroids;
        const int n = cv::connectedComponentsWithStats(dark, labels, stats, centroids, 8, CV_32S);
        std::vector<uint8_t> small(static_cast<size_t>(n), 0);
        bool any = false;
        for (int c = 1; c < n; ++c)
          if (stats.at<int>(c, cv::CC_STAT_AREA) < speck) small[static_cast<size_t>(c)] = 1, any = true;
        if (any) {
          if (level.data == frame_levels[i].data) level = level.clone();
          for (int y = 0; y < level.rows; ++y) {
            const int* l = labels.ptr<int>(y);
            float* v = level.ptr<float>(y);
            for (int x = 0; x < level.cols; ++x)
              if (small[static_cast<size_t>(l[x])]) v[x] = 1e3f;
          }
        }
      }
      cv::erode(level, darkest, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * reach + 1, 2 * reach + 1)),
                cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
      darkest.convertTo(lit[i], CV_32F, 1.0 / (hi - lo), -lo / (hi - lo));
      cv::max(lit[i], 0.0, lit[i]);
      cv::min(lit[i], 1.0, lit[i]);
    }
  }
  // The template is relit before each level at the estimate so far, and
  // once more at the end for the finest level (issue 47): relit at a stale
  // estimate, its shading (a shadow's edge above all) holds ECC there. A
  // 3 px step under a lamp 72 deg to the side was not followed otherwise
  // (stone, 384x256, moving 3 px and 0.5 deg per frame: every frame lost,
  // up to 18 px off; relit per level 0.16-2.4 px; and once more 0.11-0.28 px).
  bool ok = true;
  std::vector<size_t> order;  // coarsest to finest, then the finest again
  for (int i = static_cast<int>(levels_.size()) - 1; i >= 0; --i) order.push_back(static_cast<size_t>(i));
  order.push_back(0);
  for (int round = 0; round < options_.relight_rounds && ok; ++round)
    for (size_t k = 0; k < order.size() && ok; ++k) {
      const size_t level = order[k];
      relight(frame_levels[0], lit[0], to_level(w, levels_[0].factor), frame_hp[0]);
      const int f = levels_[level].factor;
      cv::Matx23d wl = to_level(w, f);
      ok = align(levels_[level], frame_hp[level], lit[level], options_.iterations * (level > 0 ? 2 : 1), wl);
      if (ok) w = to_full(wl, f);
    }
  double lit_share = 0;
  const double rho = ok ? correlation(frame_hp[0], lit[0], to_level(w, levels_[0].factor), &lit_share) : 0.0;
  r.correlation = rho;
  r.lit = lit_share;
  if (!ok || !(rho >= options_.seed_correlation)) {
    r.lost = true;
    return r;
  }
  const cv::Matx22d l(w(0, 0), w(0, 1), w(1, 0), w(1, 1));
  const cv::Vec2d t = cv::Vec2d(w(0, 2) + roi.x, w(1, 2) + roi.y) - l * o;
  // A doubtful estimate is not shown, but it still seeds the next frame:
  // kept at the old place, the object only gets further away.
  last_ = cv::Matx23d(l(0, 0), l(0, 1), t[0], l(1, 0), l(1, 1), t[1]);
  // A lamp beyond the stills' shades what no mix of them makes (the peel's
  // pits under a grazing lamp, a glossy source's highlights): the less of
  // the object it lights, the lower the correlation it leaves at the right
  // place (issue 47's arc, 72 deg off the axis, lit 0.45-0.56 of the
  // region: orange 0.89-0.92 within 0.41 px, apple 0.61-0.85 within
  // 0.78 px). So the bar falls with the share the frame leaves dark, from
  // min_correlation (all lit) to shadow_min_correlation (all dark). A cover
  // that is lit counts as lit: an object covered 80 % by a smooth bright
  // patch correlated 0.18-0.33 at lit 0.87, under a bar of 0.78 (the note
  // above the lit map).
  const double bar = options_.min_correlation -
                     (options_.min_correlation - std::min(options_.min_correlation, options_.shadow_min_correlation)) *
                         std::clamp(1.0 - lit_share, 0.0, 1.0);
  r.lost = !(rho >= bar);
  if (!r.lost) r.still_to_frame = last_;
  return r;
}

cv::Mat alignment_picture(const cv::Mat& frame, const cv::Mat& mask, const TrackResult& result) {
  cv::Mat out = frame.clone();
  if (out.type() != CV_8UC3) return out;
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(mask.clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  const cv::Scalar colour = result.lost ? cv::Scalar(0, 0, 255) : cv::Scalar(0, 255, 0);
  const int shift = 4;  // sub-pixel drawing: coordinates in 1/16 px
  for (const auto& contour : contours) {
    std::vector<cv::Point> moved;
    for (const auto& p : contour) {
      const cv::Vec2d q = result.still_to_frame * cv::Vec3d(p.x, p.y, 1);
      moved.emplace_back(cvRound(q[0] * (1 << shift)), cvRound(q[1] * (1 << shift)));
    }
    cv::polylines(out, std::vector<std::vector<cv::Point>>{moved}, true, colour, 1, cv::LINE_AA, shift);
  }
  char text[64];
  if (!result.lost && result.correlation <= 0)  // no registration ran (--no-track)
    std::snprintf(text, sizeof text, "stills' pose, not registered");
  else
    std::snprintf(text, sizeof text, "%s  ECC %.2f", result.lost ? "LOST - hold still / recapture" : "tracked",
                  result.correlation);
  const double font = std::max(0.35, out.cols / 1400.0);
  cv::putText(out, text, {6, std::max(14, out.rows / 14)}, cv::FONT_HERSHEY_SIMPLEX, font, colour, 1, cv::LINE_AA);
  return out;
}

double motion_error_px(const cv::Matx23d& a, const cv::Matx23d& b, const cv::Mat& mask) {
  const cv::Matx23d d = a - b;
  double sum = 0;
  long n = 0;
  for (int y = 0; y < mask.rows; ++y) {
    const uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 0; x < mask.cols; ++x) {
      if (!m[x]) continue;
      const double dx = d(0, 0) * x + d(0, 1) * y + d(0, 2), dy = d(1, 0) * x + d(1, 1) * y + d(1, 2);
      sum += std::sqrt(dx * dx + dy * dy);
      ++n;
    }
  }
  return n ? sum / n : 0.0;
}

}  // namespace veneer::repaint
