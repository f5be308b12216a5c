// The shaded look's seam feathering: a screened Poisson solve of log T by
// Jacobi-preconditioned conjugate gradients (look_seams.hpp).
#include "look_seams.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include <opencv2/core/utility.hpp>

namespace veneer::repaint::detail {
namespace {

// Dot product over a vector, in parallel chunks summed in a fixed order.
double dot(const std::vector<float>& a, const std::vector<float>& b) {
  const int n = static_cast<int>(a.size()), parts = 16;
  std::array<double, 16> part{};
  cv::parallel_for_(cv::Range(0, parts), [&](const cv::Range& r) {
    for (int k = r.start; k < r.end; ++k) {
      double s = 0;
      for (int i = n * k / parts; i < n * (k + 1) / parts; ++i) s += static_cast<double>(a[i]) * b[i];
      part[k] = s;
    }
  });
  double s = 0;
  for (double v : part) s += v;
  return s;
}

}  // namespace

Status feather_seams(const SeamInputs& in, cv::Mat& texture, std::size_t& seams, const Progress& progress) {
  seams = 0;
  const cv::Mat& xy = in.xy;
  const int rows = xy.rows, cols = xy.cols;
  // the unknowns: mapped pixels, numbered row by row
  cv::Mat index(xy.size(), CV_32SC1, cv::Scalar(-1));
  std::vector<cv::Point> pixel;
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x)
      if (xy.at<cv::Vec2f>(y, x)[0] >= 0) {
        index.at<int>(y, x) = static_cast<int>(pixel.size());
        pixel.emplace_back(x, y);
      }
  const int n = static_cast<int>(pixel.size());
  if (n == 0) return Status::success();
  // per unknown: its neighbours right, down, left, up (-1 none) and u0 = log T
  std::vector<std::array<int, 4>> nb(n);
  std::vector<cv::Vec3f> u0(n);
  const float floor = in.log_floor;
  cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) {
      const cv::Point p = pixel[i];
      const cv::Point step[4] = {{1, 0}, {0, 1}, {-1, 0}, {0, -1}};
      for (int k = 0; k < 4; ++k) {
        const cv::Point q = p + step[k];
        nb[i][k] = (q.x >= 0 && q.y >= 0 && q.x < cols && q.y < rows) ? index.at<int>(q) : -1;
      }
      const cv::Vec3f t = texture.at<cv::Vec3f>(p);
      for (int c = 0; c < 3; ++c) u0[i][c] = std::log(std::max(t[c], floor));
    }
  });
  index.release();
  const cv::Size ssize = in.source_field.size();
  auto source_at = [&](cv::Point s, cv::Vec3f& v) {
    if (s.x < 0 || s.y < 0 || s.x >= ssize.width || s.y >= ssize.height || !in.source_mask.at<uchar>(s)) return false;
    v = in.source_field.at<cv::Vec3f>(s);
    return true;
  };
  auto rounded = [&](cv::Point p) {
    const cv::Vec2f m = xy.at<cv::Vec2f>(p);
    return cv::Point(static_cast<int>(std::lround(m[0])), static_cast<int>(std::lround(m[1])));
  };
  // the target g from unknown i toward its neighbour j = nb[i][k], k = 0 (right) or 1 (down); `seam`
  // says whether the matches do not continue each other there
  auto target = [&](int i, int k, int j, bool& seam) {
    const cv::Point e = k == 0 ? cv::Point(1, 0) : cv::Point(0, 1), p = pixel[i], q = pixel[j];
    const cv::Vec2f mp = xy.at<cv::Vec2f>(p), mq = xy.at<cv::Vec2f>(q);
    seam = !(std::abs(mq[0] - mp[0] - e.x) <= 1.f && std::abs(mq[1] - mp[1] - e.y) <= 1.f);
    if (!seam) return cv::Vec3f(u0[j] - u0[i]);
    // the source's step at each side's match, continued; the destination's own
    const cv::Point sp = rounded(p), sq = rounded(q);
    cv::Vec3f a0, a1, b0, b1, sum(0, 0, 0);
    int count = 0;
    if (source_at(sp, a0) && source_at(sp + e, a1)) sum += a1 - a0, ++count;
    if (source_at(sq - e, b0) && source_at(sq, b1)) sum += b1 - b0, ++count;
    if (count > 0) sum *= 1.f / count;
    const float w = in.destination_field.at<float>(q) - in.destination_field.at<float>(p);
    return cv::Vec3f(sum + cv::Vec3f::all(w));
  };
  // b_p = sum over neighbours q of (u0_q - u0_p - g_pq), per channel: nonzero only at seams (a target
  // toward the left or up is the one that neighbour has toward p, negated)
  std::vector<cv::Vec3f> b3(n);
  std::vector<unsigned char> seam_right(n, 0), seam_down(n, 0);
  cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) {
      cv::Vec3f g[4];
      for (int k = 0; k < 4; ++k) {
        const int j = nb[i][k];
        if (j < 0) continue;
        bool seam = false;
        if (k < 2) {
          g[k] = target(i, k, j, seam);
          (k == 0 ? seam_right : seam_down)[i] = seam;
        } else {
          g[k] = -target(j, k - 2, i, seam);
        }
      }
      for (int c = 0; c < 3; ++c) {
        const float u = u0[i][c];
        float s = 0;
        for (int k = 0; k < 4; ++k) {
          const int j = nb[i][k];
          if (j < 0) continue;
          s += u0[j][c] - u - g[k][c];
        }
        b3[i][c] = s;
      }
    }
  });
  for (int i = 0; i < n; ++i) seams += seam_right[i] + seam_down[i];
  if (seams == 0) return Status::success();
  std::vector<cv::Vec3f>().swap(u0);  // what the solve does not read goes before it
  std::vector<unsigned char>().swap(seam_right);
  std::vector<unsigned char>().swap(seam_down);
  const float lambda = static_cast<float>(1.0 / (in.feather * in.feather));
  std::vector<float> diag(n);
  for (int i = 0; i < n; ++i) {
    int deg = 0;
    for (int k = 0; k < 4; ++k) deg += nb[i][k] >= 0;
    diag[i] = lambda + static_cast<float>(deg);
  }
  auto apply = [&](const std::vector<float>& x, std::vector<float>& y) {
    cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& r) {
      for (int i = r.start; i < r.end; ++i) {
        float s = diag[i] * x[i];
        for (int k = 0; k < 4; ++k)
          if (nb[i][k] >= 0) s -= x[nb[i][k]];
        y[i] = s;
      }
    });
  };
  std::vector<float> x(n), b(n), res(n), z(n), d(n), ad(n);
  for (int c = 0; c < 3; ++c) {
    cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& r) {
      for (int i = r.start; i < r.end; ++i) {
        const float s = b3[i][c];
        b[i] = s;
        x[i] = 0;
        res[i] = s;
        z[i] = s / diag[i];
        d[i] = z[i];
      }
    });
    double rz = dot(res, z);
    const double stop = 1e-8 * std::max(1.0, dot(b, b));
    for (int it = 0; it < in.iterations && dot(res, res) > stop; ++it) {
      if (progress.cancelled()) return make_error("feathering the seams cancelled");
      apply(d, ad);
      const double dad = dot(d, ad);
      if (!(dad > 0)) break;
      const float alpha = static_cast<float>(rz / dad);
      cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& r) {
        for (int i = r.start; i < r.end; ++i) {
          x[i] += alpha * d[i];
          res[i] -= alpha * ad[i];
          z[i] = res[i] / diag[i];
        }
      });
      const double rz_next = dot(res, z);
      const float beta = static_cast<float>(rz_next / rz);
      rz = rz_next;
      cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& r) {
        for (int i = r.start; i < r.end; ++i) d[i] = z[i] + beta * d[i];
      });
    }
    // T times exp(u - u0): u - u0 is the solve's x
    cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& r) {
      for (int i = r.start; i < r.end; ++i) texture.at<cv::Vec3f>(pixel[i])[c] *= std::exp(x[i]);
    });
    progress.report((c + 1) / 3.0, "feathering the seams");
  }
  return Status::success();
}

}  // namespace veneer::repaint::detail
