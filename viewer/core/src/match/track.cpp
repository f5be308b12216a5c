#include "veneer/match/track.hpp"

#include <cmath>
#include <cstdio>

#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

namespace veneer::match {

namespace {

cv::Mat linear_gray(const cv::Mat& frame, bool srgb) {
  if (frame.depth() != CV_8U || !srgb) return cv::Mat();
  static const cv::Mat lut = [] {
    cv::Mat t(1, 256, CV_32F);
    for (int i = 0; i < 256; ++i) {
      const float c = i / 255.0f;
      t.at<float>(i) = c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
    }
    return t;
  }();
  cv::Mat linear;
  cv::LUT(frame, lut, linear);
  if (linear.channels() == 3) cv::cvtColor(linear, linear, cv::COLOR_BGR2GRAY);
  return linear;
}

cv::Mat to_gray32(const cv::Mat& image) {
  cv::Mat gray = image;
  if (image.channels() == 3) cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  cv::Mat out;
  gray.convertTo(out, CV_32F, gray.depth() == CV_8U ? 1.0 / 255.0 : 1.0);
  return out;
}

}  // namespace

Status TrackOptions::check() const {
  if (!(min_correlation >= 0 && min_correlation <= 1)) return make_error("min_correlation: expected 0..1");
  if (!(seed_correlation >= 0 && seed_correlation <= 1)) return make_error("seed_correlation: expected 0..1");
  if (iterations < 1 || iterations > 1000) return make_error("iterations: expected 1..1000");
  if (!(epsilon > 0)) return make_error("epsilon: expected > 0");
  if (margin_px < 0) return make_error("margin_px: expected >= 0");
  if (max_region_px < 16) return make_error("max_region_px: expected >= 16");
  if (search_px < 0) return make_error("search_px: expected >= 0");
  if (max_levels < 1 || max_levels > 6) return make_error("max_levels: expected 1..6");
  if (!(highpass_sigma_px >= 0 && highpass_sigma_px <= 64)) return make_error("highpass_sigma_px: expected 0..64");
  if (relight_rounds < 1 || relight_rounds > 4) return make_error("relight_rounds: expected 1..4");
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
  // the full-size crop halved (an uneven resize would shift it by a pixel).
  const int coarsest = finest << (options_.max_levels - 1);
  crop_.width = std::min(still.cols - crop_.x, (crop_.width + coarsest - 1) / coarsest * coarsest) / finest * finest;
  crop_.height = std::min(still.rows - crop_.y, (crop_.height + coarsest - 1) / coarsest * coarsest) / finest * finest;
  crop_mask_ = mask.empty() ? cv::Mat(crop_.size(), CV_8U, cv::Scalar(255)) : mask(crop_).clone();
  cv::Mat sum = cv::Mat::zeros(crop_.size(), CV_32F);
  std::vector<cv::Mat> basis_full;  // CV_32F grey crops of the photos at full size
  for (const auto& p : photos) {
    if (p.size() != still.size()) return;
    basis_full.push_back(to_gray32(p(crop_)));
    sum += basis_full.back();
  }
  for (int level = 0, factor = finest; level < options_.max_levels; ++level, factor *= 2) {
    if (level > 0 && (crop_.width / factor < options_.coarse_min_width || crop_.width % factor || crop_.height % factor))
      break;
    Level l;
    l.factor = factor;
    if (factor == 1) l.object = crop_mask_;
    else cv::resize(crop_mask_, l.object, cv::Size(), 1.0 / factor, 1.0 / factor, cv::INTER_NEAREST);
    for (const auto& b : basis_full) {
      cv::Mat r = b;
      if (factor > 1) cv::resize(b, r, cv::Size(), 1.0 / factor, 1.0 / factor, cv::INTER_AREA);
      l.basis.push_back(r);
    }
    cv::Mat grown = crop_mask_;
    if (options_.mask_dilate_px > 0)
      cv::dilate(crop_mask_, grown,
                 cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * options_.mask_dilate_px + 1,
                                                                       2 * options_.mask_dilate_px + 1)));
    if (factor == 1) l.mask = grown;
    else cv::resize(grown, l.mask, cv::Size(), 1.0 / factor, 1.0 / factor, cv::INTER_NEAREST);
    if (factor == 1) l.templ = sum;  // every lamp on until the first frame relights it
    else cv::resize(sum, l.templ, cv::Size(), 1.0 / factor, 1.0 / factor, cv::INTER_AREA);
    levels_.push_back(l);
  }
}

void Tracker::relight(const cv::Mat& frame_linear, const cv::Matx23f& w_crop) {
  // at the finest level: `frame_linear` and `w_crop` are at its scale
  const Level& fine = levels_[0];
  cv::Mat warped;
  cv::warpAffine(frame_linear, warped, cv::Mat(w_crop), fine.object.size(), cv::INTER_LINEAR | cv::WARP_INVERSE_MAP,
                 cv::BORDER_REPLICATE);
  const int k = static_cast<int>(fine.basis.size());
  const int n = cv::countNonZero(fine.object);
  if (n < 4 * (k + 1)) return;
  cv::Mat a(n, k + 1, CV_32F), b(n, 1, CV_32F);
  int row = 0;
  for (int y = 0; y < fine.object.rows; ++y) {
    const uint8_t* m = fine.object.ptr<uint8_t>(y);
    for (int x = 0; x < fine.object.cols; ++x) {
      if (!m[x]) continue;
      float* ar = a.ptr<float>(row);
      for (int i = 0; i < k; ++i) ar[i] = fine.basis[i].at<float>(y, x);
      ar[k] = 1.0f;
      b.at<float>(row) = warped.at<float>(y, x);
      ++row;
    }
  }
  cv::Mat weights;
  if (!cv::solve(a, b, weights, cv::DECOMP_SVD | cv::DECOMP_NORMAL)) return;  // 8x8 normal equations
  for (auto& level : levels_) {
    level.templ = cv::Mat(level.basis[0].size(), CV_32F, cv::Scalar(weights.at<float>(k)));
    for (int i = 0; i < k; ++i) level.templ += weights.at<float>(i) * level.basis[i];
  }
}

TrackResult Tracker::track(const cv::Mat& frame) {
  TrackResult r;
  r.still_to_frame = last_;
  if (!ready() || frame.empty()) {
    r.lost = true;
    return r;
  }
  // The warp ECC estimates maps the crop's pixels to the frame's:
  // W_crop = [L | L o + t] for the crop's offset o.
  const cv::Matx22d l0(last_(0, 0), last_(0, 1), last_(1, 0), last_(1, 1));
  const cv::Vec2d o(crop_.x, crop_.y);
  const cv::Vec2d t0 = l0 * o + cv::Vec2d(last_(0, 2), last_(1, 2));
  // Only the part of the frame where the object can be is read: the crop
  // carried by the last estimate, grown by the motion allowed per frame
  // (ECC filters and differentiates its whole input). Its corner and sides
  // are multiples of the coarsest factor, so the levels halve it exactly.
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
  cv::Matx23f w(float(l0(0, 0)), float(l0(0, 1)), float(t0[0] - roi.x), float(l0(1, 0)), float(l0(1, 1)),
                float(t0[1] - roi.y));
  double rho = 0;
  bool ok = true;
  cv::Mat frame_level;
  std::vector<cv::Mat> frame_levels(levels_.size());
  for (size_t i = 0; i < levels_.size(); ++i) {
    if (levels_[i].factor == 1) frame_levels[i] = gray;
    else {
      // an exact halving: the frame's sides cut to a multiple of the factor first
      const int f = levels_[i].factor;
      cv::resize(gray(cv::Rect(0, 0, gray.cols / f * f, gray.rows / f * f)), frame_levels[i],
                 cv::Size(gray.cols / f, gray.rows / f), 0, 0, cv::INTER_AREA);
    }
  }
  for (int round = 0; round < options_.relight_rounds && ok; ++round) {
  {
    cv::Matx23f w0 = w;
    const float k0 = static_cast<float>(levels_[0].factor);
    w0(0, 2) /= k0;
    w0(1, 2) /= k0;
    relight(frame_levels[0], w0);
  }
  for (int i = static_cast<int>(levels_.size()) - 1; i >= 0 && ok; --i) {
    const Level& level = levels_[i];
    const float k = static_cast<float>(level.factor);
    frame_level = frame_levels[i];
    cv::Mat warp(w);
    warp.at<float>(0, 2) /= k;
    warp.at<float>(1, 2) /= k;
    const int iterations = options_.iterations * (i > 0 ? 2 : 1);
    // ECC's region: the object, carried into the frame by the current estimate
    cv::Mat region;
    cv::warpAffine(level.mask, region, warp, frame_level.size(), cv::INTER_NEAREST, cv::BORDER_CONSTANT);
    try {
      cv::Mat t = level.templ, f = frame_level;
      if (options_.highpass_sigma_px > 0) {
        // the shading the relit template still misses is smooth; texture and outline are not
        cv::Mat bt, bf;
        cv::GaussianBlur(t, bt, cv::Size(), std::max(2.0, options_.highpass_sigma_px / k));
        cv::GaussianBlur(f, bf, cv::Size(), std::max(2.0, options_.highpass_sigma_px / k));
        t = t - bt;
        f = f - bf;
      }
      rho = cv::findTransformECC(t, f, warp, cv::MOTION_AFFINE,
                                 cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, iterations,
                                                  options_.epsilon),
                                 region, 3);
    } catch (const cv::Exception&) {
      ok = false;  // diverged or the region left the frame
      break;
    }
    warp.at<float>(0, 2) *= k;
    warp.at<float>(1, 2) *= k;
    w = cv::Matx23f(warp);
  }
  }
  r.correlation = ok ? rho : 0.0;
  if (!ok || !(rho >= options_.seed_correlation)) {
    r.lost = true;
    return r;
  }
  const cv::Matx22d l(w(0, 0), w(0, 1), w(1, 0), w(1, 1));
  const cv::Vec2d t = cv::Vec2d(w(0, 2) + roi.x, w(1, 2) + roi.y) - l * o;
  // A doubtful estimate is not shown, but it still seeds the next frame:
  // kept at the old place, the object only gets further away.
  last_ = cv::Matx23d(l(0, 0), l(0, 1), t[0], l(1, 0), l(1, 1), t[1]);
  r.lost = !(rho >= options_.min_correlation);
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

}  // namespace veneer::match
