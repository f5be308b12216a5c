// The shaded look (look.hpp).
#include "veneer/repaint/look.hpp"

#include <algorithm>
#include <cmath>

#include <opencv2/core/utility.hpp>

#include "look_seams.hpp"

namespace veneer::repaint {

const char* look_name(Look look) { return look == Look::shaded ? "shaded" : "copy"; }

Expected<Look> parse_look(std::string_view name) {
  if (name == "shaded") return Look::shaded;
  if (name == "copy") return Look::copy;
  return make_error("look \"" + std::string(name) + "\" is not shaded or copy");
}

Status LookOptions::check() const {
  if (!(normal_smoothing >= 0 && normal_smoothing <= 64))
    return make_error("look: normal_smoothing " + std::to_string(normal_smoothing) + " px is outside [0, 64]");
  if (!(shading_floor >= 0.001 && shading_floor <= 1))
    return make_error("look: shading_floor " + std::to_string(shading_floor) + " is outside [0.001, 1]");
  if (!(max_correction >= 1 && max_correction <= 100))
    return make_error("look: max_correction " + std::to_string(max_correction) + " is outside [1, 100]");
  if (!(ratio_headroom >= 1 && ratio_headroom <= 100))
    return make_error("look: ratio_headroom " + std::to_string(ratio_headroom) + " is outside [1, 100]");
  if (!(seam_feather >= 0 && seam_feather <= 64))
    return make_error("look: seam_feather " + std::to_string(seam_feather) + " px is outside [0, 64]");
  if (seam_iterations < 1 || seam_iterations > 2000)
    return make_error("look: seam_iterations " + std::to_string(seam_iterations) + " is outside 1..2000");
  return gloss.check();
}

namespace {

Status check_side(const LookSide& side, const char* name) {
  const ObjectView& v = side.view;
  const std::string who = std::string("look: the ") + name + "'s ";
  if (v.images.empty()) return make_error(who + "photos are missing");
  if (v.mask.type() != CV_8UC1 || v.normals.type() != CV_32FC3 || v.normals.size() != v.mask.size())
    return make_error(who + "normals (CV_32FC3) and mask (CV_8UC1) do not fit each other");
  for (const cv::Mat& p : v.images)
    if (!readable_photo(p) || p.size() != v.mask.size())
      return make_error(who + "photos must be CV_32FC3 (or CV_16FC3) of the mask's size");
  if (side.lamps.size() != v.images.size())
    return make_error(who + std::to_string(side.lamps.size()) + " lamp directions for " +
                      std::to_string(v.images.size()) + " photos");
  return {};
}

// The normals averaged over a Gaussian of sigma px within the object, unit again.
cv::Mat coarse_normals(const cv::Mat& normals, const cv::Mat& mask, double sigma) {
  cv::Mat out = masked_blur(normals, mask, sigma);
  out.forEach<cv::Vec3f>([](cv::Vec3f& n, const int*) {
    const float l = static_cast<float>(cv::norm(n));
    n = l > 1e-6f ? n / l : cv::Vec3f(0, 0, 0);
  });
  return out;
}

// median over v[0..n) in place (the upper-lower mean for even n)
float median_of(float* v, int n) {
  std::nth_element(v, v + n / 2, v + n);
  float m = v[n / 2];
  if (n % 2 == 0) m = 0.5f * (m + *std::max_element(v, v + n / 2));
  return m;
}

// Per pixel: the median over the lamps of max(0, n.l) (the coarse shading).
cv::Mat median_shading(const cv::Mat& normals, const std::vector<cv::Vec3d>& lamps) {
  std::vector<cv::Vec3f> l;
  for (const cv::Vec3d& d : lamps) l.emplace_back(d / std::max(1e-9, cv::norm(d)));
  cv::Mat out(normals.size(), CV_32FC1);
  const int n = static_cast<int>(l.size());
  cv::parallel_for_(cv::Range(0, normals.rows), [&](const cv::Range& r) {
    std::vector<float> v(n);
    for (int y = r.start; y < r.end; ++y)
      for (int x = 0; x < normals.cols; ++x) {
        const cv::Vec3f nn = normals.at<cv::Vec3f>(y, x);
        for (int i = 0; i < n; ++i) v[i] = std::max(0.f, nn.dot(l[i]));
        out.at<float>(y, x) = median_of(v.data(), n);
      }
  });
  return out;
}

// Per pixel of `used` and channel (CV_32FC3), or of the grey (CV_32FC1): the
// median over the photos less k (n.h)^alpha, at least `floor`; 0 elsewhere.
// With `unoccluded` (grey only), in the same pass: the median shading as the
// pixel's albedo and normal say the lamps would give it with nothing in their
// way, a x `model_median` (the median over the lamps of max(0, n.l)); a the
// grey albedo, the median of (photo less gloss) / n.l over the lamps that face
// the pixel (n.l > 0.15) and light it (at least 0.6 of the largest such value:
// a lamp whose light another part blocks says nothing of the albedo).
cv::Mat diffuse_median(const std::vector<cv::Mat>& photos, const cv::Mat& normals, const cv::Mat& weight,
                       const std::vector<cv::Vec3d>& lamps, double exponent, float floor, bool grey,
                       const cv::Mat& used, cv::Mat* unoccluded = nullptr, const cv::Mat& model_median = {}) {
  constexpr float kFacing = 0.15f, kLit = 0.6f;
  const bool open = grey && unoccluded != nullptr;
  if (open) *unoccluded = cv::Mat(photos[0].size(), CV_32FC1, cv::Scalar(0));
  const int n = static_cast<int>(photos.size());
  std::vector<cv::Vec3f> l, h;
  for (const cv::Vec3d& d : lamps) l.emplace_back(d / std::max(1e-9, cv::norm(d))), h.push_back(half_vector(d));
  cv::Mat out(photos[0].size(), grey ? CV_32FC1 : CV_32FC3, cv::Scalar::all(0));
  cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& r) {
    std::vector<float> v(3 * n), a;
    a.reserve(n);
    PhotoRows rows_of(photos);
    for (int y = r.start; y < r.end; ++y) {
      if (cv::countNonZero(used.row(y)) == 0) continue;
      const cv::Vec3f* const* row = rows_of.row(y);
      for (int x = 0; x < out.cols; ++x) {
        if (!used.at<uchar>(y, x)) continue;
        const float k = weight.empty() ? 0.f : weight.at<float>(y, x);
        const cv::Vec3f nn = normals.at<cv::Vec3f>(y, x);
        for (int i = 0; i < n; ++i) {
          const float s = k > 0 ? k * Gloss::lobe(nn, l[i], h[i], exponent) : 0.f;
          const cv::Vec3f p = row[i][x];
          if (grey)
            v[i] = std::max((p[0] + p[1] + p[2]) / 3.f - s, floor);
          else
            for (int c = 0; c < 3; ++c) v[c * n + i] = std::max(p[c] - s, floor);
        }
        if (grey) {
          if (open) {
            a.clear();
            float top = 0;
            for (int i = 0; i < n; ++i) {
              const float nl = nn.dot(l[i]);
              if (nl <= kFacing) continue;
              a.push_back(std::max(v[i], 0.f) / nl);
              top = std::max(top, a.back());
            }
            if (!a.empty() && top > 0) {
              a.erase(std::remove_if(a.begin(), a.end(), [&](float q) { return q < kLit * top; }), a.end());
              unoccluded->at<float>(y, x) =
                  median_of(a.data(), static_cast<int>(a.size())) * model_median.at<float>(y, x);
            }
          }
          out.at<float>(y, x) = median_of(v.data(), n);
          continue;
        }
        cv::Vec3f& o = out.at<cv::Vec3f>(y, x);
        for (int c = 0; c < 3; ++c) o[c] = median_of(&v[c * n], n);
      }
    }
  });
  return out;
}

// Dd is raised only where it falls below a_d c_d by more than this factor: lamps of one direction but unequal
// brightness, and the model's own error, stay Dd's (the demo pair's still median against the truth's: 0.0291 at
// 1, 0.0287 at 1.25)
constexpr float kUnoccludedMargin = 1.25f;

constexpr float kRatioFloor = ShadedLook::ratio_floor();  // Dd and its median are kept above this (linear units)

}  // namespace

Expected<ShadedLook> ShadedLook::make(const LookSide& dst, const LookSide& src, const Map& map,
                                      const LookOptions& options, const Progress& progress) {
  if (auto s = options.check(); !s) return s.error();
  if (auto s = check_side(dst, "destination"); !s) return s.error();
  if (auto s = check_side(src, "source"); !s) return s.error();
  if (map.xy.type() != CV_32FC2 || map.xy.size() != dst.view.mask.size())
    return make_error("look: the map is " + std::to_string(map.xy.cols) + "x" + std::to_string(map.xy.rows) +
                      ", the destination " + std::to_string(dst.view.mask.cols) + "x" +
                      std::to_string(dst.view.mask.rows));
  const cv::Size dsize = dst.view.mask.size(), ssize = src.view.mask.size();
  ShadedLook look;
  look.xy_ = map.xy;
  look.normals_ = dst.view.normals;
  for (const cv::Vec3d& d : dst.lamps) {
    look.lamp_.emplace_back(d / std::max(1e-9, cv::norm(d)));
    look.half_.push_back(half_vector(d));
  }
  // the glosses
  cv::Mat source_weight;
  if (options.source_gloss) {
    auto g = fit_gloss(src.view.images, src.view.normals, src.view.mask, src.lamps, options.gloss,
                       progress.part(0.0, 0.3));
    if (!g) return make_error("look: the source's " + g.message());
    source_weight = g->weight;
    look.source_exponent_ = g->exponent;
  }
  if (options.destination_gloss) {
    auto g = fit_gloss(dst.view.images, dst.view.normals, dst.view.mask, dst.lamps, options.gloss,
                       progress.part(0.3, 0.6));
    if (!g) return make_error("look: the destination's " + g.message());
    look.destination_weight_ = g->weight;
    look.destination_exponent_ = g->exponent;
  }
  if (progress.cancelled()) return make_error("look cancelled");
  progress.report(0.6, "shading");
  // the coarse shading of each side first, while little else is held (the normals' blur was the look's
  // peak at 5600x3750, issue 42)
  const float e = static_cast<float>(options.shading_floor), top = static_cast<float>(options.max_correction);
  cv::Mat shade_d = median_shading(coarse_normals(dst.view.normals, dst.view.mask, options.normal_smoothing),
                                   dst.lamps);
  cv::Mat shade_s = median_shading(coarse_normals(src.view.normals, src.view.mask, options.normal_smoothing),
                                   src.lamps);
  // the pixels each side needs: the mapped ones and the sources they map to
  cv::Mat mapped(dsize, CV_8UC1, cv::Scalar(0)), sourced(ssize, CV_8UC1, cv::Scalar(0));
  for (int y = 0; y < dsize.height; ++y)
    for (int x = 0; x < dsize.width; ++x) {
      const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
      if (m[0] < 0) continue;
      mapped.at<uchar>(y, x) = 255;
      sourced.at<uchar>(std::clamp(static_cast<int>(std::lround(m[1])), 0, ssize.height - 1),
                        std::clamp(static_cast<int>(std::lround(m[0])), 0, ssize.width - 1)) = 255;
    }
  look.model_median_ = median_shading(dst.view.normals, dst.lamps);
  cv::Mat open;
  look.shading_median_ = diffuse_median(dst.view.images, dst.view.normals, look.destination_weight_, dst.lamps,
                                        look.destination_exponent_, 0.f, true, mapped,
                                        options.unoccluded_median ? &open : nullptr, look.model_median_);
  if (options.unoccluded_median) {
    // the raise as a factor, smoothed over 2 px: a_d from a few lamps is noisy pixel by pixel, and that noise
    // would otherwise sit on the source's texture (the demo pair's texture correlation 0.33 unsmoothed)
    cv::Mat raise(dsize, CV_32FC1, cv::Scalar(1));
    raise.forEach<float>([&](float& f, const int* at) {
      const float dd = look.shading_median_.at<float>(at[0], at[1]);
      if (dd > 0) f = std::max(1.f, open.at<float>(at[0], at[1]) / kUnoccludedMargin / dd);
    });
    look.shading_median_ = look.shading_median_.mul(masked_blur(raise, mapped, 2.0));
  }
  look.shading_median_ += kRatioFloor;
  look.headroom_ = static_cast<float>(options.ratio_headroom);
  mapped.release();
  cv::Mat source_diffuse =
      diffuse_median(src.view.images, src.view.normals, source_weight, src.lamps, look.source_exponent_, 0.f, false,
                     options.seam_feather > 0 ? src.view.mask : sourced);  // the seams read the matches' neighbours
  // T through the map (nearest source pixel)
  look.texture_ = cv::Mat(dsize, CV_32FC3, cv::Scalar::all(0));
  if (!source_weight.empty()) look.source_weight_ = cv::Mat(dsize, CV_32FC1, cv::Scalar(0));
  cv::parallel_for_(cv::Range(0, dsize.height), [&](const cv::Range& r) {
    for (int y = r.start; y < r.end; ++y)
      for (int x = 0; x < dsize.width; ++x) {
        const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
        if (m[0] < 0) continue;
        const int sx = std::clamp(static_cast<int>(std::lround(m[0])), 0, ssize.width - 1);
        const int sy = std::clamp(static_cast<int>(std::lround(m[1])), 0, ssize.height - 1);
        const float ratio =
            std::clamp((shade_d.at<float>(y, x) + e) / (shade_s.at<float>(sy, sx) + e), 1.f / top, top);
        look.texture_.at<cv::Vec3f>(y, x) = source_diffuse.at<cv::Vec3f>(sy, sx) * ratio;
        if (!source_weight.empty()) look.source_weight_.at<float>(y, x) = source_weight.at<float>(sy, sx);
      }
  });
  source_weight.release();
  if (options.seam_feather > 0) {
    // log's floor: a hundredth of the source's mean (linear units), so a dark
    // pixel's noise does not make a step of the seams' targets
    const cv::Scalar mean_diffuse = cv::mean(source_diffuse, sourced);
    const float tiny =
        std::max(1e-6f, 0.01f * static_cast<float>(mean_diffuse[0] + mean_diffuse[1] + mean_diffuse[2]) / 3.f);
    auto log_of = [tiny](const cv::Vec3f& v) {
      return cv::Vec3f(std::log(std::max(v[0], tiny)), std::log(std::max(v[1], tiny)), std::log(std::max(v[2], tiny)));
    };
    cv::Mat destination_field(dsize, CV_32FC1), source_field(ssize, CV_32FC3);
    source_field.forEach<cv::Vec3f>([&](cv::Vec3f& v, const int* at) {
      v = log_of(source_diffuse.at<cv::Vec3f>(at[0], at[1])) -
          cv::Vec3f::all(std::log(shade_s.at<float>(at[0], at[1]) + e));
    });
    destination_field.forEach<float>([&](float& v, const int* at) { v = std::log(shade_d.at<float>(at[0], at[1]) + e); });
    // what the seams do not read goes before they are solved (issue 42: at 5600x3750 the solve was
    // the look's peak)
    source_diffuse.release(), shade_d.release(), shade_s.release(), sourced.release();
    detail::SeamInputs in{tiny,          map.xy, source_field, src.view.mask, destination_field,
                          options.seam_feather, options.seam_iterations};
    if (auto solved = detail::feather_seams(in, look.texture_, look.seams_, progress.part(0.7, 1.0)); !solved)
      return make_error("look: " + solved.message());
  }
  progress.report(1.0, "shading");
  return look;
}

cv::Vec3f ShadedLook::shade(int x, int y, size_t lamp, const cv::Vec3f& d) const {
  const cv::Vec3f n = normals_.at<cv::Vec3f>(y, x);
  const float kd = destination_weight_.empty() ? 0.f : destination_weight_.at<float>(y, x);
  const float gloss_d = kd > 0 ? kd * Gloss::lobe(n, lamp_[lamp], half_[lamp], destination_exponent_) : 0.f;
  const float ks = source_weight_.empty() ? 0.f : source_weight_.at<float>(y, x);
  const float gloss_s = ks > 0 ? ks * Gloss::lobe(n, lamp_[lamp], half_[lamp], source_exponent_) : 0.f;
  // the lamp's shading as a grey ratio: the lamps are white, and a channel
  // the destination barely reflects would only add its noise
  const float shading = std::max((d[0] + d[1] + d[2]) / 3.f - gloss_d, 0.f) + kRatioFloor;
  // at most `headroom` x the Lambert model's ratio (and 2): where the median
  // lamp is in a cast shadow the measured ratio blows the lamps that do reach
  // the pixel up (inside the bull's legs 30-100x); never below 1, so the
  // median over the lamps stays T
  constexpr float e = 0.05f;
  const float model = (std::max(0.f, n.dot(lamp_[lamp])) + e) / (model_median_.at<float>(y, x) + e);
  const float ratio = std::min(shading / shading_median_.at<float>(y, x), std::max(2.f, headroom_ * model));
  return texture_.at<cv::Vec3f>(y, x) * ratio + cv::Vec3f::all(gloss_s);
}

Expected<cv::Mat> ShadedLook::paint(size_t lamp, const cv::Mat& photo) const {
  if (lamp >= lamp_.size())
    return make_error("look: lamp " + std::to_string(lamp) + " of " + std::to_string(lamp_.size()));
  if (!readable_photo(photo) || photo.size() != xy_.size())
    return make_error("look: the destination photo must be CV_32FC3 (or CV_16FC3) of the map's size");
  cv::Mat out;
  if (photo.type() == CV_32FC3) out = photo.clone();
  else photo.convertTo(out, CV_32F);
  cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& r) {
    for (int y = r.start; y < r.end; ++y)
      for (int x = 0; x < out.cols; ++x)
        if (xy_.at<cv::Vec2f>(y, x)[0] >= 0) out.at<cv::Vec3f>(y, x) = shade(x, y, lamp, out.at<cv::Vec3f>(y, x));
  });
  return out;
}

Expected<cv::Mat> ShadedLook::median(const std::vector<cv::Mat>& photos) const {
  if (photos.size() != lamp_.size())
    return make_error("look: " + std::to_string(photos.size()) + " photos for " + std::to_string(lamp_.size()) +
                      " lamps");
  for (const cv::Mat& p : photos)
    if (!readable_photo(p) || p.size() != xy_.size())
      return make_error("look: the destination photos must be CV_32FC3 (or CV_16FC3) of the map's size");
  const int n = static_cast<int>(photos.size());
  cv::Mat out(xy_.size(), CV_32FC3);
  cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& r) {
    std::vector<float> v(3 * n), a;
    a.reserve(n);
    PhotoRows rows_of(photos);
    for (int y = r.start; y < r.end; ++y) {
      const cv::Vec3f* const* row = rows_of.row(y);
      for (int x = 0; x < out.cols; ++x) {
        const bool mapped = xy_.at<cv::Vec2f>(y, x)[0] >= 0;
        for (int i = 0; i < n; ++i) {
          const cv::Vec3f d = row[i][x];
          const cv::Vec3f p = mapped ? shade(x, y, static_cast<size_t>(i), d) : d;
          for (int c = 0; c < 3; ++c) v[c * n + i] = p[c];
        }
        cv::Vec3f& o = out.at<cv::Vec3f>(y, x);
        for (int c = 0; c < 3; ++c) o[c] = median_of(&v[c * n], n);
      }
    }
  });
  return out;
}

}  // namespace veneer::repaint
