#include "veneer/repaint/specular.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace veneer::repaint {

Status SpecularOptions::check() const {
  if (!(diffuse >= 0 && diffuse <= 2))
    return make_error("specular enhancement: diffuse " + std::to_string(diffuse) + " is outside [0, 2]");
  if (!(specular >= 0 && specular <= 2))
    return make_error("specular enhancement: specular " + std::to_string(specular) + " is outside [0, 2]");
  if (!(exponent >= 1 && exponent <= 1000))
    return make_error("specular enhancement: exponent " + std::to_string(exponent) + " is outside [1, 1000]");
  return {};
}

Expected<cv::Mat> specular_enhancement(const cv::Mat& normals, const cv::Vec3d& direction,
                                       const SpecularOptions& options) {
  if (auto ok = options.check(); !ok) return ok.error();
  if (normals.empty()) return make_error("specular enhancement: no normals");
  if (normals.type() != CV_32FC3) return make_error("specular enhancement: the normals must be CV_32FC3 (x, y, z)");
  const double length = cv::norm(direction);
  if (!(length > 1e-9) || !std::isfinite(length))
    return make_error("specular enhancement: the light direction has no length");
  const cv::Vec3f l(direction / length);
  const cv::Vec3f h = cv::normalize(l + cv::Vec3f(0, 0, 1));
  const float kd = static_cast<float>(options.diffuse), ks = static_cast<float>(options.specular),
              e = static_cast<float>(options.exponent);
  cv::Mat out(normals.size(), CV_8UC3, cv::Scalar::all(0));
  cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      const auto* n = normals.ptr<cv::Vec3f>(y);
      auto* o = out.ptr<cv::Vec3b>(y);
      for (int x = 0; x < out.cols; ++x) {
        if (n[x] == cv::Vec3f()) continue;
        const float diffuse = std::max(0.f, n[x].dot(l)), spec = std::pow(std::max(0.f, n[x].dot(h)), e);
        o[x] = cv::Vec3b::all(cv::saturate_cast<uchar>(255 * std::min(1.f, kd * diffuse + ks * spec)));
      }
    }
  });
  return out;
}

}  // namespace veneer::repaint
