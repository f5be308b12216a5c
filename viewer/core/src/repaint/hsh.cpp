// Hemispherical harmonics: basis and per-pixel least-squares fit (hsh.hpp).
#include "veneer/repaint/hsh.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <numbers>

#include <opencv2/core/utility.hpp>

namespace veneer::repaint {

namespace {

constexpr int kMaxOrder = 3;

}  // namespace

int hsh_terms(int order) { return order * order; }

std::vector<double> hsh_basis(const cv::Vec3d& direction, int order) {
  if (order < 1 || order > kMaxOrder) return {};
  const double len = cv::norm(direction);
  const double pi = std::numbers::pi;
  const double c = len > 0 ? std::clamp(direction[2] / len, 0.0, 1.0) : 0.0;  // cos theta, at the horizon below it
  const double phi = std::atan2(direction[1], direction[0]);
  const double s = std::sqrt(std::max(0.0, c - c * c));
  std::vector<double> h(static_cast<size_t>(order * order));
  h[0] = 1 / std::sqrt(2 * pi);
  if (order >= 2) {
    h[1] = std::sqrt(6 / pi) * std::cos(phi) * s;
    h[2] = std::sqrt(3 / (2 * pi)) * (2 * c - 1);
    h[3] = std::sqrt(6 / pi) * std::sin(phi) * s;
  }
  if (order >= 3) {
    h[4] = std::sqrt(30 / pi) * std::cos(2 * phi) * (c * c - c);
    h[5] = std::sqrt(30 / pi) * std::cos(phi) * (2 * c - 1) * s;
    h[6] = std::sqrt(5 / (2 * pi)) * (6 * c * c - 6 * c + 1);
    h[7] = std::sqrt(30 / pi) * std::sin(phi) * (2 * c - 1) * s;
    h[8] = std::sqrt(30 / pi) * std::sin(2 * phi) * (c * c - c);
  }
  return h;
}

int hsh_order_for(size_t lamps, int max_order) {
  int order = 0;
  while (order < std::min(max_order, kMaxOrder) && static_cast<size_t>((order + 1) * (order + 1)) <= lamps) ++order;
  return order;
}

Expected<HshFit> fit_hsh(const std::vector<cv::Mat>& images, const std::vector<cv::Vec3d>& directions, int order) {
  if (images.empty() || directions.empty()) return make_error("HSH fit: no lamps (no photos or no lamp directions)");
  if (images.size() != directions.size())
    return make_error("HSH fit: " + std::to_string(images.size()) + " photos but " + std::to_string(directions.size()) +
                      " lamp directions");
  if (order < 1 || order > kMaxOrder)
    return make_error("HSH fit: order " + std::to_string(order) + " (1..3: 1, 4 or 9 coefficients per colour)");
  const int terms = hsh_terms(order);
  if (images.size() < static_cast<size_t>(terms))
    return make_error("HSH fit: order " + std::to_string(order) + " has " + std::to_string(terms) +
                      " coefficients per colour, " + std::to_string(images.size()) +
                      " lamps cannot determine them (order " + std::to_string(hsh_order_for(images.size())) +
                      " fits " + std::to_string(images.size()) + " lamps)");
  const cv::Size size = images[0].size();
  const int type = images[0].type();
  if (images[0].depth() != CV_32F || images[0].channels() > 4 || size.area() == 0)
    return make_error("HSH fit: the photos must be float (CV_32F), 1..4 channels, not empty");
  for (size_t i = 0; i < images.size(); ++i) {
    if (images[i].size() != size || images[i].type() != type)
      return make_error("HSH fit: photo " + std::to_string(i) + " is not of the first photo's size and type");
    const cv::Vec3d& d = directions[i];
    const double len = cv::norm(d);
    if (!std::isfinite(len) || len < 1e-9) return make_error("HSH fit: lamp " + std::to_string(i) + "'s direction is zero or not finite");
    if (!(d[2] / len > 1e-6)) return make_error("HSH fit: lamp " + std::to_string(i) + " is at or below the object's horizon (z <= 0)");
  }
  const int n = static_cast<int>(images.size());
  const int channels = images[0].channels();
  // coefficients = P * values, P the terms x n pseudo-inverse (least norm where the lamps leave terms undetermined)
  cv::Mat A(n, terms, CV_64F), P;
  std::vector<std::vector<double>> basis(static_cast<size_t>(n));
  for (int i = 0; i < n; ++i) {
    basis[static_cast<size_t>(i)] = hsh_basis(directions[static_cast<size_t>(i)], order);
    for (int k = 0; k < terms; ++k) A.at<double>(i, k) = basis[static_cast<size_t>(i)][static_cast<size_t>(k)];
  }
  cv::invert(A, P, cv::DECOMP_SVD);
  HshFit fit;
  fit.order = order;
  for (int c = 0; c < channels; ++c) fit.coefficients.emplace_back(size, CV_MAKETYPE(CV_32F, terms));
  std::vector<double> sq(static_cast<size_t>(n), 0.0);
  cv::Mutex merge;
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& rows) {
    std::vector<double> values(static_cast<size_t>(n)), coef(static_cast<size_t>(terms)), local(static_cast<size_t>(n), 0.0);
    std::vector<const float*> src(static_cast<size_t>(n));
    for (int y = rows.start; y < rows.end; ++y) {
      for (int i = 0; i < n; ++i) src[static_cast<size_t>(i)] = images[static_cast<size_t>(i)].ptr<float>(y);
      for (int c = 0; c < channels; ++c) {
        float* out = fit.coefficients[static_cast<size_t>(c)].ptr<float>(y);
        for (int x = 0; x < size.width; ++x) {
          for (int i = 0; i < n; ++i) {
            const float v = src[static_cast<size_t>(i)][x * channels + c];
            values[static_cast<size_t>(i)] = std::isfinite(v) ? v : 0.0;
          }
          for (int k = 0; k < terms; ++k) {
            const double* pk = P.ptr<double>(k);
            double s = 0;
            for (int i = 0; i < n; ++i) s += pk[i] * values[static_cast<size_t>(i)];
            coef[static_cast<size_t>(k)] = s;
            out[x * terms + k] = static_cast<float>(s);
          }
          for (int i = 0; i < n; ++i) {
            double v = 0;
            for (int k = 0; k < terms; ++k) v += static_cast<float>(coef[static_cast<size_t>(k)]) * basis[static_cast<size_t>(i)][static_cast<size_t>(k)];
            const double e = v - values[static_cast<size_t>(i)];
            local[static_cast<size_t>(i)] += e * e;
          }
        }
      }
    }
    cv::AutoLock lock(merge);
    for (int i = 0; i < n; ++i) sq[static_cast<size_t>(i)] += local[static_cast<size_t>(i)];
  });
  const double per_image = static_cast<double>(size.area()) * channels;
  double total = 0;
  for (double s : sq) {
    fit.rms_per_image.push_back(std::sqrt(s / per_image));
    total += s;
  }
  fit.rms = std::sqrt(total / (per_image * n));
  return fit;
}

cv::Mat evaluate_hsh(const HshFit& fit, const cv::Vec3d& direction) {
  if (fit.coefficients.empty()) return {};
  const int terms = hsh_terms(fit.order);
  const std::vector<double> h = hsh_basis(direction, fit.order);
  const int channels = static_cast<int>(fit.coefficients.size());
  const cv::Size size = fit.coefficients[0].size();
  cv::Mat out(size, CV_MAKETYPE(CV_32F, channels));
  for (int y = 0; y < size.height; ++y) {
    float* o = out.ptr<float>(y);
    for (int c = 0; c < channels; ++c) {
      const float* k = fit.coefficients[static_cast<size_t>(c)].ptr<float>(y);
      for (int x = 0; x < size.width; ++x) {
        double v = 0;
        for (int t = 0; t < terms; ++t) v += k[x * terms + t] * h[static_cast<size_t>(t)];
        o[x * channels + c] = static_cast<float>(v);
      }
    }
  }
  return out;
}

}  // namespace veneer::repaint
