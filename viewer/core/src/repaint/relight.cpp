#include "veneer/repaint/relight.hpp"

#include <algorithm>
#include <cmath>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/match/object.hpp"
#include "veneer/repaint/repaint.hpp"

namespace veneer::repaint {
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

Expected<Relighter> Relighter::fit(const io::ImageSet& source) {
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
  Relighter r;
  r.basis_ = chosen;
  for (int i = 0; i < n; ++i)
    r.reach_ = std::max(r.reach_, std::hypot(source.lights[i].direction[0], source.lights[i].direction[1]));
  r.size_ = source.size;
  const int k = terms(chosen);
  std::vector<cv::Mat> photos(n);
  for (int i = 0; i < n; ++i) {
    const cv::Mat lit = source.ambient.empty() ? source.images[i] : cv::Mat(source.images[i] - source.ambient);
    // Divide out each lamp's intensity so the fit sees unit lamps (into a
    // buffer of its own: `lit` may be the caller's photo).
    const cv::Vec3f in = source.lights[i].intensity;  // r, g, b
    cv::multiply(lit, cv::Scalar(1.0 / std::max(1e-6f, in[2]), 1.0 / std::max(1e-6f, in[1]), 1.0 / std::max(1e-6f, in[0])),
                 photos[i]);
  }
  // Only the object is relit: its background (the table, whose look at a new
  // light depends on the object's cast shadow, which no per-pixel model
  // knows) is left as captured, the photos' per-pixel median.
  r.captured_ = median_photo(photos);
  auto object = match::object_mask(source, !source.truth.mask.empty());  // the truth's where simulated
  r.object_ = object && !object->empty() ? *object : cv::Mat(source.size, CV_8U, cv::Scalar(255));
  if (r.object_.size() != source.size) cv::resize(r.object_, r.object_, source.size, 0, 0, cv::INTER_NEAREST);
  // Per pixel, a least-squares fit over the lamps that light it. A sample in
  // shadow (attached or cast: below shadow_fraction of the pixel's brightest)
  // does not follow a smooth model; fitted anyway, the shadows of
  // the other lamps come back as displaced ghost copies (rings about the
  // object) and the fit swings below zero (black speckle at the terminator).
  // A ridge keeps poorly determined terms from amplifying the noise: next to
  // none on the Lambertian terms, some on the second-order ones, so a pixel
  // with a lamp or two in shadow gets a Lambertian-like fit instead of a wild
  // quadratic. A pixel lit by fewer than 4 lamps is left as captured.
  // Measured (core/Relight.NoGhostRings..., orange x2.5, a lamp between ring
  // lamps / one beyond the ring): 0.02 and 1e-2 gave 39.4 / 38.0 / 29.3 dB on
  // the object (the plain fit: 40.0 / 39.8 / 28.0 dB); 0.15 cost 4 dB.
  const double shadow_fraction = 0.02;
  std::vector<int> lambert;  // the basis's Lambertian terms
  if (chosen == Basis::ptm6) lambert = {3, 4, 5};
  else lambert = {0, 1, 2};
  for (int t = 0; t < k; ++t) r.coeffs_.push_back(cv::Mat(source.size, CV_32FC3, cv::Scalar::all(0)));
  r.fitted_ = cv::Mat(source.size, CV_8U, cv::Scalar(0));
  std::vector<double> basis_rows(static_cast<size_t>(n) * k);
  for (int i = 0; i < n; ++i) basis(chosen, source.lights[i].direction, &basis_rows[static_cast<size_t>(i) * k]);
  cv::parallel_for_(cv::Range(0, source.size.height), [&](const cv::Range& rows) {
    std::vector<double> grey(static_cast<size_t>(n));
    for (int y = rows.start; y < rows.end; ++y) {
      const uint8_t* obj = r.object_.ptr<uint8_t>(y);
      uint8_t* fitted = r.fitted_.ptr<uint8_t>(y);
      for (int x = 0; x < source.size.width; ++x) {
        if (!obj[x]) continue;
        double brightest = 0;
        for (int i = 0; i < n; ++i) {
          const cv::Vec3f v = photos[i].at<cv::Vec3f>(y, x);
          grey[static_cast<size_t>(i)] = (v[0] + v[1] + v[2]) / 3.0;
          brightest = std::max(brightest, grey[static_cast<size_t>(i)]);
        }
        if (!(brightest > 0)) continue;
        int lit = 0;
        for (int i = 0; i < n; ++i) lit += grey[static_cast<size_t>(i)] > shadow_fraction * brightest;
        if (lit < 4) continue;  // left as captured
        std::vector<int> use;
        for (int t = 0; t < k; ++t) use.push_back(t);
        const int m = static_cast<int>(use.size());
        cv::Matx66d ata = cv::Matx66d::zeros();
        cv::Matx<double, 6, 3> atb = cv::Matx<double, 6, 3>::zeros();
        for (int i = 0; i < n; ++i) {
          if (!(grey[static_cast<size_t>(i)] > shadow_fraction * brightest)) continue;
          const double* b = &basis_rows[static_cast<size_t>(i) * k];
          const cv::Vec3f v = photos[i].at<cv::Vec3f>(y, x);
          for (int p = 0; p < m; ++p) {
            for (int q = 0; q < m; ++q) ata(p, q) += b[use[p]] * b[use[q]];
            for (int c = 0; c < 3; ++c) atb(p, c) += b[use[p]] * v[c];
          }
        }
        double trace = 0;
        for (int p = 0; p < m; ++p) trace += ata(p, p);
        // the Lambertian terms barely held, the others (highlights' shape) held
        // towards 0 where the lit lamps do not pin them down
        for (int p = 0; p < m; ++p)
          ata(p, p) += (std::find(lambert.begin(), lambert.end(), use[p]) != lambert.end() ? 1e-6 : 1e-2) * trace / m;
        for (int p = m; p < 6; ++p) ata(p, p) = 1;  // unused terms: identity, zero right side
        cv::Matx<double, 6, 3> coef;
        if (!cv::solve(ata, atb, coef, cv::DECOMP_CHOLESKY)) continue;
        for (int p = 0; p < m; ++p)
          r.coeffs_[static_cast<size_t>(use[p])].at<cv::Vec3f>(y, x) =
              cv::Vec3f(float(coef(p, 0)), float(coef(p, 1)), float(coef(p, 2)));
        fitted[x] = 255;
      }
    }
  });
  // the fit's error over the relit pixels, lit samples only (what it models)
  double se = 0;
  long count = 0;
  for (int i = 0; i < n; ++i) {
    cv::Mat pred = r.relit(source.lights[i].direction);
    for (int y = 0; y < source.size.height; ++y)
      for (int x = 0; x < source.size.width; ++x) {
        if (!r.fitted_.at<uint8_t>(y, x)) continue;
        const cv::Vec3f d = pred.at<cv::Vec3f>(y, x) - photos[i].at<cv::Vec3f>(y, x);
        se += d.dot(d);
        count += 3;
      }
  }
  r.fit_rms_ = count ? std::sqrt(se / static_cast<double>(count)) : 0.0;
  return r;
}

cv::Mat Relighter::relit(const cv::Vec3d& direction) const {
  double b[6];
  basis(basis_, direction, b);
  {
    // Second-order terms at the direction brought within the lamps' reach:
    // beyond it they were extrapolated from nothing and swung (speckle); the
    // Lambertian terms follow the light all the way.
    cv::Vec3d d = direction;
    const double r = std::hypot(d[0], d[1]);
    if (r > reach_ && r > 0) {
      d[0] *= reach_ / r;
      d[1] *= reach_ / r;
      d[2] = std::sqrt(std::max(0.0, 1 - reach_ * reach_));
    }
    double q[6];
    basis(basis_, d, q);
    if (basis_ == Basis::ring5) { b[3] = q[3]; b[4] = q[4]; }
    else { b[0] = q[0]; b[1] = q[1]; b[2] = q[2]; }
  }
  cv::Mat out(size_, CV_32FC3, cv::Scalar::all(0));
  for (int k = 0; k < terms(basis_); ++k) cv::scaleAdd(coeffs_[k], b[k], out, out);
  cv::max(out, cv::Scalar::all(0), out);  // beyond the terminator: shadow, not negative light
  return out;
}

cv::Mat Relighter::render_source(const cv::Vec3d& direction) const {
  cv::Mat out = captured_.clone();
  relit(direction).copyTo(out, fitted_);
  return out;
}

cv::Mat Relighter::render(const Map& map, const cv::Vec3d& direction, const cv::Mat& backdrop) const {
  const cv::Mat lit = render_source(direction);
  cv::Mat out = backdrop.empty() ? cv::Mat(map.xy.size(), CV_32FC3, cv::Scalar::all(0)) : backdrop.clone();
  if (out.size() != map.xy.size()) cv::resize(out, out, map.xy.size(), 0, 0, cv::INTER_AREA);
  // bilinear at the map's sub-pixel positions (nearest steps between neighbours' source pixels)
  cv::Mat table(map.xy.size(), CV_32FC2);
  for (int y = 0; y < map.xy.rows; ++y) {
    const cv::Vec2f* m = map.xy.ptr<cv::Vec2f>(y);
    cv::Vec2f* t = table.ptr<cv::Vec2f>(y);
    for (int x = 0; x < map.xy.cols; ++x) t[x] = m[x][0] < 0 ? cv::Vec2f(-1e6f, -1e6f) : m[x];
  }
  cv::remap(lit, out, table, cv::noArray(), cv::INTER_LINEAR, cv::BORDER_TRANSPARENT);
  return out;
}

}  // namespace veneer::repaint
