// The gloss of a material fitted from photos and normals (gloss.hpp).
#include "veneer/repaint/gloss.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

namespace veneer::repaint {

Status GlossOptions::check() const {
  if (exponents.empty()) return make_error("gloss: no exponent to try");
  for (double e : exponents)
    if (!(e >= 1 && e <= 1000)) return make_error("gloss: exponent " + std::to_string(e) + " is outside [1, 1000]");
  if (!(ridge > 0 && ridge < 1e6)) return make_error("gloss: ridge " + std::to_string(ridge) + " must be > 0");
  if (!(lit >= 0 && lit <= 0.9)) return make_error("gloss: lit " + std::to_string(lit) + " is outside [0, 0.9]");
  if (!(smoothing >= 0 && smoothing <= 16))
    return make_error("gloss: smoothing " + std::to_string(smoothing) + " px is outside [0, 16]");
  return {};
}

cv::Vec3f half_vector(const cv::Vec3d& lamp_direction) {
  const cv::Vec3d h = lamp_direction + cv::Vec3d(0, 0, 1);
  const double n = cv::norm(h);
  return n > 1e-9 ? cv::Vec3f(h / n) : cv::Vec3f(0, 0, 1);
}

float Gloss::lobe(const cv::Vec3f& n, const cv::Vec3f& l, const cv::Vec3f& half, double exponent) {
  if (n.dot(l) <= 0) return 0.f;
  const float c = n.dot(half);
  return c > 0 ? std::pow(c, static_cast<float>(exponent)) : 0.f;
}

cv::Mat masked_blur(const cv::Mat& image, const cv::Mat& mask, double sigma) {
  if (sigma <= 0) return image.clone();
  // at most three of the image's size at once (the masked image, its blur, the weight): at 5600x3750 the
  // normals' blur held six (1.1 GB), the look's peak (issue 42)
  const int ch = image.channels();
  cv::Mat weight, blurred;
  {
    cv::Mat m;
    mask.convertTo(m, CV_32F, 1.0 / 255);
    cv::GaussianBlur(m, weight, cv::Size(), sigma);
    cv::Mat masked(image.size(), image.type());
    cv::parallel_for_(cv::Range(0, image.rows), [&](const cv::Range& rows) {
      for (int y = rows.start; y < rows.end; ++y) {
        const float* p = image.ptr<float>(y);
        const float* w = m.ptr<float>(y);
        float* o = masked.ptr<float>(y);
        for (int x = 0; x < image.cols; ++x)
          for (int c = 0; c < ch; ++c) o[x * ch + c] = p[x * ch + c] * w[x];
      }
    });
    m.release();
    cv::GaussianBlur(masked, blurred, cv::Size(), sigma);
  }
  // the blur divided by the weight, in place
  cv::parallel_for_(cv::Range(0, image.rows), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      float* b = blurred.ptr<float>(y);
      const float* w = weight.ptr<float>(y);
      for (int x = 0; x < image.cols; ++x)
        for (int c = 0; c < ch; ++c) b[x * ch + c] = w[x] > 1e-6f ? b[x * ch + c] / w[x] : 0.f;
    }
  });
  return blurred;
}

bool readable_photo(const cv::Mat& photo) { return photo.type() == CV_32FC3 || photo.type() == CV_16FC3; }

PhotoRows::PhotoRows(const std::vector<cv::Mat>& photos)
    : photos_(photos), buffers_(photos.size()), rows_(photos.size(), nullptr) {}

const cv::Vec3f* const* PhotoRows::row(int y) {
  for (size_t i = 0; i < photos_.size(); ++i) {
    const cv::Mat& p = photos_[i];
    if (p.type() == CV_32FC3) {
      rows_[i] = p.ptr<cv::Vec3f>(y);
      continue;
    }
    buffers_[i].resize(static_cast<size_t>(p.cols));
    cv::Mat wide(1, p.cols, CV_32FC3, buffers_[i].data());
    p.row(y).convertTo(wide, CV_32F);
    rows_[i] = buffers_[i].data();
  }
  return rows_.data();
}

Expected<Gloss> fit_gloss(const std::vector<cv::Mat>& photos, const cv::Mat& normals, const cv::Mat& mask,
                          const std::vector<cv::Vec3d>& directions, const GlossOptions& options,
                          const Progress& progress) {
  if (auto s = options.check(); !s) return s.error();
  if (photos.size() < 3) return make_error("gloss: " + std::to_string(photos.size()) + " photos, at least 3 needed");
  if (directions.size() != photos.size())
    return make_error("gloss: " + std::to_string(directions.size()) + " lamp directions for " +
                      std::to_string(photos.size()) + " photos");
  if (normals.type() != CV_32FC3 || mask.type() != CV_8UC1 || normals.size() != mask.size())
    return make_error("gloss: the normals must be CV_32FC3 and the mask CV_8UC1 of their size");
  for (const cv::Mat& p : photos)
    if (!readable_photo(p) || p.size() != mask.size())
      return make_error("gloss: every photo must be CV_32FC3 (or CV_16FC3) of the normals' size");
  const int lamps = static_cast<int>(photos.size()), rows = mask.rows, cols = mask.cols;
  std::vector<cv::Vec3f> l(lamps), h(lamps);
  for (int i = 0; i < lamps; ++i) {
    const double n = cv::norm(directions[i]);
    if (!(n > 1e-9)) return make_error("gloss: lamp " + std::to_string(i) + "'s direction has no length");
    l[i] = cv::Vec3f(directions[i] / n);
    h[i] = half_vector(directions[i] / n);
  }
  const int alphas = static_cast<int>(options.exponents.size());
  Gloss out;
  out.albedo = cv::Mat(mask.size(), CV_32FC3, cv::Scalar::all(0));
  cv::Mat weight(mask.size(), CV_32FC1, cv::Scalar(0));
  int best = 0;
  std::vector<double> row_error(static_cast<size_t>(rows) * alphas, 0.0);
  const float lit = static_cast<float>(options.lit), ridge = static_cast<float>(options.ridge);
  progress.report(0.0, "fitting the gloss");
  // Per pixel the albedo and the residual; `pass` 0 sums each lobe's fit over
  // the object (the object-wide k0 a pixel no highlight reached is pulled to),
  // pass 1 solves k per pixel against that prior and sums the errors, pass 2
  // keeps k of the best lobe (one plane, not one per exponent).
  std::vector<double> row_num(static_cast<size_t>(rows) * alphas, 0.0), row_den(row_num.size(), 0.0);
  std::vector<float> prior(alphas, 0.f);
  // Each exponent twice the one before (the default 4..128): a lamp's lobes are one pow and squarings
  // (each within a few millionths of its own pow), not a pow each -- the fit's pow calls were most of
  // its time, 9 s of the look at 5600x3750 (issue 42)
  bool doubling = true;
  for (int a = 1; a < alphas; ++a) doubling = doubling && options.exponents[a] == 2 * options.exponents[a - 1];
  for (int pass = 0; pass < 3; ++pass) {
    cv::parallel_for_(cv::Range(0, rows), [&](const cv::Range& range) {
      std::vector<float> ratio(lamps), res(lamps), c(lamps), s(lamps), lobes(static_cast<size_t>(lamps) * alphas);
      PhotoRows rows_of(photos);
      for (int y = range.start; y < range.end; ++y) {
        if (progress.cancelled()) return;
        const uchar* m = mask.ptr<uchar>(y);
        if (cv::countNonZero(mask.row(y)) == 0) continue;
        const cv::Vec3f* const* row = rows_of.row(y);
        const auto* n = normals.ptr<cv::Vec3f>(y);
        auto* albedo = out.albedo.ptr<cv::Vec3f>(y);
        for (int x = 0; x < cols; ++x) {
          if (!m[x]) continue;
          for (int i = 0; i < lamps; ++i) c[i] = std::max(0.f, n[x].dot(l[i]));
          if (pass == 0) {
            cv::Vec3f rho(0, 0, 0);
            for (int ch = 0; ch < 3; ++ch) {
              int k = 0;
              for (int i = 0; i < lamps; ++i)
                if (c[i] > lit) ratio[k++] = row[i][x][ch] / c[i];
              if (k == 0) continue;
              std::nth_element(ratio.begin(), ratio.begin() + k / 2, ratio.begin() + k);
              float med = ratio[k / 2];
              if (k % 2 == 0) med = 0.5f * (med + *std::max_element(ratio.begin(), ratio.begin() + k / 2));
              rho[ch] = med;
            }
            albedo[x] = rho;
          }
          const cv::Vec3f rho = albedo[x];
          const float grey_rho = (rho[0] + rho[1] + rho[2]) / 3.f;
          for (int i = 0; i < lamps; ++i) {
            const cv::Vec3f& p = row[i][x];
            res[i] = (p[0] + p[1] + p[2]) / 3.f - grey_rho * c[i];
          }
          // the lobes of the exponents this pass tries, per lamp: Gloss::lobe's (n.h)^alpha where n.l > 0
          const int a_end = pass == 2 ? best + 1 : alphas;
          for (int i = 0; i < lamps; ++i) {
            float* lobe = &lobes[static_cast<size_t>(i) * alphas];
            const float ch = n[x].dot(h[i]);
            const bool lit_by = c[i] > 0 && ch > 0;  // c = max(0, n.l)
            if (!doubling) {
              for (int a = pass == 2 ? best : 0; a < a_end; ++a)
                lobe[a] = lit_by ? std::pow(ch, static_cast<float>(options.exponents[a])) : 0.f;
              continue;
            }
            float v = lit_by ? std::pow(ch, static_cast<float>(options.exponents[0])) : 0.f;
            lobe[0] = v;
            for (int a = 1; a < a_end; ++a) lobe[a] = v = v * v;
          }
          for (int a = pass == 2 ? best : 0; a < a_end; ++a) {
            float num = 0, den = 0;
            for (int i = 0; i < lamps; ++i) {
              s[i] = lobes[static_cast<size_t>(i) * alphas + a];
              num += std::max(res[i], 0.f) * s[i];
              den += s[i] * s[i];
            }
            const size_t at = static_cast<size_t>(y) * alphas + a;
            if (pass == 0) {
              row_num[at] += num, row_den[at] += den;
              continue;
            }
            const float k = std::max(0.f, (num + ridge * prior[a]) / (den + ridge));
            if (pass == 2) {
              weight.ptr<float>(y)[x] = k;
              continue;
            }
            double e = 0;
            for (int i = 0; i < lamps; ++i) e += static_cast<double>(res[i] - k * s[i]) * (res[i] - k * s[i]);
            row_error[at] += e;
          }
        }
      }
    });
    if (progress.cancelled()) break;
    if (pass == 0) {
      for (int a = 0; a < alphas; ++a) {
        double num = 0, den = 0;
        for (int y = 0; y < rows; ++y) num += row_num[static_cast<size_t>(y) * alphas + a], den += row_den[static_cast<size_t>(y) * alphas + a];
        prior[a] = den > 0 ? static_cast<float>(num / den) : 0.f;
      }
      progress.report(0.4, "fitting the gloss");
    } else if (pass == 1) {
      std::vector<double> error(alphas, 0.0);
      for (int y = 0; y < rows; ++y)
        for (int a = 0; a < alphas; ++a) error[a] += row_error[static_cast<size_t>(y) * alphas + a];
      for (int a = 1; a < alphas; ++a)
        if (error[a] < error[best]) best = a;
      const double samples = std::max(1.0, static_cast<double>(cv::countNonZero(mask)) * lamps);
      out.residual = std::sqrt(error[best] / samples);
      progress.report(0.8, "fitting the gloss");
    }
  }
  if (progress.cancelled()) return make_error("fitting the gloss cancelled");
  out.exponent = options.exponents[best];
  out.object_weight = prior[best];
  out.weight = masked_blur(weight, mask, options.smoothing);
  out.weight.setTo(0, mask == 0);
  progress.report(1.0, "fitting the gloss");
  return out;
}

}  // namespace veneer::repaint
