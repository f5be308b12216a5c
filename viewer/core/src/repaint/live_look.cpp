// The live view's shaded look (live_look.hpp).
#include "veneer/repaint/live_look.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>

#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/repaint/gloss.hpp"

namespace veneer::repaint {

Status LightEstimateOptions::check() const {
  if (samples < 100 || samples > 100000)
    return make_error("light estimate: samples " + std::to_string(samples) + " is outside 100..100000");
  if (iterations < 1 || iterations > 20)
    return make_error("light estimate: iterations " + std::to_string(iterations) + " is outside 1..20");
  if (!(max_residual > 0 && max_residual <= 10))
    return make_error("light estimate: max_residual " + std::to_string(max_residual) + " is outside (0, 10]");
  if (hold_frames < 0 || hold_frames > 100000)
    return make_error("light estimate: hold_frames " + std::to_string(hold_frames) + " is outside 0..100000");
  return {};
}

Status LiveLookOptions::check() const {
  if (auto s = model.check(); !s) return s;
  if (auto s = light.check(); !s) return s;
  if (!(change_dead_zone >= 0 && change_dead_zone <= 5))
    return make_error("live look: change_dead_zone " + std::to_string(change_dead_zone) + " is outside [0, 5]");
  if (!(change_clip >= 1 && change_clip <= 100))
    return make_error("live look: change_clip " + std::to_string(change_clip) + " is outside [1, 100]");
  if (!(extrapolate_floor > 0 && extrapolate_floor <= 1))
    return make_error("live look: extrapolate_floor " + std::to_string(extrapolate_floor) + " is outside (0, 1]");
  if (!(extrapolate_ring_deg >= 0 && extrapolate_ring_deg <= 90))
    return make_error("live look: extrapolate_ring_deg " + std::to_string(extrapolate_ring_deg) + " is outside [0, 90]");
  if (auto s = shadow.check(); !s) return make_error("live look: " + s.message());
  return {};
}

// Per mapped destination pixel, compact (index i), and the light estimate's samples.
struct LiveLookData {
  cv::Size dsize;
  std::vector<int> pixel;            // y * width + x
  cv::Mat dcoef, scoef;              // terms x N (CV_32FC1, a plane per term): the destination's model, the
                                     // source's at m(p)
  // one record per pixel, read in one stream per frame
  struct Pixel {
    cv::Vec3f texture;    // T
    cv::Vec3f normal;     // n_d
    float inv_median;     // 1 / (Dd + floor)
    float inv_model;      // 1 / (median of max(0, n_d.l) + 0.05): the headroom's Lambert ratio; T times it ~ the
                          // albedo (the ambient's share)
    float source_gloss;   // k_s(m(p))
  };
  struct Source {
    cv::Vec2f xy;         // the map's source coordinates
    cv::Vec3f chroma;     // the source's albedo per channel over its grey, at m(p)
    cv::Vec3f normal;     // the source's normal at m(p)
    float albedo;         // the source's grey albedo at m(p)
  };
  std::vector<Pixel> px;
  std::vector<Source> src;
  bool any_gloss = false;
  float headroom = 2;
  double source_exponent = 32;
  RelightableModel dmodel, smodel;   // for their weights (coefficients dropped; kept compact above)
  PixelHorizons dshadow;             // LiveLookOptions::shadows: the destination's horizons, per mapped pixel
  // where a side's model is extrapolated (LiveLookOptions::extrapolate): its lamps on a ring, a light farther off
  // the camera's axis than the ring is evaluated at the ring's angle (same azimuth) times the Lambert ratio
  struct Span {
    bool on = false;                // the lamps are a ring and the option is on
    double cos_lo = 0, cos_hi = 1;  // cos of the lamps' largest, of their smallest angle off the axis
    float floor = 0.02f;            // e of the Lambert ratio (n.l + e) / (n.l' + e)
  };
  Span dspan, sspan;                 // the destination's lamps', the source's
  // the light estimate's samples: source pixels, their normals, albedo (per channel) and the source's model
  std::vector<cv::Vec2f> sample_xy;
  std::vector<cv::Vec3f> sample_n, sample_rho;
  cv::Mat sample_coef;               // samples x terms (CV_32FC1)
  std::vector<cv::Vec3d> source_positions;
  // near lamps with a known camera: the light is fitted as a lamp at a place (point_lamp_fit), on the samples'
  // places in the rig frame (on the plane z = 0 through the object's nominal position)
  bool point_lamp = false;
  std::vector<cv::Vec3f> sample_x;
  std::vector<cv::Vec3f> sample_rho_near;  // the samples' albedo from the lamps' places (point_lamp only)
  double lamp_distance = 1;          // the source lamps' mean distance from the origin [m]: where the fit starts
  std::array<float, 256> to_linear{};
  std::vector<uchar> to_srgb;        // linear [0, 1] in kSrgbSteps steps -> 8-bit
  bool srgb = true;
};

namespace {

constexpr int kSrgbSteps = 16384;
constexpr float kModelFloor = 0.05f;  // as ShadedLook::shade's Lambert ratio

float srgb_decode(float v) { return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f); }
float srgb_encode(float v) {
  v = std::clamp(v, 0.f, 1.f);
  return v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1 / 2.4f) - 0.055f;
}

inline float grey(const cv::Vec3f& v) { return (v[0] + v[1] + v[2]) / 3.f; }

// the diffuse albedo per channel at (x, y): the median over the lamps that light it of I / (n.l)
cv::Vec3f albedo_at(const ObjectView& v, const std::vector<cv::Vec3f>& lamps, int x, int y, std::vector<float>& buf) {
  const cv::Vec3f n = v.normals.at<cv::Vec3f>(y, x);
  cv::Vec3f out(0, 0, 0);
  for (int c = 0; c < 3; ++c) {
    buf.clear();
    for (size_t i = 0; i < lamps.size(); ++i) {
      const float nl = n.dot(lamps[i]);
      if (nl > 0.1f) buf.push_back(v.images[i].at<cv::Vec3f>(y, x)[c] / nl);
    }
    if (buf.empty()) continue;
    std::nth_element(buf.begin(), buf.begin() + buf.size() / 2, buf.end());
    out[c] = buf[buf.size() / 2];
  }
  return out;
}

// the weights of `model` at `l`, with the indices whose weight matters (the
// residual's radial basis is 0 far from the captured lamps)
struct Active {
  std::vector<float> w;
  std::vector<int> at;
};
Active active_weights(const RelightableModel& model, const cv::Vec3d& l) {
  Active a;
  const std::vector<float> w = model.weights(l);
  for (int k = 0; k < static_cast<int>(w.size()); ++k)
    if (k < model.basis_terms() || std::abs(w[k]) > 1e-4f) a.w.push_back(w[k]), a.at.push_back(k);
  return a;
}

inline float dot_active(const float* c, const Active& a) {
  float s = 0;
  for (size_t k = 0; k < a.at.size(); ++k) s += c[a.at[k]] * a.w[k];
  return s;
}

constexpr uchar kClipped = 250;  // a frame value at or above this may be clipped: it says nothing of the light

inline bool clipped(const cv::Vec3b& v) { return v[0] >= kClipped || v[1] >= kClipped || v[2] >= kClipped; }

// x^k for a whole k >= 1, by squaring
inline float whole_power(float x, int k) {
  float r = 1.f;
  while (k > 0) {
    if (k & 1) r *= x;
    x *= x;
    k >>= 1;
  }
  return r;
}

// the same for pixel i of planes (terms x pixels)
inline float dot_column(const cv::Mat& planes, int i, const Active& a) {
  float s = 0;
  for (size_t k = 0; k < a.at.size(); ++k) s += planes.at<float>(a.at[k], i) * a.w[k];
  return s;
}

// Bilinear sample of an 8-bit BGR frame at (x, y), linear; false outside or clipped.
inline bool sample_frame(const cv::Mat& frame, const std::array<float, 256>& lin, float x, float y, cv::Vec3f* out) {
  if (!(x >= 0 && y >= 0 && x <= frame.cols - 1 && y <= frame.rows - 1)) return false;
  const int x0 = std::min(static_cast<int>(x), frame.cols - 2 < 0 ? 0 : frame.cols - 2);
  const int y0 = std::min(static_cast<int>(y), frame.rows - 2 < 0 ? 0 : frame.rows - 2);
  const int x1 = std::min(x0 + 1, frame.cols - 1), y1 = std::min(y0 + 1, frame.rows - 1);
  const float fx = x - x0, fy = y - y0;
  const cv::Vec3b a = frame.at<cv::Vec3b>(y0, x0), b = frame.at<cv::Vec3b>(y0, x1);
  const cv::Vec3b c = frame.at<cv::Vec3b>(y1, x0), d = frame.at<cv::Vec3b>(y1, x1);
  if (clipped(a) || clipped(b) || clipped(c) || clipped(d)) return false;
  for (int k = 0; k < 3; ++k)
    (*out)[k] = (1 - fy) * ((1 - fx) * lin[a[k]] + fx * lin[b[k]]) + fy * ((1 - fx) * lin[c[k]] + fx * lin[d[k]]);
  return true;
}

// Nearest-pixel sample, linear; false outside or clipped.
inline bool nearest_frame(const cv::Mat& frame, const std::array<float, 256>& lin, float x, float y, cv::Vec3f* out) {
  const int xi = static_cast<int>(x + 0.5f), yi = static_cast<int>(y + 0.5f);
  if (x < -0.5f || y < -0.5f || xi >= frame.cols || yi >= frame.rows) return false;
  const cv::Vec3b a = frame.at<cv::Vec3b>(yi, xi);
  if (clipped(a)) return false;
  *out = cv::Vec3f(lin[a[0]], lin[a[1]], lin[a[2]]);
  return true;
}

// The direction a side's model is evaluated at for a light `l`: l itself
// within the lamps' ring (their hull: the cap inside it), else l turned (same
// azimuth) back to the ring's angle off the axis. The model there is then
// carried to l by the Lambert ratio on that side's normals: the model learns
// nothing from a ring of lamps about how the shading changes with the lamp's
// angle off the axis (HSH's terms in theta alone are one constant on a cone),
// and extrapolated it overshoots; Lambert knows it from the normals.
// Measured (tools/prototypes/live/README.md): the simulated ring sequence
// 1.33x -> 1.13x the pixel copy; on a Lambert sphere at 50 deg 0.026 against
// the model's 0.305. Inside the ring the model alone is better (the sphere at
// 5 deg: model 0.026, Lambert ratio 0.053; the sequence's first frames too).
cv::Vec3d supported(const LiveLookData::Span& d, const cv::Vec3d& l) {
  if (!d.on) return l;
  const double c = std::clamp(l[2], -1.0, 1.0);
  if (c >= d.cos_lo - 1e-9) return l;
  const double ct = d.cos_lo, st = std::sqrt(std::max(0.0, 1 - ct * ct));
  const double r = std::hypot(l[0], l[1]);
  const double cx = r > 1e-9 ? l[0] / r : 1.0, cy = r > 1e-9 ? l[1] / r : 0.0;
  return {st * cx, st * cy, ct};
}

// Extrapolated only when the lamps are a ring: their angles off the axis
// within `ring_deg` of each other (then the lamps' hull is the cap inside the
// ring, and a light farther off the axis than the ring is outside it). Lamps
// spread over the hemisphere (DiLiGenT's) are left to the model.
LiveLookData::Span span_of(const std::vector<cv::Vec3d>& lamps, bool on, double floor, double ring_deg) {
  LiveLookData::Span s;
  s.floor = static_cast<float>(floor);
  s.cos_lo = 1, s.cos_hi = -1;
  for (const cv::Vec3d& l : lamps) {
    const double c = l[2] / std::max(1e-12, cv::norm(l));
    s.cos_lo = std::min(s.cos_lo, c), s.cos_hi = std::max(s.cos_hi, c);
  }
  const double spread = (std::acos(std::clamp(s.cos_lo, -1.0, 1.0)) - std::acos(std::clamp(s.cos_hi, -1.0, 1.0))) *
                        180 / CV_PI;
  s.on = on && lamps.size() >= 3 && spread <= ring_deg;
  return s;
}

// The Lambert ratio that carries a model evaluated at l' to l.
inline float lambert_ratio(const cv::Vec3f& n, const cv::Vec3f& l, const cv::Vec3f& ls, float e) {
  return (std::max(0.f, n.dot(l)) + e) / (std::max(0.f, n.dot(ls)) + e);
}
inline cv::Vec3f to_f(const cv::Vec3d& v) {
  return {static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2])};
}

// a direction turned by small angles about x and y (radians)
cv::Vec3d turned(const cv::Vec3d& l, double ax, double ay) {
  cv::Vec3d d(l[0] + ay * l[2], l[1] + ax * l[2], l[2] - ay * l[0] - ax * l[1]);
  return d / std::max(1e-12, cv::norm(d));
}

// The lamp as a place P (rig frame, m), fitted to the frame's grey samples I_j = rho_j (s n_j.(P - x_j) /
// |P - x_j|^3 + a) (Lambert, the lamp's fall-off, an ambient a) by Gauss-Newton with Cauchy weights (cast
// shadows, highlights and the pits' own shading count little), from `p0`, `s0`. Why a place: a lamp at
// arm's length lights the object's near side more and from a wider angle than a distant lamp in the same
// direction, so a direction fitted to it (the Lambert fit, or the source's model) leans outward: on the
// demo's spiral +3.3 deg (Lambert) and +1.9 deg (the model) median; the place, with the samples on the
// plane z = 0 (their depth left out), 0.23 deg median, +0.06 bias (tools/prototypes/live/README.md).
struct PointFit {
  cv::Vec3d position;
  double strength = 0, ambient = 0;
  bool ok = false;
};
PointFit point_lamp_fit(const std::vector<cv::Vec3f>& x, const std::vector<cv::Vec3f>& normal,
                        const std::vector<cv::Vec3f>& rho, const std::vector<cv::Vec3f>& I,
                        const std::vector<uchar>& use, const cv::Vec3d& p0, double s0, double a0) {
  PointFit out;
  const size_t n = x.size();
  cv::Vec3d P = p0;
  double s = s0, a = std::max(0.0, a0);
  std::vector<double> w(n, 1.0), e(n, 0.0);
  double lambda = 1e-3;
  auto residuals = [&](const cv::Vec3d& Pp, double sp, double ap, std::vector<double>* out_e) {
    double sse = 0;
    for (size_t j = 0; j < n; ++j) {
      if (!use[j]) continue;
      const cv::Vec3d v = Pp - cv::Vec3d(x[j]);
      const double r2 = v.dot(v), r = std::sqrt(r2);
      const double c = std::max(0.0, cv::Vec3d(normal[j]).dot(v) / r);
      const double g = grey(rho[j]);
      const double ej = grey(I[j]) - g * (sp * c / r2 + ap);
      if (out_e) (*out_e)[j] = ej;
      sse += w[j] * ej * ej;
    }
    return sse;
  };
  for (int round = 0; round < 4; ++round) {
    double sse = residuals(P, s, a, &e);
    for (int it = 0; it < 8; ++it) {
      cv::Matx<double, 5, 5> A = cv::Matx<double, 5, 5>::zeros();
      cv::Vec<double, 5> b(0, 0, 0, 0, 0);
      for (size_t j = 0; j < n; ++j) {
        if (!use[j] || w[j] <= 0) continue;
        const cv::Vec3d v = P - cv::Vec3d(x[j]);
        const double r2 = v.dot(v), r = std::sqrt(r2), r3 = r2 * r, r5 = r3 * r2;
        const cv::Vec3d nn(normal[j]);
        const double nv = nn.dot(v);
        const double g = grey(rho[j]);
        cv::Vec<double, 5> J(0, 0, 0, 0, g);
        if (nv > 0) {
          const cv::Vec3d dP = g * s * (nn / r3 - 3 * nv * v / r5);
          J = cv::Vec<double, 5>(dP[0], dP[1], dP[2], g * nv / r3, g);
        }
        A += w[j] * J * J.t();
        b += w[j] * e[j] * J;
      }
      cv::Matx<double, 5, 5> Ad = A;
      for (int k = 0; k < 5; ++k) Ad(k, k) += lambda * std::max(A(k, k), 1e-12);
      cv::Vec<double, 5> step;
      if (!cv::solve(Ad, b, step, cv::DECOMP_CHOLESKY)) break;
      cv::Vec3d Pn(P[0] + step[0], P[1] + step[1], std::max(0.05, P[2] + step[2]));
      const double sn = std::max(1e-9, s + step[3]), an = std::max(0.0, a + step[4]);
      std::vector<double> en(n, 0.0);
      const double ssen = residuals(Pn, sn, an, &en);
      if (ssen < sse) {
        P = Pn, s = sn, a = an, sse = ssen, e.swap(en);
        lambda = std::max(1e-6, lambda * 0.3);
        if (cv::norm(cv::Vec3d(step[0], step[1], step[2])) < 1e-5) break;
      } else {
        lambda *= 10;
        if (lambda > 1e6) break;
      }
    }
    // Cauchy weights on the residuals relative to the frame's typical brightness
    std::vector<double> r;
    r.reserve(n);
    double level = 0, count = 0;
    for (size_t j = 0; j < n; ++j)
      if (use[j]) r.push_back(std::abs(e[j])), level += grey(I[j]), count += 1;
    if (r.size() < 30) return out;
    std::nth_element(r.begin(), r.begin() + r.size() / 2, r.end());
    const double scale = std::max(0.02 * level / std::max(count, 1.0), 2.5 * 1.4826 * r[r.size() / 2]);
    for (size_t j = 0; j < n; ++j) {
      const double q = e[j] / scale;
      w[j] = 1.0 / (1.0 + q * q);
    }
  }
  out.position = P, out.strength = s, out.ambient = a;
  out.ok = std::isfinite(P[0]) && std::isfinite(P[1]) && std::isfinite(P[2]) && cv::norm(P) > 1e-6;
  return out;
}

}  // namespace

Expected<LiveLook> LiveLook::make(const ShadedLook& look, const LookSide& destination, const LookSide& source,
                                  const Map& map, const std::vector<cv::Vec3d>& source_positions,
                                  const LiveLookOptions& options, const Progress& progress) {
  if (auto s = options.check(); !s) return s.error();
  const ObjectView& dv = destination.view;
  const ObjectView& sv = source.view;
  const cv::Size dsize = dv.mask.size(), ssize = sv.mask.size();
  if (look.map_xy().size() != dsize || map.xy.size() != dsize || look.texture().size() != dsize)
    return make_error("live look: the still look, the map and the destination's view differ in size");
  if (dv.images.size() != destination.lamps.size() || sv.images.size() != source.lamps.size())
    return make_error("live look: lamps and photos differ in number");
  if (sv.normals.type() != CV_32FC3 || sv.normals.size() != ssize || dv.normals.type() != CV_32FC3)
    return make_error("live look: the views' normals must be CV_32FC3 of their masks' size");
  for (const cv::Mat& p : sv.images)
    if (p.type() != CV_32FC3 || p.size() != ssize) return make_error("live look: the source's photos must be CV_32FC3");
  for (const cv::Mat& p : dv.images)
    if (p.type() != CV_32FC3 || p.size() != dsize)
      return make_error("live look: the destination's photos must be CV_32FC3");
  if (!source_positions.empty() && source_positions.size() != source.lamps.size())
    return make_error("live look: " + std::to_string(source_positions.size()) + " lamp positions for " +
                      std::to_string(source.lamps.size()) + " lamps");
  auto data = std::make_shared<LiveLookData>();
  LiveLookData& d = *data;
  d.dsize = dsize;
  d.headroom = look.headroom();
  d.source_exponent = look.source_exponent();
  d.source_positions = source_positions;
  d.srgb = options.light.srgb;
  // each side's model off its lamps' ring (the source's too: the light's intensity is the frame over the
  // source's model, and the destination's shading over it must err alike, or the frames' brightness drifts)
  d.dspan = span_of(destination.lamps, options.extrapolate, options.extrapolate_floor, options.extrapolate_ring_deg);
  d.sspan = span_of(source.lamps, options.extrapolate, options.extrapolate_floor, options.extrapolate_ring_deg);

  // the destination's diffuse grey photos (its own gloss off, as the still look's ratio takes it off)
  std::vector<cv::Vec3f> dl, sl;
  for (const cv::Vec3d& l : destination.lamps) dl.emplace_back(l / std::max(1e-12, cv::norm(l)));
  for (const cv::Vec3d& l : source.lamps) sl.emplace_back(l / std::max(1e-12, cv::norm(l)));
  std::vector<cv::Mat> diffuse(dv.images.size());
  const cv::Mat& kd = look.destination_gloss_weight();
  for (size_t i = 0; i < dv.images.size(); ++i) {
    diffuse[i] = cv::Mat(dsize, CV_32FC1);
    const cv::Vec3f h = half_vector(destination.lamps[i]);
    diffuse[i].forEach<float>([&](float& v, const int* at) {
      const float g = grey(dv.images[i].at<cv::Vec3f>(at[0], at[1]));
      const float k = kd.empty() ? 0.f : kd.at<float>(at[0], at[1]);
      const float s = k > 0 ? k * Gloss::lobe(dv.normals.at<cv::Vec3f>(at[0], at[1]), dl[i], h,
                                              look.destination_exponent())
                            : 0.f;
      v = std::max(g - s, 0.f);
    });
  }
  // the destination's cast shadows: horizons of its normals told its photos' shadows, and the model fitted
  // without them (a shadowed sample replaced by its albedo x n.l), so that at any light its shading is the
  // unshadowed model times the visibility there
  std::optional<ShadowMap> shadows;
  if (options.shadows) {
    auto seen = photo_shadows(diffuse, dv.normals, dv.mask, destination.lamps);
    if (!seen) return make_error("live look: the destination's " + seen.message());
    auto made = ShadowMap::make(dv.normals, dv.mask, options.shadow, progress.part(0.0, 0.1));
    if (!made) return make_error("live look: the destination's " + made.message());
    if (auto s = made->observe(destination.lamps, seen->shadowed, seen->lit); !s)
      return make_error("live look: the destination's " + s.message());
    shadows = std::move(*made);
    for (size_t i = 0; i < diffuse.size(); ++i)
      diffuse[i].forEach<float>([&](float& v, const int* at) {
        if (seen->shadowed[i].at<uchar>(at[0], at[1]))
          v = seen->albedo.at<float>(at[0], at[1]) * std::max(0.f, dv.normals.at<cv::Vec3f>(at[0], at[1]).dot(dl[i]));
      });
  }
  auto dm = RelightableModel::fit(diffuse, dv.mask, destination.lamps, options.model, progress.part(0.1, 0.4));
  if (!dm) return make_error("live look: the destination's " + dm.message());
  auto sm = RelightableModel::fit(sv.images, sv.mask, source.lamps, options.model, progress.part(0.4, 0.8));
  if (!sm) return make_error("live look: the source's " + sm.message());
  if (progress.cancelled()) return make_error("live look: cancelled");

  // compact per mapped destination pixel
  const cv::Mat& xy = map.xy;
  for (int y = 0; y < dsize.height; ++y)
    for (int x = 0; x < dsize.width; ++x)
      if (xy.at<cv::Vec2f>(y, x)[0] >= 0) d.pixel.push_back(y * dsize.width + x);
  const int n = static_cast<int>(d.pixel.size());
  if (shadows) d.dshadow = shadows->at(d.pixel);
  const int td = dm->terms(), ts = sm->terms();
  d.dcoef = cv::Mat(td, n, CV_32FC1);
  d.scoef = cv::Mat(ts, n, CV_32FC1);
  d.px.assign(n, {});
  d.src.assign(n, {});
  const cv::Mat& ks = look.source_gloss_weight();
  cv::parallel_for_(cv::Range(0, n), [&](const cv::Range& r) {
    std::vector<float> buf;
    for (int i = r.start; i < r.end; ++i) {
      const int x = d.pixel[i] % dsize.width, y = d.pixel[i] / dsize.width;
      const cv::Vec2f m = xy.at<cv::Vec2f>(y, x);
      LiveLookData::Pixel& e = d.px[i];
      LiveLookData::Source& f = d.src[i];
      f.xy = m;
      const int sx = std::clamp(static_cast<int>(std::lround(m[0])), 0, ssize.width - 1);
      const int sy = std::clamp(static_cast<int>(std::lround(m[1])), 0, ssize.height - 1);
      f.normal = sv.normals.at<cv::Vec3f>(sy, sx);
      const float* dc = dm->coefficients().ptr<float>(y) + x * td;
      const float* sc = sm->coefficients().ptr<float>(sy) + sx * ts;
      for (int k = 0; k < td; ++k) d.dcoef.at<float>(k, i) = dc[k];
      for (int k = 0; k < ts; ++k) d.scoef.at<float>(k, i) = sc[k];
      e.texture = look.texture().at<cv::Vec3f>(y, x);
      e.inv_median = 1.f / look.shading_median().at<float>(y, x);
      e.normal = dv.normals.at<cv::Vec3f>(y, x);
      e.inv_model = 1.f / (look.model_median().at<float>(y, x) + kModelFloor);
      e.source_gloss = ks.empty() ? 0.f : ks.at<float>(y, x);
      const cv::Vec3f a = albedo_at(sv, sl, sx, sy, buf);
      const float g = grey(a);
      f.albedo = g;
      f.chroma = g > 1e-6f ? a / g : cv::Vec3f(1, 1, 1);
    }
  });
  // the light estimate's samples: source object pixels on a regular grid
  std::vector<cv::Point> object;
  cv::findNonZero(sv.mask, object);
  if (object.size() < 50) return make_error("live look: the source's mask holds fewer than 50 pixels");
  const size_t want = static_cast<size_t>(options.light.samples);
  const double stride = std::max(1.0, static_cast<double>(object.size()) / want);
  std::vector<float> buf;
  for (double k = 0; k < object.size(); k += stride) {
    const cv::Point p = object[static_cast<size_t>(k)];
    const cv::Vec3f nn = sv.normals.at<cv::Vec3f>(p);
    if (cv::norm(nn) < 0.5) continue;
    const cv::Vec3f a = albedo_at(sv, sl, p.x, p.y, buf);
    if (grey(a) <= 0) continue;
    d.sample_xy.emplace_back(static_cast<float>(p.x), static_cast<float>(p.y));
    d.sample_n.push_back(nn);
    d.sample_rho.push_back(a);
  }
  const cv::Vec3d cam = source.camera;
  if (!source_positions.empty() && cam[0] > 0) {
    const double f = cam[0], cx = cam[1] > 0 ? cam[1] : (ssize.width - 1) * 0.5,
                 cy = cam[2] > 0 ? cam[2] : (ssize.height - 1) * 0.5;
    d.point_lamp = true;
    d.lamp_distance = 0;
    for (const cv::Vec3d& p : source_positions) d.lamp_distance += cv::norm(p) / static_cast<double>(source_positions.size());
    for (const cv::Vec2f& q : d.sample_xy)
      d.sample_x.emplace_back(static_cast<float>((q[0] - cx) / f), static_cast<float>(-(q[1] - cy) / f), 0.f);
    // the samples' albedo under the lamps as they are, at their places (each lamp's direction and fall-off at
    // the sample, its strength at the origin as recorded): the directions alone tint the albedo by where the
    // sample sits, and the fit reads that as the lamp's place
    std::vector<float> vals;
    for (size_t j = 0; j < d.sample_xy.size(); ++j) {
      const cv::Vec3d xj(d.sample_x[j]), nj(d.sample_n[j]);
      const int px = static_cast<int>(d.sample_xy[j][0]), py = static_cast<int>(d.sample_xy[j][1]);
      cv::Vec3f rho(0, 0, 0);
      for (int c = 0; c < 3; ++c) {
        vals.clear();
        for (size_t i = 0; i < source_positions.size(); ++i) {
          const cv::Vec3d v = source_positions[i] - xj;
          const double r2 = v.dot(v), r = std::sqrt(r2);
          const double nl = nj.dot(v) / r;
          if (nl <= 0.1) continue;
          const double e = nl * source_positions[i].dot(source_positions[i]) / r2;
          vals.push_back(static_cast<float>(sv.images[i].at<cv::Vec3f>(py, px)[c] / e));
        }
        if (vals.empty()) continue;
        std::nth_element(vals.begin(), vals.begin() + vals.size() / 2, vals.end());
        rho[c] = vals[vals.size() / 2];
      }
      if (grey(rho) > 0) d.sample_rho_near.push_back(rho);
      else d.sample_rho_near.push_back(d.sample_rho[j]);
    }
  }
  d.sample_coef = cv::Mat(static_cast<int>(d.sample_xy.size()), ts, CV_32FC1);
  for (size_t i = 0; i < d.sample_xy.size(); ++i)
    std::copy_n(sm->coefficients().ptr<float>(static_cast<int>(d.sample_xy[i][1])) +
                    static_cast<int>(d.sample_xy[i][0]) * ts,
                ts, d.sample_coef.ptr<float>(static_cast<int>(i)));
  if (d.sample_xy.size() < 50) return make_error("live look: fewer than 50 lit source pixels to estimate light on");
  for (const auto& e : d.px) d.any_gloss = d.any_gloss || e.source_gloss > 0;
  d.dmodel = std::move(*dm);
  d.smodel = std::move(*sm);
  d.dmodel.drop_coefficients();
  d.smodel.drop_coefficients();
  for (int v = 0; v < 256; ++v) d.to_linear[v] = d.srgb ? srgb_decode(v / 255.f) : v / 255.f;
  d.to_srgb.resize(kSrgbSteps + 1);
  for (int i = 0; i <= kSrgbSteps; ++i) {
    const float v = static_cast<float>(i) / kSrgbSteps;
    d.to_srgb[i] = cv::saturate_cast<uchar>(255.f * (d.srgb ? srgb_encode(v) : v));
  }
  progress.report(1.0, "live look");
  LiveLook out;
  out.options_ = options;
  out.size_ = dsize;
  out.data_ = std::move(data);
  return out;
}

LiveLight LiveLook::estimate_light(const cv::Mat& frame, const cv::Matx23d& a) const {
  const LiveLookData& d = *data_;
  LiveLight light;
  light.explained = false;
  // the frame at each sample, linear
  const size_t n = d.sample_xy.size();
  std::vector<cv::Vec3f> I(n);
  std::vector<uchar> ok(n, 0);
  std::vector<float> at_least(n, -1.f);
  size_t inside = 0;
  for (size_t j = 0; j < n; ++j) {
    const cv::Vec2f q = d.sample_xy[j];
    const float fx = static_cast<float>(a(0, 0) * q[0] + a(0, 1) * q[1] + a(0, 2));
    const float fy = static_cast<float>(a(1, 0) * q[0] + a(1, 1) * q[1] + a(1, 2));
    ok[j] = frame.type() == CV_8UC3 && sample_frame(frame, d.to_linear, fx, fy, &I[j]);
    inside += ok[j];
    if (!ok[j] && frame.type() == CV_8UC3) {
      // clipped: the frame says only that the pixel is at least this bright (the residual's censored samples)
      const int xi = static_cast<int>(fx + 0.5f), yi = static_cast<int>(fy + 0.5f);
      if (xi >= 0 && yi >= 0 && xi < frame.cols && yi < frame.rows) {
        const cv::Vec3b v = frame.at<cv::Vec3b>(yi, xi);
        if (clipped(v)) at_least[j] = (d.to_linear[v[0]] + d.to_linear[v[1]] + d.to_linear[v[2]]) / 3.f;
      }
    }
  }
  if (inside < 30) {
    light.residual = 1;
    light.fallback = "the object is out of the frame";
    return light;
  }
  // 1. Lambert, reweighted: g = rho (n.L + amb), on the samples the lamp lights
  cv::Vec3d L(0, 0, 1);
  double amb = 0;
  std::vector<double> w(n, 1.0);
  for (int it = 0; it < options_.light.iterations; ++it) {
    cv::Matx44d A = cv::Matx44d::zeros();
    cv::Vec4d b(0, 0, 0, 0);
    const cv::Vec3d dir = L / std::max(1e-12, cv::norm(L));
    for (size_t j = 0; j < n; ++j) {
      if (!ok[j] || w[j] <= 0) continue;
      const cv::Vec3d nn = d.sample_n[j];
      if (it > 0 && nn.dot(dir) < 0.1) continue;  // attached shadow: outside the linear model
      const double rho = grey(d.sample_rho[j]);
      const cv::Vec4d row(rho * nn[0], rho * nn[1], rho * nn[2], rho);
      A += w[j] * row * row.t();
      b += w[j] * grey(I[j]) * row;
    }
    cv::Vec4d x;
    if (!cv::solve(A, b, x, cv::DECOMP_SVD)) break;
    L = {x[0], x[1], x[2]};
    amb = x[3];
    if (cv::norm(L) < 1e-9) break;
    // Cauchy weights on the relative residual: cast shadows and highlights count little
    std::vector<double> r;
    r.reserve(n);
    for (size_t j = 0; j < n; ++j) {
      if (!ok[j]) continue;
      const double rho = grey(d.sample_rho[j]);
      const double p = rho * (std::max(0.0, cv::Vec3d(d.sample_n[j]).dot(L)) + amb);
      r.push_back(std::abs(grey(I[j]) - p) / std::max(p, 1e-3 * cv::norm(L) * rho + 1e-6));
    }
    std::vector<double> sorted = r;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double scale = std::max(0.02, 2.5 * 1.4826 * sorted[sorted.size() / 2]);
    for (size_t j = 0, k = 0; j < n; ++j) {
      if (!ok[j]) continue;
      const double e = r[k++] / scale;
      w[j] = 1.0 / (1.0 + e * e);
    }
  }
  const double strength = cv::norm(L);
  if (!(strength > 1e-9) || !std::isfinite(strength)) {
    light.residual = 1;
    light.fallback = "no light found";
    return light;
  }
  cv::Vec3d dir = L / strength;
  if (dir[2] < 0) {
    light.residual = 1;
    light.fallback = "the light found is behind the object";
    return light;
  }
  // 2. The source's own model at that direction (its cast shadows and gloss in
  // it) fitted to the frame as s S(l) + amb rho; the direction refined by
  // trying small turns; its residual says whether one lamp explains the frame.
  // Off the source's lamps' ring the model as the painting evaluates it (supported()): searched with the model
  // alone, the direction is nearer the lamp (simulated sequence, 512x340: median 1.33 deg against 1.70) but the
  // painted shading no better than without extrapolating (1.25x the copy against 1.09x): the destination's
  // shading is extrapolated alike, and the two err alike at the direction found this way.
  auto model_fit = [&](const cv::Vec3d& l, double* s_out, double* a_out) {
    const cv::Vec3d lsd = supported(d.sspan, l);
    const bool sext = lsd != l;
    const cv::Vec3f lf = to_f(l), lsf = to_f(lsd);
    const Active act = active_weights(d.smodel, lsd);
    double saa = 0, sab = 0, sbb = 0, sya = 0, syb = 0, syy = 0, count = 0;
    for (size_t j = 0; j < n; ++j) {
      if (!ok[j]) continue;
      double p = std::max(0.f, dot_active(d.sample_coef.ptr<float>(static_cast<int>(j)), act));
      if (sext) p *= lambert_ratio(d.sample_n[j], lf, lsf, d.sspan.floor);
      const double rho = grey(d.sample_rho[j]);
      const double y = grey(I[j]);
      saa += p * p, sab += p * rho, sbb += rho * rho, sya += y * p, syb += y * rho, syy += y * y, count += 1;
    }
    const double det = saa * sbb - sab * sab;
    double s = det > 1e-18 ? (sya * sbb - syb * sab) / det : sya / std::max(saa, 1e-18);
    double am = det > 1e-18 ? (syb * saa - sya * sab) / det : 0;
    if (am < 0) am = 0, s = sya / std::max(saa, 1e-18);
    const double sse = syy - 2 * s * sya - 2 * am * syb + s * s * saa + 2 * s * am * sab + am * am * sbb;
    const double mean_y = std::sqrt(syy / std::max(count, 1.0));  // RMS brightness: the scale of the residual
    *s_out = s, *a_out = am;
    return std::sqrt(std::max(sse, 0.0) / std::max(count, 1.0)) / std::max(mean_y, 1e-9);
  };
  std::optional<cv::Vec3d> place;
  if (d.point_lamp) {
    const PointFit pf = point_lamp_fit(d.sample_x, d.sample_n, d.sample_rho_near, I, ok, dir * d.lamp_distance,
                                       strength * d.lamp_distance * d.lamp_distance, amb);
    if (pf.ok && pf.position[2] > 0) {
      place = pf.position;
      dir = pf.position / cv::norm(pf.position);
    }
  }
  double s = 0, am = 0;
  double best = model_fit(dir, &s, &am);
  for (double step_deg : {4.0, 2.0, 1.0}) {
    if (place) break;  // the place fitted: its direction stands
    const double step = step_deg * CV_PI / 180;
    for (int round = 0; round < 3; ++round) {
      bool moved = false;
      for (const auto& [ax, ay] : {std::pair{step, 0.0}, {-step, 0.0}, {0.0, step}, {0.0, -step}}) {
        const cv::Vec3d t = turned(dir, ax, ay);
        if (t[2] < 0.05) continue;
        double st = 0, at = 0;
        const double e = model_fit(t, &st, &at);
        if (e < best) best = e, dir = t, s = st, am = at, moved = true;
      }
      if (!moved) break;
    }
  }
  light.direction = dir;
  // The residual over every sample the frame shows, the clipped ones too: where the prediction is at least
  // as bright as a clipped pixel it agrees with it. Without them a frame that clips its lit side (the demo's
  // live view clips half the orange) is judged on its terminator and pits alone, where any model is worst:
  // the demo's single lamp read 0.20-0.24, above a hand-held pair of lamps (issue 47).
  {
    const cv::Vec3d lsd = supported(d.sspan, dir);
    const bool sext = lsd != dir;
    const Active act = active_weights(d.smodel, lsd);
    double see = 0, syy = 0, count = 0;
    for (size_t j = 0; j < n; ++j) {
      if (!ok[j] && at_least[j] < 0) continue;
      double p = std::max(0.f, dot_active(d.sample_coef.ptr<float>(static_cast<int>(j)), act));
      if (sext) p *= lambert_ratio(d.sample_n[j], to_f(dir), to_f(lsd), d.sspan.floor);
      const double pred = s * p + am * grey(d.sample_rho[j]);
      const double y = ok[j] ? grey(I[j]) : at_least[j];
      const double e = ok[j] ? y - pred : std::max(0.0, y - pred);
      see += e * e, syy += y * y, count += 1;
    }
    if (count > 0 && syy > 0) best = std::sqrt(see / syy);
  }
  light.residual = best;
  // colour: per sample the frame's chromaticity over the source's albedo's (each channel over the source's
  // chroma, over their mean), the median over the samples the lamp lights well. A shading error (the model's,
  // a cast shadow, the light's distance) scales the three channels alike and cancels in the ratio; a weighted
  // fit of the frame against the grey prediction times the chroma (before, issue 47) let the shading's error
  // where the albedo's colour varies (the peel's pits) tint a white lamp, to blue 0.92 on the demo's spiral.
  const double lit_floor = 0.25 * std::max(1e-9, s);
  cv::Vec3d colour(1, 1, 1);
  {
    std::array<std::vector<float>, 3> per;
    for (size_t j = 0; j < n; ++j) {
      if (!ok[j] || cv::Vec3d(d.sample_n[j]).dot(dir) < 0.3) continue;
      const double g = grey(d.sample_rho[j]);
      if (g <= 0 || grey(I[j]) < lit_floor * g * 0.3) continue;
      cv::Vec3d q;
      for (int c = 0; c < 3; ++c) q[c] = I[j][c] / std::max(1e-6, d.sample_rho[j][c] / g);
      const double mq = (q[0] + q[1] + q[2]) / 3;
      if (mq <= 1e-9) continue;
      for (int c = 0; c < 3; ++c) per[c].push_back(static_cast<float>(q[c] / mq));
    }
    if (per[0].size() >= 30)
      for (int c = 0; c < 3; ++c) {
        std::nth_element(per[c].begin(), per[c].begin() + per[c].size() / 2, per[c].end());
        colour[c] = per[c][per[c].size() / 2];
      }
  }
  const double mean_colour = (colour[0] + colour[1] + colour[2]) / 3;
  if (mean_colour > 1e-9) colour /= mean_colour;
  // BGR in memory -> r, g, b in the report
  light.colour = {colour[2], colour[1], colour[0]};
  light.intensity = s;
  if (place) {
    light.position_m = *place;
  } else if (!d.source_positions.empty() && dir[2] > 0.05) {
    double z = 0;
    for (const cv::Vec3d& p : d.source_positions) z += p[2];
    z /= static_cast<double>(d.source_positions.size());
    light.position_m = dir * (z / dir[2]);
  }
  light.explained = s > 0 && best <= options_.light.max_residual;
  return light;
}

namespace {
// The destination's side of a light `l` (unit), what paint and
// paint_linear each shade with: the direction its model supports (`ls`, the
// ring's at the same azimuth when `l` lies beyond the ring), whether that
// differs (`ext`), the model's weights there, the directions and the half
// vector in float, and the Lambert ratio's floor.
struct DestinationLight {
  cv::Vec3d ls;
  bool ext;
  Active wd;
  cv::Vec3f lf, lsf, h;
  float ef;
};
DestinationLight destination_light(const LiveLookData& d, const cv::Vec3d& l) {
  const cv::Vec3d ls = supported(d.dspan, l);
  return {ls, ls != l, active_weights(d.dmodel, ls), to_f(l), to_f(ls), half_vector(l), d.dspan.floor};
}
}  // namespace

cv::Mat LiveLook::paint(const cv::Mat& frame, const cv::Matx23d& a, const LiveLight& light,
                        const cv::Mat& backdrop, double exposure) const {
  const LiveLookData& d = *data_;
  cv::Mat out;
  if (!backdrop.empty() && backdrop.size() == d.dsize && backdrop.type() == CV_8UC3)
    out = backdrop.clone();
  else
    out = cv::Mat(d.dsize, CV_8UC3, cv::Scalar::all(0));
  const cv::Vec3d& l = light.direction;
  // named, not bound: clang 14 (make fuzz) cannot capture structured bindings in the lambdas below
  const DestinationLight dl = destination_light(d, l);
  const bool ext = dl.ext;
  const Active& wd = dl.wd;
  const cv::Vec3f &lf = dl.lf, &lsf = dl.lsf, &h = dl.h;
  const float ef = dl.ef;
  const cv::Vec3d lss = supported(d.sspan, l);
  const bool sext = lss != l;
  const cv::Vec3f lssf = to_f(lss);
  const Active ws = active_weights(d.smodel, lss);
  const float s = static_cast<float>(light.intensity), am = static_cast<float>(light.ambient);
  // r, g, b -> BGR, times the exposure
  const cv::Vec3f colour = static_cast<float>(exposure) *
                           cv::Vec3f(static_cast<float>(light.colour[2]), static_cast<float>(light.colour[1]),
                                     static_cast<float>(light.colour[0]));
  const cv::Vec3f frame_colour = colour / static_cast<float>(std::max(exposure, 1e-9));
  const float lo = static_cast<float>(std::exp(options_.change_dead_zone));
  const float clip = static_cast<float>(options_.change_clip);
  const bool change = frame.type() == CV_8UC3 && !frame.empty();
  const float floor = ShadedLook::ratio_floor();
  // the lobe below a ten-thousandth of its peak is left out (no pow for most pixels)
  const float gloss_from = static_cast<float>(std::pow(1e-4, 1.0 / std::max(1.0, d.source_exponent)));
  const float alpha = static_cast<float>(d.source_exponent);
  // the fitted exponents are whole (4..128 by default): by squaring, not pow
  const int whole_alpha = d.source_exponent == std::floor(d.source_exponent) && d.source_exponent >= 1 &&
                                  d.source_exponent <= 1024
                              ? static_cast<int>(d.source_exponent)
                              : 0;
  const float ax = static_cast<float>(a(0, 0)), bx = static_cast<float>(a(0, 1)), cx = static_cast<float>(a(0, 2));
  const float ay = static_cast<float>(a(1, 0)), by = static_cast<float>(a(1, 1)), cy = static_cast<float>(a(1, 2));
  const float pred_floor = 1e-4f * std::max(s, 1e-6f);
  const int n = static_cast<int>(d.pixel.size());
  uchar* base = out.ptr<uchar>();  // continuous: clone() and create() make it so
  // the dot products as sums of planes (terms x pixels, one row per term): vectorised over the pixels
  auto shade_planes = [](const cv::Mat& planes, const Active& w, int from, int count, float* into) {
    std::fill(into, into + count, 0.f);
    for (size_t k = 0; k < w.at.size(); ++k) {
      const float* p = planes.ptr<float>(w.at[k]) + from;
      const float wk = w.w[k];
      for (int i = 0; i < count; ++i) into[i] += wk * p[i];
    }
  };
  cv::parallel_for_(cv::Range(0, (n + 4095) / 4096), [&](const cv::Range& blocks) {
    std::vector<float> S(4096), P(4096), V(4096, 1.f);
    for (int block = blocks.start; block < blocks.end; ++block) {
      const int from = block * 4096, count = std::min(4096, n - from);
      shade_planes(d.dcoef, wd, from, count, S.data());
      if (!d.dshadow.empty()) d.dshadow.visibility(l, from, count, V.data());  // the light's cast shadows
      if (change) shade_planes(d.scoef, ws, from, count, P.data());
      for (int j = 0; j < count; ++j) {
        const int i = from + j;
        const LiveLookData::Pixel& e = d.px[i];
        const float nl = std::max(0.f, e.normal.dot(lf));
        // off the lamps' elevations: the model at the nearest one times the Lambert ratio
        if (ext) S[j] = std::max(S[j], 0.f) * (nl + ef) / (std::max(0.f, e.normal.dot(lsf)) + ef);
        // as ShadedLook::shade: at most `headroom` x the Lambert model's ratio (and 2)
        const float cap = std::max(2.f, d.headroom * (nl + kModelFloor) * e.inv_model);
        const float ratio = std::min((std::max(S[j], 0.f) * V[j] + floor) * e.inv_median, cap);
        float gloss = 0.f;
        if (d.any_gloss && e.source_gloss > 0 && nl > 0 && V[j] > 0) {
          const float nh = e.normal.dot(h);
          if (nh > gloss_from)
            gloss = V[j] * e.source_gloss * (whole_alpha > 0 ? whole_power(nh, whole_alpha) : std::pow(nh, alpha));
        }
        const cv::Vec3f& t = e.texture;
        const float lit = s * ratio + am * e.inv_model;
        cv::Vec3f v(colour[0] * (t[0] * lit + s * gloss), colour[1] * (t[1] * lit + s * gloss),
                    colour[2] * (t[2] * lit + s * gloss));
        if (change) {
          const LiveLookData::Source& f = d.src[i];
          const cv::Vec2f q = f.xy;
          cv::Vec3f g;
          const float pm = sext ? std::max(P[j], 0.f) * lambert_ratio(f.normal, lf, lssf, d.sspan.floor)
                                : std::max(P[j], 0.f);
          const float pred = s * pm + am * f.albedo;
          if (pred > pred_floor && nearest_frame(frame, d.to_linear, ax * q[0] + bx * q[1] + cx,
                                                 ay * q[0] + by * q[1] + cy, &g)) {
            for (int c = 0; c < 3; ++c) {
              const float pc = pred * f.chroma[c] * frame_colour[c];
              float k = g[c] / std::max(pc, 1e-6f);
              // within the dead zone the model's own error: 1; beyond it what changed, clipped
              k = k > lo ? k / lo : (k * lo < 1.f ? k * lo : 1.f);
              v[c] *= std::clamp(k, 1.f / clip, clip);
            }
          }
        }
        uchar* o = base + static_cast<size_t>(d.pixel[i]) * 3;
        for (int c = 0; c < 3; ++c) o[c] = d.to_srgb[static_cast<int>(std::clamp(v[c], 0.f, 1.f) * kSrgbSteps + 0.5f)];
      }
    }
  });
  return out;
}

cv::Mat LiveLook::paint_linear(const cv::Vec3d& direction) const {
  const LiveLookData& d = *data_;
  cv::Mat out(d.dsize, CV_32FC3, cv::Scalar::all(0));
  const cv::Vec3d l = direction / std::max(1e-12, cv::norm(direction));
  const auto& [ls, ext, wd, lf, lsf, h, ef] = destination_light(d, l);
  const float floor = ShadedLook::ratio_floor();
  const std::vector<float> seen =
      d.dshadow.empty() ? std::vector<float>(d.pixel.size(), 1.f) : d.dshadow.visibility(l);  // the cast shadows
  for (size_t i = 0; i < d.pixel.size(); ++i) {
    const LiveLookData::Pixel& e = d.px[i];
    const float nl = std::max(0.f, e.normal.dot(lf));
    float S = std::max(dot_column(d.dcoef, static_cast<int>(i), wd), 0.f);
    if (ext) S *= (nl + ef) / (std::max(0.f, e.normal.dot(lsf)) + ef);
    S = S * seen[i] + floor;
    const float cap = std::max(2.f, d.headroom * (nl + kModelFloor) * e.inv_model);
    const float ratio = std::min(S * e.inv_median, cap);
    const float gloss =
        e.source_gloss > 0 ? seen[i] * e.source_gloss * Gloss::lobe(e.normal, lf, h, d.source_exponent) : 0.f;
    out.at<cv::Vec3f>(d.pixel[i] / d.dsize.width, d.pixel[i] % d.dsize.width) = e.texture * ratio + cv::Vec3f::all(gloss);
  }
  return out;
}

}  // namespace veneer::repaint
