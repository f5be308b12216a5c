#include "veneer/match/relight.hpp"

#include <cmath>

#include <opencv2/core.hpp>

namespace veneer::match {
namespace {

// Smallest over largest singular value of the lamps' basis matrix.
double conditioning(const cv::Mat& A) {
  cv::Mat w;
  cv::SVD::compute(A, w);
  return w.at<double>(w.rows - 1) / std::max(1e-300, w.at<double>(0));
}

}  // namespace

void Relighter::basis(Basis b, const cv::Vec3d& d, double* out) {
  const double lu = d[0], lv = d[1];
  if (b == Basis::ptm6) {
    out[0] = lu * lu;
    out[1] = lv * lv;
    out[2] = lu * lv;
    out[3] = lu;
    out[4] = lv;
    out[5] = 1.0;
  } else {
    out[0] = lu;
    out[1] = lv;
    out[2] = d[2];
    out[3] = lu * lv;
    out[4] = lu * lu - lv * lv;
  }
}

cv::Vec3d direction_on_sphere(double u, double v) {
  double r2 = u * u + v * v;
  if (r2 > 1.0) {
    const double r = std::sqrt(r2);
    u /= r;
    v /= r;
    r2 = 1.0;
  }
  return cv::Vec3d(u, v, std::sqrt(std::max(0.0, 1.0 - r2)));
}

Expected<Relighter> Relighter::fit(const ImageSet& source) {
  const int n = static_cast<int>(source.images.size());
  if (n < 5) {
    return make_error("relight: the source set '" + source.id + "' has " + std::to_string(n) +
                      " lamps; the per-pixel fit needs at least 5");
  }
  auto matrix = [&](Basis b) {
    cv::Mat A(n, terms(b), CV_64F);
    for (int i = 0; i < n; ++i) basis(b, source.lights[i].direction, A.ptr<double>(i));
    return A;
  };
  Basis chosen = Basis::ptm6;
  cv::Mat A;
  if (n >= 6 && conditioning(A = matrix(Basis::ptm6)) > 1e-4) {
    chosen = Basis::ptm6;
  } else if (conditioning(A = matrix(Basis::ring5)) > 1e-4) {
    chosen = Basis::ring5;
  } else {
    return make_error("relight: the lamp directions of '" + source.id + "' are too alike for a per-pixel fit");
  }
  cv::Mat pinv;
  cv::invert(A, pinv, cv::DECOMP_SVD);
  Relighter r;
  r.basis_ = chosen;
  r.size_ = source.size;
  std::vector<cv::Mat> photos(n);
  for (int i = 0; i < n; ++i) {
    photos[i] = source.ambient.empty() ? source.images[i] : source.images[i] - source.ambient;
    // Divide out each lamp's intensity so the fit sees unit lamps.
    const cv::Vec3f in = source.lights[i].intensity;  // r, g, b
    cv::multiply(photos[i], cv::Scalar(1.0 / std::max(1e-6f, in[2]), 1.0 / std::max(1e-6f, in[1]),
                                       1.0 / std::max(1e-6f, in[0])),
                 photos[i]);
  }
  for (int k = 0; k < terms(chosen); ++k) {
    cv::Mat c(source.size, CV_32FC3, cv::Scalar::all(0));
    for (int i = 0; i < n; ++i) cv::scaleAdd(photos[i], pinv.at<double>(k, i), c, c);
    r.coeffs_.push_back(c);
  }
  double se = 0;
  for (int i = 0; i < n; ++i) {
    cv::Mat pred = r.render_source(source.lights[i].direction);
    cv::Mat diff = pred - photos[i];
    se += cv::norm(diff, cv::NORM_L2SQR);
  }
  r.fit_rms_ = std::sqrt(se / (static_cast<double>(n) * source.size.area() * 3.0));
  return r;
}

cv::Mat Relighter::render_source(const cv::Vec3d& direction) const {
  double b[6];
  basis(basis_, direction, b);
  cv::Mat out(size_, CV_32FC3, cv::Scalar::all(0));
  for (int k = 0; k < terms(basis_); ++k) cv::scaleAdd(coeffs_[k], b[k], out, out);
  cv::max(out, cv::Scalar::all(0), out);
  return out;
}

cv::Mat Relighter::render(const Map& map, const cv::Vec3d& direction, const cv::Mat& backdrop) const {
  const cv::Mat lit = render_source(direction);
  cv::Mat out = backdrop.empty() ? cv::Mat(map.xy.size(), CV_32FC3, cv::Scalar::all(0)) : backdrop.clone();
  for (int y = 0; y < map.xy.rows; ++y) {
    const cv::Vec2f* m = map.xy.ptr<cv::Vec2f>(y);
    cv::Vec3f* o = out.ptr<cv::Vec3f>(y);
    for (int x = 0; x < map.xy.cols; ++x) {
      if (m[x][0] < 0) continue;
      const int sx = static_cast<int>(std::lround(m[x][0])), sy = static_cast<int>(std::lround(m[x][1]));
      if (sx >= 0 && sy >= 0 && sx < lit.cols && sy < lit.rows) o[x] = lit.at<cv::Vec3f>(sy, sx);
    }
  }
  return out;
}

}  // namespace veneer::match
