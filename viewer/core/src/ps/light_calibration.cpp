// Photometric stereo's light self-calibration (PsOptions::refine_lights):
// the lamps' vectors fitted to the photos given the solved normals, brought
// back to the recorded frame, and the set solved again with them.
#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "row_solver.hpp"
#include "veneer/ps/photometric_stereo.hpp"

namespace veneer::ps {

using detail::kMaxPatternLights;
using detail::solve_once;

namespace {

// The linear map C taking the solved normals to integrable ones, up to the
// bas-relief family, from the integrability condition written on them: with
// rows c1, c2, c3 of C, w1 = c3 x c1 and w2 = c3 x c2 satisfy, at every pixel,
//   w1 . (n x dn/dy) + w2 . (n x dn/dx) = 0      (image y pointing down),
// six unknowns, one homogeneous linear equation per pixel. Then c3 is along
// w1 x w2 and C = [k u1 + a c3; k u2 + b c3; s c3] (u = w x c3) with k, a, b, s
// fitted so that C^T recorded ~ fitted. `out` gets the lamps C^-T fitted.
bool integrable_gauge(const PsResult& r, const std::vector<cv::Vec3d>& recorded, const std::vector<cv::Vec3d>& fitted,
                      std::vector<cv::Vec3d>& out) {
  const int n = static_cast<int>(recorded.size());
  cv::Mat ok = r.reliable & r.mask;
  cv::Mat w;
  ok.convertTo(w, CV_32F, 1.0 / 255);
  cv::Mat nm = r.normals.clone();
  nm.setTo(cv::Scalar::all(0), ~ok);
  cv::GaussianBlur(nm, nm, cv::Size(0, 0), 1.0);
  cv::Mat ws;
  cv::GaussianBlur(w, ws, cv::Size(0, 0), 1.0);
  cv::Mat inner;
  cv::erode(ok, inner, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(5, 5)));
  const int count = cv::countNonZero(inner);
  if (count < 500) return false;
  const int stride = std::max(1, static_cast<int>(std::sqrt(double(count) / 60000.0)));
  auto at = [&](int x, int y) {
    cv::Vec3d v(nm.at<cv::Vec3f>(y, x));
    return v / std::max(1e-6, double(ws.at<float>(y, x)));
  };
  std::vector<cv::Vec<double, 6>> rows;
  for (int y = 1; y < r.normals.rows - 1; y += stride)
    for (int x = 1; x < r.normals.cols - 1; x += stride) {
      if (!inner.at<uint8_t>(y, x)) continue;
      cv::Vec3d c = at(x, y);
      const double len = cv::norm(c);
      if (!(len > 0.5)) continue;
      c /= len;
      const cv::Vec3d dx = (at(x + 1, y) - at(x - 1, y)) * 0.5, dy = (at(x, y + 1) - at(x, y - 1)) * 0.5;
      const cv::Vec3d a = c.cross(dy), b = c.cross(dx);
      rows.push_back({a[0], a[1], a[2], b[0], b[1], b[2]});
    }
  if (rows.size() < 300) return false;
  {  // Every pixel about one say: rows longer than the median (limbs, creases) scaled down to it.
    std::vector<double> len(rows.size());
    for (size_t i = 0; i < rows.size(); ++i) len[i] = cv::norm(rows[i]);
    std::vector<double> sorted = len;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double med = std::max(1e-12, sorted[sorted.size() / 2]);
    for (size_t i = 0; i < rows.size(); ++i)
      if (len[i] > med) rows[i] *= med / len[i];
  }
  cv::Vec<double, 6> v;
  std::vector<double> res(rows.size());
  for (int round = 0; round < 2; ++round) {
    cv::Matx<double, 6, 6> S = cv::Matx<double, 6, 6>::zeros();
    double cut = 1e30;
    if (round > 0) {  // drop the worst tenth (occluding edges, creases: not one smooth surface)
      std::vector<double> sorted = res;
      std::nth_element(sorted.begin(), sorted.begin() + sorted.size() * 9 / 10, sorted.end());
      cut = sorted[sorted.size() * 9 / 10];
    }
    for (size_t i = 0; i < rows.size(); ++i)
      if (res[i] <= cut || round == 0) S += rows[i] * rows[i].t();
    cv::Mat evals, evecs;
    cv::eigen(cv::Mat(S), evals, evecs);
    // The smallest eigenvalue must stand clear of the next: one condition, well posed.
    if (!(evals.at<double>(5) < 0.2 * evals.at<double>(4))) return false;
    for (int k = 0; k < 6; ++k) v[k] = evecs.at<double>(5, k);
    for (size_t i = 0; i < rows.size(); ++i) res[i] = std::abs(rows[i].dot(v));
  }
  const cv::Vec3d w1(v[0], v[1], v[2]), w2(v[3], v[4], v[5]);
  cv::Vec3d c3 = w1.cross(w2);
  if (!(cv::norm(c3) > 1e-9)) return false;
  c3 /= cv::norm(c3);
  const cv::Vec3d u1 = w1.cross(c3), u2 = w2.cross(c3);
  // C^T rec = k (u1 rx + u2 ry) + c3 (a rx + b ry + s rz), linear in (k, a, b, s).
  cv::Mat A(3 * n, 4, CV_64F), B(3 * n, 1, CV_64F);
  for (int i = 0; i < n; ++i) {
    const cv::Vec3d& q = recorded[i];
    const cv::Vec3d col0 = u1 * q[0] + u2 * q[1];
    for (int d = 0; d < 3; ++d) {
      A.at<double>(3 * i + d, 0) = col0[d];
      A.at<double>(3 * i + d, 1) = c3[d] * q[0];
      A.at<double>(3 * i + d, 2) = c3[d] * q[1];
      A.at<double>(3 * i + d, 3) = c3[d] * q[2];
      B.at<double>(3 * i + d) = fitted[i][d];
    }
  }
  cv::Mat p;
  if (!cv::solve(A, B, p, cv::DECOMP_SVD)) return false;
  const double k = p.at<double>(0), a = p.at<double>(1), b = p.at<double>(2), s = p.at<double>(3);
  const cv::Vec3d c1 = u1 * k + c3 * a, c2 = u2 * k + c3 * b, c3s = c3 * s;
  const cv::Matx33d C(c1[0], c1[1], c1[2], c2[0], c2[1], c2[2], c3s[0], c3s[1], c3s[2]);
  if (!(std::abs(cv::determinant(C)) > 1e-9)) return false;
  const cv::Matx33d CinvT = C.inv().t();
  out.resize(n);
  for (int i = 0; i < n; ++i) out[i] = CinvT * fitted[i];
  return true;
}

// A photo's pixel as float, whether the photo is float or half floats (io::ReadOptions::half_floats).
cv::Vec3f pixel_at(const cv::Mat& photo, int y, int x) {
  if (photo.depth() == CV_32F) return photo.at<cv::Vec3f>(y, x);
  const cv::float16_t* p = photo.ptr<cv::float16_t>(y) + size_t(x) * 3;
  return {float(p[0]), float(p[1]), float(p[2])};
}

// One round of light refinement (see PsOptions::refine_lights): each lamp's
// vector (intensity x direction) fitted to the grey photos given the solved
// normals and albedo, over the reliable pixels that lamp lights clearly
// (shadowed, saturated and far-off samples -- highlights -- left out); then
// the whole set of fitted vectors mapped by the one linear transform that
// brings them closest to the recorded ones, since the photos alone fix the
// lamps only up to such a transform. False when the data does not allow it.
bool refine_round(const io::ImageSet& set, const PsResult& r, const PsOptions& options, std::vector<io::Light>& lights) {
  const int n = static_cast<int>(set.images.size());
  const cv::Size size = set.images[0].size();
  // Pixels: reliable, a stride so that about 40k are used.
  const int count = cv::countNonZero(r.reliable & r.mask);
  if (count < 300) return false;
  const int stride = std::max(1, static_cast<int>(std::sqrt(double(count) / 40000.0)));
  struct Px {
    cv::Vec3d b;  // grey albedo x normal
    float g[kMaxPatternLights * 2];
    float peak;
  };
  if (n > kMaxPatternLights * 2) return false;
  const bool amb = options.subtract_ambient && !set.ambient.empty() && set.ambient.size() == size;
  std::vector<Px> px;
  px.reserve(static_cast<size_t>(count / (stride * stride) + 16));
  for (int y = 0; y < size.height; y += stride) {
    const uint8_t* ok = r.reliable.ptr<uint8_t>(y);
    const uint8_t* m = r.mask.ptr<uint8_t>(y);
    const cv::Vec3f* nr = r.normals.ptr<cv::Vec3f>(y);
    const cv::Vec3f* al = r.albedo.ptr<cv::Vec3f>(y);
    for (int x = 0; x < size.width; x += stride) {
      if (!ok[x] || !m[x]) continue;
      Px p;
      const double rho = (al[x][0] + al[x][1] + al[x][2]) / 3.0;
      if (!(rho > 0)) continue;
      p.b = cv::Vec3d(nr[x][0], nr[x][1], nr[x][2]) * rho;
      p.peak = 0;
      for (int i = 0; i < n; ++i) {
        const cv::Vec3f v = pixel_at(set.images[i], y, x);
        float g = (v[0] + v[1] + v[2]) / 3.f;
        if (amb) {
          const cv::Vec3f a = pixel_at(set.ambient, y, x);
          g -= (a[0] + a[1] + a[2]) / 3.f;
        }
        p.peak = std::max(p.peak, g);
        // a sample with any channel saturated is left out of the fit (as the solve leaves it out)
        p.g[i] = std::max({v[0], v[1], v[2]}) >= options.saturation ? -1.f : g;
      }
      px.push_back(p);
    }
  }
  if (px.size() < 200) return false;
  std::vector<cv::Vec3d> fitted(n), recorded(n);
  for (int i = 0; i < n; ++i) {
    const io::Light& l = lights[i];
    const double e = (l.intensity[0] + l.intensity[1] + l.intensity[2]) / 3.0;
    recorded[i] = l.direction / cv::norm(l.direction) * e;
    cv::Vec3d cur = recorded[i];
    // Three rounds: fit, then drop samples off by more than 3 robust sigmas (highlights, cast shadows).
    double cut = 1e30;
    for (int round = 0; round < 3; ++round) {
      cv::Matx33d A = cv::Matx33d::zeros();
      cv::Vec3d rhs(0, 0, 0);
      std::vector<float> res;
      res.reserve(px.size());
      int used = 0;
      for (const Px& p : px) {
        const float g = p.g[i];
        if (g < options.shadow_fraction * p.peak) continue;  // shadowed, or saturated (-1)
        const double pred = p.b.dot(cur);
        if (pred <= 0.05 * p.peak) continue;  // near the terminator: attached shadow's edge
        const double d = g - pred;
        if (round > 0 && std::abs(d) > cut) continue;
        res.push_back(static_cast<float>(std::abs(d)));
        A += p.b * p.b.t();
        rhs += p.b * double(g);
        ++used;
      }
      if (used < 100) return false;
      // Conditioning: the normals must spread in every direction.
      cv::Vec3d ev;
      cv::eigen(A, ev);
      if (!(ev[2] > 1e-3 * ev[0])) return false;
      cur = A.solve(rhs, cv::DECOMP_CHOLESKY);
      std::nth_element(res.begin(), res.begin() + res.size() / 2, res.end());
      cut = std::max(3.0 * 1.4826 * res[res.size() / 2], 1e-4);
    }
    fitted[i] = cur;
  }
  // The gauge. The photos fix the lamps only up to one linear map (any C
  // with normals C n and lamps C^-T l shades alike). Integrable normals (a
  // surface's) leave 3 of its 9 numbers free (the bas-relief ambiguity);
  // those, or all 9 when the normals can't say, are taken from the recorded lamps.
  std::vector<cv::Vec3d> out(n);
  if (!integrable_gauge(r, recorded, fitted, out)) {
    cv::Matx33d FF = cv::Matx33d::zeros(), RF = cv::Matx33d::zeros();  // M minimising sum |M fitted - recorded|^2
    for (int i = 0; i < n; ++i) {
      FF += fitted[i] * fitted[i].t();
      RF += recorded[i] * fitted[i].t();
    }
    if (std::abs(cv::determinant(FF)) < 1e-12) return false;
    const cv::Matx33d M = RF * FF.inv();
    for (int i = 0; i < n; ++i) out[i] = M * fitted[i];
  }
  for (int i = 0; i < n; ++i) {
    const cv::Vec3d v = out[i];
    const double len = cv::norm(v);
    if (!(len > 0)) return false;
    const double e_old = (lights[i].intensity[0] + lights[i].intensity[1] + lights[i].intensity[2]) / 3.0;
    lights[i].direction = v / len;
    lights[i].intensity *= static_cast<float>(len / e_old);
  }
  return true;
}

}  // namespace

Status photometric_stereo_into(const io::ImageSet& set, const cv::Mat& mask_in, const PsOptions& options,
                               const Progress& progress, PsResult& result) {
  if (Status st = solve_once(set, mask_in, options, progress, result); !st) return st;
  result.lights_refined = false;
  result.light_change_deg.clear();
  if (!options.refine_lights || !options.robust || result.model_used != LightModel::distant) return Status::success();
  std::vector<io::Light> lights = set.lights;
  io::ImageSet view = set;  // shares the photos; only the lights differ
  std::vector<double> moved(set.lights.size());
  for (int it = 0; it < options.refine_iterations; ++it) {
    if (!refine_round(set, result, options, lights)) break;
    // Directions that moved implausibly far are not a calibration error: keep the last plausible ones.
    for (size_t i = 0; i < lights.size(); ++i) {
      const double c = lights[i].direction.dot(set.lights[i].direction / cv::norm(set.lights[i].direction));
      moved[i] = std::acos(std::clamp(c, -1.0, 1.0)) * 180 / CV_PI;
    }
    if (*std::max_element(moved.begin(), moved.end()) > options.refine_max_deg) break;
    view.lights = lights;
    PsResult next;
    if (Status st = solve_once(view, mask_in, options, {}, next); !st) break;
    result = std::move(next);
    result.lights_refined = true;
    result.lights = view.lights;
    result.light_change_deg = moved;
  }
  return Status::success();
}

}  // namespace veneer::ps
