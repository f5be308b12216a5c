// Photometric stereo's evaluation helpers: angular error against a truth and
// the residual picture (see photometric_stereo.hpp).
#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/ps/photometric_stereo.hpp"

namespace veneer::ps {

AngularError angular_error(const cv::Mat& normals, const cv::Mat& truth, const cv::Mat& mask) {
  AngularError e;
  if (normals.empty() || truth.empty() || normals.size() != truth.size()) return e;
  std::vector<float> deg;
  deg.reserve(size_t(normals.total()));
  for (int y = 0; y < normals.rows; ++y) {
    const cv::Vec3f* a = normals.ptr<cv::Vec3f>(y);
    const cv::Vec3f* t = truth.ptr<cv::Vec3f>(y);
    const uint8_t* m = mask.empty() ? nullptr : mask.ptr<uint8_t>(y);
    for (int x = 0; x < normals.cols; ++x) {
      if (m && !m[x]) continue;
      const float la = std::sqrt(a[x].dot(a[x])), lt = std::sqrt(t[x].dot(t[x]));
      if (la < 1e-6f || lt < 1e-6f) continue;
      const double c = std::clamp(double(a[x].dot(t[x])) / (double(la) * lt), -1.0, 1.0);
      deg.push_back(static_cast<float>(std::acos(c) * 180.0 / CV_PI));
    }
  }
  e.pixels = static_cast<int>(deg.size());
  if (deg.empty()) return e;
  double sum = 0;
  for (float d : deg) sum += d;
  e.mean_deg = sum / deg.size();
  auto nth = [&](double q) {
    size_t k = std::min(deg.size() - 1, static_cast<size_t>(q * (deg.size() - 1) + 0.5));
    std::nth_element(deg.begin(), deg.begin() + k, deg.end());
    return double(deg[k]);
  };
  e.median_deg = nth(0.5);
  e.p95_deg = nth(0.95);
  e.max_deg = *std::max_element(deg.begin(), deg.end());
  return e;
}

cv::Mat residual_picture(const PsResult& result, float full_scale) {
  cv::Mat out(result.residual.size(), CV_8UC3, cv::Scalar::all(0));
  const float sc = full_scale > 0 ? 255.f / full_scale : 255.f;
  for (int y = 0; y < out.rows; ++y) {
    const float* r = result.residual.ptr<float>(y);
    const uint8_t* m = result.mask.ptr<uint8_t>(y);
    const uint8_t* ok = result.reliable.ptr<uint8_t>(y);
    cv::Vec3b* o = out.ptr<cv::Vec3b>(y);
    for (int x = 0; x < out.cols; ++x) {
      if (!m[x]) continue;
      if (!ok[x]) {
        o[x] = cv::Vec3b(0, 0, 255);
        continue;
      }
      const uint8_t v = static_cast<uint8_t>(std::clamp(r[x] * sc, 0.f, 255.f));
      o[x] = cv::Vec3b(v, v, v);
    }
  }
  return out;
}

}  // namespace veneer::ps
