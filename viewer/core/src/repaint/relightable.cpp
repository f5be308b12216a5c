// The relightable model (relightable.hpp).
#include "veneer/repaint/relightable.hpp"

#include "veneer/repaint/hsh.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include <opencv2/core/utility.hpp>

namespace veneer::repaint {

const char* relight_basis_name(RelightBasis basis) { return basis == RelightBasis::hsh ? "hsh" : "ptm"; }

Expected<RelightBasis> parse_relight_basis(std::string_view name) {
  if (name == "hsh") return RelightBasis::hsh;
  if (name == "ptm") return RelightBasis::ptm;
  return make_error("relightable basis \"" + std::string(name) + "\" is not hsh or ptm");
}

Status RelightableOptions::check() const {
  if (order < 1 || order > 3) return make_error("relightable: HSH order " + std::to_string(order) + " is outside 1..3");
  if (!(ridge >= 0 && ridge <= 10))
    return make_error("relightable: ridge " + std::to_string(ridge) + " is outside [0, 10]");
  if (!(residual_deg >= 0 && residual_deg <= 90))
    return make_error("relightable: residual_deg " + std::to_string(residual_deg) + " is outside [0, 90]");
  return {};
}

void ptm_basis(const cv::Vec3d& direction, float* out) {
  const cv::Vec3d l = direction / std::max(1e-12, cv::norm(direction));
  const float u = static_cast<float>(l[0]), v = static_cast<float>(l[1]);
  out[0] = u * u, out[1] = v * v, out[2] = u * v, out[3] = u, out[4] = v, out[5] = 1.f;
}

namespace {

// The basis' values at `l` into `out` (basis_terms values): HSH through hsh.hpp (one
// implementation with the .rti export), in float as the coefficients are.
void basis_at(const RelightableOptions& options, const cv::Vec3d& l, float* out) {
  if (options.basis == RelightBasis::ptm) {
    ptm_basis(l, out);
    return;
  }
  const std::vector<double> h = hsh_basis(l, options.order);
  std::transform(h.begin(), h.end(), out, [](double v) { return static_cast<float>(v); });
}

// grey of a CV_32FC3 or CV_32FC1 pixel row value
inline float grey_at(const cv::Mat& m, int y, int x) {
  if (m.type() == CV_32FC1) return m.at<float>(y, x);
  const cv::Vec3f v = m.at<cv::Vec3f>(y, x);
  return (v[0] + v[1] + v[2]) / 3.f;
}

Status check_photos(const std::vector<cv::Mat>& photos, const cv::Mat& mask) {
  if (photos.empty()) return make_error("relightable: no photos");
  if (mask.type() != CV_8UC1) return make_error("relightable: the mask must be CV_8UC1");
  for (const cv::Mat& p : photos)
    if ((p.type() != CV_32FC3 && p.type() != CV_32FC1) || p.size() != mask.size())
      return make_error("relightable: photos must be CV_32FC3 or CV_32FC1 of the mask's size (" +
                        std::to_string(mask.cols) + "x" + std::to_string(mask.rows) + ")");
  return {};
}

double angle_between(const cv::Vec3d& a, const cv::Vec3d& b) {
  return std::acos(std::clamp(a.dot(b) / std::max(1e-12, cv::norm(a) * cv::norm(b)), -1.0, 1.0));
}

}  // namespace

Expected<cv::Mat> fit_coefficients(const std::vector<cv::Mat>& photos, const cv::Mat& mask, const cv::Mat& basis,
                                   double ridge, const Progress& progress) {
  if (auto s = check_photos(photos, mask); !s) return s.error();
  const int lamps = static_cast<int>(photos.size());
  if (basis.type() != CV_32FC1 || basis.rows != lamps || basis.cols < 1 || basis.cols > 64)
    return make_error("relightable: the basis must be CV_32FC1, one row per photo (" + std::to_string(lamps) +
                      "), 1..64 terms");
  if (!(ridge >= 0)) return make_error("relightable: the ridge must be >= 0");
  const int terms = basis.cols;
  cv::Mat B;
  basis.convertTo(B, CV_64F);
  cv::Mat A = B.t() * B;
  const double mean_diagonal = cv::trace(A)[0] / terms;
  A += cv::Mat::eye(terms, terms, CV_64F) * (ridge * mean_diagonal);
  cv::Mat P;  // terms x lamps: c = P I
  if (cv::invert(A, P, cv::DECOMP_SVD) == 0 || (ridge == 0 && lamps < terms))
    return make_error("relightable: " + std::to_string(lamps) + " lamps do not determine " + std::to_string(terms) +
                      " terms (give a ridge)");
  P = P * B.t();
  cv::Mat Pf;
  P.convertTo(Pf, CV_32F);
  cv::Mat out(mask.size(), CV_32FC(terms), cv::Scalar::all(0));
  if (progress.cancelled()) return make_error("relightable: cancelled");
  cv::parallel_for_(cv::Range(0, mask.rows), [&](const cv::Range& r) {
    std::vector<float> v(lamps);
    for (int y = r.start; y < r.end; ++y) {
      float* o = out.ptr<float>(y);
      for (int x = 0; x < mask.cols; ++x) {
        if (!mask.at<uchar>(y, x)) continue;
        for (int i = 0; i < lamps; ++i) v[i] = grey_at(photos[i], y, x);
        for (int k = 0; k < terms; ++k) {
          const float* pk = Pf.ptr<float>(k);
          float c = 0;
          for (int i = 0; i < lamps; ++i) c += pk[i] * v[i];
          o[x * terms + k] = c;
        }
      }
    }
  });
  progress.report(1.0, "relightable fit");
  return out;
}

Expected<RelightableModel> RelightableModel::fit(const std::vector<cv::Mat>& photos, const cv::Mat& mask,
                                                 const std::vector<cv::Vec3d>& directions,
                                                 const RelightableOptions& options, const Progress& progress) {
  if (auto s = options.check(); !s) return s.error();
  if (auto s = check_photos(photos, mask); !s) return s.error();
  if (directions.size() != photos.size())
    return make_error("relightable: " + std::to_string(directions.size()) + " lamp directions for " +
                      std::to_string(photos.size()) + " photos");
  RelightableModel model;
  model.options_ = options;
  model.lamps_ = directions;
  const int lamps = static_cast<int>(photos.size());
  const int terms = options.basis == RelightBasis::hsh ? options.order * options.order : 6;
  model.basis_terms_ = terms;
  cv::Mat basis(lamps, terms, CV_32FC1);
  for (int i = 0; i < lamps; ++i) basis_at(options, directions[i], basis.ptr<float>(i));
  auto c = fit_coefficients(photos, mask, basis, options.ridge, progress.part(0.0, 0.8));
  if (!c) return c.error();
  model.terms_ = terms;
  if (options.residual_deg <= 0) {
    model.coefficients_ = std::move(*c);
    return model;
  }
  // the residual at each captured lamp, and the radial basis that interpolates it
  const double sigma = options.residual_deg * CV_PI / 180.0;
  cv::Mat K(lamps, lamps, CV_64FC1);
  for (int i = 0; i < lamps; ++i)
    for (int j = 0; j < lamps; ++j) {
      const double a = angle_between(directions[i], directions[j]) / sigma;
      K.at<double>(i, j) = std::exp(-0.5 * a * a);
    }
  K += cv::Mat::eye(lamps, lamps, CV_64F) * 1e-3;  // a captured lamp twice over stays solvable
  cv::invert(K, model.kernel_inverse_, cv::DECOMP_SVD);
  const int all = terms + lamps;
  model.terms_ = all;
  model.coefficients_ = cv::Mat(mask.size(), CV_32FC(all), cv::Scalar::all(0));
  cv::parallel_for_(cv::Range(0, mask.rows), [&](const cv::Range& r) {
    for (int y = r.start; y < r.end; ++y) {
      const float* ci = c->ptr<float>(y);
      float* o = model.coefficients_.ptr<float>(y);
      for (int x = 0; x < mask.cols; ++x) {
        if (!mask.at<uchar>(y, x)) continue;
        const float* cc = ci + x * terms;
        float* oo = o + x * all;
        std::copy(cc, cc + terms, oo);
        for (int i = 0; i < lamps; ++i) {
          const float* b = basis.ptr<float>(i);
          float fit = 0;
          for (int k = 0; k < terms; ++k) fit += b[k] * cc[k];
          oo[terms + i] = grey_at(photos[i], y, x) - fit;
        }
      }
    }
  });
  if (progress.cancelled()) return make_error("relightable: cancelled");
  progress.report(1.0, "relightable fit");
  return model;
}

std::vector<float> RelightableModel::weights(const cv::Vec3d& l) const {
  std::vector<float> w(terms(), 0.f);
  basis_at(options_, l, w.data());
  if (kernel_inverse_.empty()) return w;
  const int lamps = static_cast<int>(lamps_.size());
  const double sigma = options_.residual_deg * CV_PI / 180.0;
  cv::Mat k(lamps, 1, CV_64FC1);
  for (int i = 0; i < lamps; ++i) {
    const double a = angle_between(l, lamps_[i]) / sigma;
    k.at<double>(i) = std::exp(-0.5 * a * a);
  }
  const cv::Mat wi = kernel_inverse_ * k;
  for (int i = 0; i < lamps; ++i) w[basis_terms_ + i] = static_cast<float>(wi.at<double>(i));
  return w;
}

cv::Mat RelightableModel::evaluate(const cv::Vec3d& l) const {
  const std::vector<float> w = weights(l);
  const int n = terms();
  cv::Mat out(coefficients_.size(), CV_32FC1, cv::Scalar(0));
  if (coefficients_.empty()) return out;
  cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& r) {
    for (int y = r.start; y < r.end; ++y) {
      const float* c = coefficients_.ptr<float>(y);
      float* o = out.ptr<float>(y);
      for (int x = 0; x < out.cols; ++x) {
        float s = 0;
        for (int k = 0; k < n; ++k) s += c[x * n + k] * w[k];
        o[x] = std::max(s, 0.f);
      }
    }
  });
  return out;
}

}  // namespace veneer::repaint
