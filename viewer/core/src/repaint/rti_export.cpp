// PTM 1.2 export of repainted photos (rti_export.hpp).
#include "veneer/repaint/rti_export.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cstring>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>

#include <nlohmann/json.hpp>
#include <opencv2/core/utility.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/repaint/hsh.hpp"

namespace veneer::repaint {
namespace fs = std::filesystem;

namespace {

constexpr int kTerms = 6;

double srgb_encode(double linear) {
  const double v = std::clamp(linear, 0.0, 1.0);
  return v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
}

std::array<double, kTerms> basis(const cv::Vec3d& d) {
  const double u = d[0], v = d[1];
  return {u * u, v * v, u * v, u, v, 1.0};
}

}  // namespace

// The 99.5th percentile of the photos' samples (every 7th, enough for a percentile).
double rti_auto_exposure(const std::vector<cv::Mat>& photos) {
  std::vector<float> samples;
  for (const cv::Mat& p : photos) {
    const size_t n = p.total() * 3;
    const float* data = p.ptr<float>(0);
    for (size_t i = 0; i < n; i += 7) samples.push_back(std::isfinite(data[i]) ? data[i] : 0.0f);
  }
  if (samples.empty()) return 1;
  const size_t k = std::min(samples.size() - 1, static_cast<size_t>(0.995 * static_cast<double>(samples.size())));
  std::nth_element(samples.begin(), samples.begin() + static_cast<long>(k), samples.end());
  return samples[k] > 1e-6f ? 1.0 / samples[k] : 1.0;
}

namespace {

// One term's byte encoding: value = (byte - bias) * scale over [lo, hi] (which holds 0).
struct Quantiser {
  float scale = 1;
  int bias = 0;
  uint8_t encode(float v) const {
    return static_cast<uint8_t>(std::clamp<long>(std::lround(v / scale + bias), 0, 255));
  }
  float decode(uint8_t b) const { return (static_cast<int>(b) - bias) * scale; }
};

Quantiser make_quantiser(float lo, float hi) {
  lo = std::min(lo, 0.0f);
  hi = std::max(hi, 0.0f);
  Quantiser q;
  if (hi - lo < 1e-12f) return q;  // all zero
  q.scale = (hi - lo) / 255.0f;
  q.bias = std::clamp(static_cast<int>(std::lround(-lo / q.scale)), 0, 255);
  // Both ends inside the byte range after rounding the bias.
  if (q.bias < 255) q.scale = std::max(q.scale, hi / static_cast<float>(255 - q.bias));
  if (q.bias > 0) q.scale = std::max(q.scale, -lo / static_cast<float>(q.bias));
  return q;
}

// The residual's figures from what both exporters gather while they check
// what the file stores: per lamp the squared errors' sum (`lamp_sq`), the
// |error| histogram 0.01 level a bin (`hist`), the photos' squared
// spread, over `per_lamp` samples a lamp (pixels x 3 channels).
constexpr int kBins = 25600;  // |error| histogram, 0.01 level per bin
void summarise_residual(const std::vector<double>& lamp_sq, const std::vector<long long>& hist, double spread_sq,
                        double per_lamp, RtiFit& fit) {
  const double n = static_cast<double>(lamp_sq.size());
  double total_sq = 0;
  for (double s : lamp_sq) {
    fit.rms_per_lamp.push_back(std::sqrt(s / per_lamp));
    total_sq += s;
  }
  fit.rms = std::sqrt(total_sq / (per_lamp * n));
  fit.photo_spread = std::sqrt(spread_sq / (per_lamp * n));
  const long long want = static_cast<long long>(std::ceil(0.99 * per_lamp * n));
  long long seen = 0;
  for (int b = 0; b <= kBins; ++b) {
    seen += hist[static_cast<size_t>(b)];
    if (seen >= want) {
      fit.p99 = (b + 1) / 100.0;
      break;
    }
  }
}

}  // namespace

const char* ptm_format_name(PtmFormat f) { return f == PtmFormat::rgb ? "PTM_FORMAT_RGB" : "PTM_FORMAT_LRGB"; }

Status RtiExportOptions::check() const {
  if (!std::isfinite(exposure) || exposure < 0) return make_error("RTI export: exposure must be a finite gain >= 0 (0 = automatic)");
  return Status::success();
}

std::string RtiFit::format_label() const {
  if (hsh_order > 0)
    return "HSH order " + std::to_string(hsh_order) + " (" + std::to_string(hsh_terms(hsh_order)) + " terms)";
  return ptm_format_name(format);
}

Status HshExportOptions::check() const {
  if (order < 0 || order > 3) return make_error("HSH export: order must be 1..3 (0 = automatic)");
  if (!std::isfinite(exposure) || exposure < 0) return make_error("HSH export: exposure must be a finite gain >= 0 (0 = automatic)");
  return Status::success();
}

std::string RtiFit::json() const {
  nlohmann::ordered_json j;
  j["format"] = hsh_order > 0 ? "HSH" : ptm_format_name(format);
  if (hsh_order > 0) {
    j["hsh_order"] = hsh_order;
    j["terms"] = hsh_terms(hsh_order);
  }
  j["width"] = size.width;
  j["height"] = size.height;
  j["exposure"] = exposure;
  j["residual_rms_levels"] = rms;
  j["residual_p99_levels"] = p99;
  j["residual_rms_per_lamp"] = rms_per_lamp;
  j["photo_spread_rms_levels"] = photo_spread;
  return j.dump();
}

cv::Mat ptm_display(const cv::Mat& linear_bgr, double exposure) {
  cv::Mat out(linear_bgr.size(), CV_32FC3);
  for (int y = 0; y < linear_bgr.rows; ++y) {
    const float* s = linear_bgr.ptr<float>(y);
    float* o = out.ptr<float>(y);
    for (int x = 0; x < linear_bgr.cols * 3; ++x)
      o[x] = static_cast<float>(255.0 * srgb_encode(std::isfinite(s[x]) ? s[x] * exposure : 0.0));
  }
  return out;
}

Expected<RtiFit> export_ptm(const std::vector<cv::Mat>& photos, const std::vector<cv::Vec3d>& directions_in,
                            const fs::path& file, const RtiExportOptions& options, const Progress& progress) {
  const std::string name = file.string();
  if (Status s = options.check(); !s) return make_error(name + ": " + s.message());
  if (photos.size() < kTerms)
    return make_error(name + ": a PTM needs at least 6 photos under different lamps, got " + std::to_string(photos.size()));
  if (directions_in.size() != photos.size())
    return make_error(name + ": " + std::to_string(photos.size()) + " photos but " + std::to_string(directions_in.size()) +
                      " lamp directions");
  const cv::Size size = photos[0].size();
  if (size.width < 1 || size.height < 1) return make_error(name + ": empty photos");
  std::vector<cv::Vec3d> dirs;
  for (size_t i = 0; i < photos.size(); ++i) {
    if (photos[i].type() != CV_32FC3 || photos[i].size() != size)
      return make_error(name + ": photo " + std::to_string(i) + " is not a linear CV_32FC3 photo of the first's size");
    const cv::Vec3d& d = directions_in[i];
    const double len = cv::norm(d);
    if (!std::isfinite(len) || len < 1e-6) return make_error(name + ": lamp " + std::to_string(i) + "'s direction is zero or not finite");
    dirs.push_back(d / len);
  }
  const size_t n = photos.size();
  const int w = size.width, h = size.height;
  RtiFit fit;
  fit.size = size;
  fit.format = options.format;
  fit.exposure = options.exposure > 0 ? options.exposure : rti_auto_exposure(photos);
  progress.report(0.0, "fitting PTM");

  // The least-squares solve shared by every pixel: coefficients = P * values.
  cv::Mat A(static_cast<int>(n), kTerms, CV_64F), P;
  for (size_t i = 0; i < n; ++i) {
    const auto b = basis(dirs[i]);
    for (int k = 0; k < kTerms; ++k) A.at<double>(static_cast<int>(i), k) = b[static_cast<size_t>(k)];
  }
  cv::invert(A, P, cv::DECOMP_SVD);  // 6 x n pseudo-inverse (least norm where A is rank deficient)

  std::vector<cv::Mat> display(n);
  cv::parallel_for_(cv::Range(0, static_cast<int>(n)), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) display[static_cast<size_t>(i)] = ptm_display(photos[static_cast<size_t>(i)], fit.exposure);
  });
  if (progress.cancelled()) return make_error(name + ": cancelled");
  progress.report(0.2, "fitting PTM");

  // Unquantised coefficients: per pixel, `planes` x 6 (LRGB: luminance; RGB: r, g, b).
  const int planes = options.format == PtmFormat::rgb ? 3 : 1;
  const size_t pixels = static_cast<size_t>(w) * h;
  std::vector<float> coef(pixels * static_cast<size_t>(planes) * kTerms);
  std::atomic<bool> stop{false};
  cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& r) {
    std::vector<double> values(n);
    for (int y = r.start; y < r.end && !stop; ++y) {
      if (progress.cancelled()) stop = true;
      for (int x = 0; x < w; ++x) {
        const size_t px = static_cast<size_t>(y) * w + x;
        for (int p = 0; p < planes; ++p) {
          for (size_t i = 0; i < n; ++i) {
            const cv::Vec3f t = display[i].at<cv::Vec3f>(y, x);
            // RGB planes in R, G, B order (the Mat is BGR); LRGB: luminance 0..1.
            values[i] = planes == 3 ? t[2 - p] : (t[0] + t[1] + t[2]) / (3.0 * 255.0);
          }
          for (int k = 0; k < kTerms; ++k) {
            const double* pk = P.ptr<double>(k);
            double c = 0;
            for (size_t i = 0; i < n; ++i) c += pk[i] * values[i];
            coef[(px * planes + static_cast<size_t>(p)) * kTerms + static_cast<size_t>(k)] = static_cast<float>(c);
          }
        }
      }
    }
  });
  if (stop || progress.cancelled()) return make_error(name + ": cancelled");
  progress.report(0.6, "fitting PTM");

  std::vector<std::array<double, kTerms>> lamp_basis;
  for (const auto& d : dirs) lamp_basis.push_back(basis(d));
  // LRGB: C = L * colour leaves a per-pixel factor free. The mean of the
  // channels as L would ask more than 255 of a saturated colour's brightest
  // channel; scaling each pixel's L so that its best colour peaks at 255
  // keeps the colour in its byte and gives it all eight bits.
  if (planes == 1) {
    cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& r) {
      for (int y = r.start; y < r.end; ++y)
        for (int x = 0; x < w; ++x) {
          float* a = &coef[(static_cast<size_t>(y) * w + x) * kTerms];
          double ll = 0, lt[3] = {0, 0, 0};
          for (size_t i = 0; i < n; ++i) {
            double l = 0;
            for (int k = 0; k < kTerms; ++k) l += a[k] * lamp_basis[i][static_cast<size_t>(k)];
            const cv::Vec3f t = display[i].at<cv::Vec3f>(y, x);
            ll += l * l;
            for (int c = 0; c < 3; ++c) lt[c] += l * t[c];
          }
          const double peak = ll > 1e-12 ? std::max({lt[0], lt[1], lt[2]}) / ll : 0;
          if (peak > 1e-6)
            for (int k = 0; k < kTerms; ++k) a[k] = static_cast<float>(a[k] * peak / 255.0);
        }
    });
  }

  // One scale and bias per term, over every pixel (and plane).
  std::array<Quantiser, kTerms> q;
  for (int k = 0; k < kTerms; ++k) {
    float lo = 0, hi = 0;
    for (size_t j = static_cast<size_t>(k); j < coef.size(); j += kTerms) {
      lo = std::min(lo, coef[j]);
      hi = std::max(hi, coef[j]);
    }
    q[static_cast<size_t>(k)] = make_quantiser(lo, hi);
  }
  std::vector<uint8_t> bytes(coef.size());
  for (size_t j = 0; j < coef.size(); ++j) bytes[j] = q[j % kTerms].encode(coef[j]);

  // LRGB: the colour that best fits the photos given the stored luminance.
  std::vector<uint8_t> colour(planes == 1 ? pixels * 3 : 0);
  auto evaluate = [&](size_t px, int plane, size_t lamp) {
    double v = 0;
    for (int k = 0; k < kTerms; ++k)
      v += q[static_cast<size_t>(k)].decode(bytes[(px * planes + static_cast<size_t>(plane)) * kTerms + static_cast<size_t>(k)]) *
           lamp_basis[lamp][static_cast<size_t>(k)];
    return v;
  };
  if (planes == 1) {
    cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& r) {
      for (int y = r.start; y < r.end; ++y)
        for (int x = 0; x < w; ++x) {
          const size_t px = static_cast<size_t>(y) * w + x;
          double ll = 0, lt[3] = {0, 0, 0};
          for (size_t i = 0; i < n; ++i) {
            const double l = evaluate(px, 0, i);
            const cv::Vec3f t = display[i].at<cv::Vec3f>(y, x);
            ll += l * l;
            for (int c = 0; c < 3; ++c) lt[c] += l * t[2 - c];
          }
          for (int c = 0; c < 3; ++c)
            colour[px * 3 + static_cast<size_t>(c)] =
                static_cast<uint8_t>(std::clamp<long>(ll > 1e-12 ? std::lround(lt[c] / ll) : 0, 0, 255));
        }
    });
  }
  progress.report(0.8, "fitting PTM");

  // The residual of what the file stores, and the photos' own spread.
  std::vector<double> lamp_sq(n, 0.0);
  std::vector<long long> hist(kBins + 1, 0);
  double spread_sq = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const size_t px = static_cast<size_t>(y) * w + x;
      double mean[3] = {0, 0, 0};
      for (size_t i = 0; i < n; ++i) {
        const cv::Vec3f t = display[i].at<cv::Vec3f>(y, x);
        for (int c = 0; c < 3; ++c) mean[c] += t[2 - c] / static_cast<double>(n);
      }
      for (size_t i = 0; i < n; ++i) {
        const cv::Vec3f t = display[i].at<cv::Vec3f>(y, x);
        const double l = planes == 1 ? evaluate(px, 0, i) : 0;
        for (int c = 0; c < 3; ++c) {
          const double v = planes == 1 ? l * colour[px * 3 + static_cast<size_t>(c)] : evaluate(px, c, i);
          const double e = std::clamp(v, 0.0, 255.0) - t[2 - c];
          lamp_sq[i] += e * e;
          hist[static_cast<size_t>(std::min<double>(kBins, std::abs(e) * 100))]++;
          spread_sq += (t[2 - c] - mean[c]) * (t[2 - c] - mean[c]);
        }
      }
    }
  const double per_lamp = static_cast<double>(pixels) * 3;
  summarise_residual(lamp_sq, hist, spread_sq, per_lamp, fit);

  // The file: five header lines, then the bytes, rows bottom to top.
  std::string out = "PTM_1.2\n" + std::string(ptm_format_name(options.format)) + "\n" + std::to_string(w) + " " +
                    std::to_string(h) + "\n";
  char buf[64];
  for (int k = 0; k < kTerms; ++k) {
    std::snprintf(buf, sizeof buf, "%s%.9g", k ? " " : "", static_cast<double>(q[static_cast<size_t>(k)].scale));
    out += buf;
  }
  out += "\n";
  for (int k = 0; k < kTerms; ++k) {  // appended piece by piece: GCC 12's -Wrestrict misreads "..." + string&& (ASan build)
    if (k) out += ' ';
    out += std::to_string(q[static_cast<size_t>(k)].bias);
  }
  out += "\n";
  const size_t header = out.size();
  out.resize(header + bytes.size() + colour.size());
  char* dst = out.data() + header;
  for (int p = 0; p < planes; ++p)
    for (int y = h - 1; y >= 0; --y)
      for (int x = 0; x < w; ++x) {
        const size_t px = static_cast<size_t>(y) * w + x;
        for (int k = 0; k < kTerms; ++k) *dst++ = static_cast<char>(bytes[(px * planes + static_cast<size_t>(p)) * kTerms + static_cast<size_t>(k)]);
      }
  for (int y = h - 1; y >= 0 && planes == 1; --y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) *dst++ = static_cast<char>(colour[(static_cast<size_t>(y) * w + x) * 3 + static_cast<size_t>(c)]);
  if (progress.cancelled()) return make_error(name + ": cancelled");
  if (Status s = io::write_file_atomic(file, out); !s) return s.error();
  progress.report(1.0, "fitting PTM");
  return fit;
}

Expected<RtiFit> export_hsh(const std::vector<cv::Mat>& photos, const std::vector<cv::Vec3d>& directions,
                            const fs::path& file, const HshExportOptions& options, const Progress& progress) {
  static_assert(std::endian::native == std::endian::little, "the HSH file's floats are written as the host holds them");
  const std::string name = file.string();
  if (Status s = options.check(); !s) return make_error(name + ": " + s.message());
  if (photos.empty() || directions.empty()) return make_error(name + ": HSH fit: no lamps (no photos or no lamp directions)");
  for (size_t i = 0; i < photos.size(); ++i)
    if (photos[i].type() != CV_32FC3 || photos[i].size() != photos[0].size() || photos[i].empty())
      return make_error(name + ": photo " + std::to_string(i) + " is not a linear CV_32FC3 photo of the first's size");
  const int order = options.order > 0 ? options.order : hsh_order_for(photos.size());
  RtiFit fit;
  fit.size = photos[0].size();
  fit.hsh_order = order;
  fit.exposure = options.exposure > 0 ? options.exposure : rti_auto_exposure(photos);
  progress.report(0.0, "fitting HSH");
  // the photos as the file shows them, 0..1 (BGR)
  const size_t n = photos.size();
  std::vector<cv::Mat> display(n);
  cv::parallel_for_(cv::Range(0, static_cast<int>(n)), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i)
      display[static_cast<size_t>(i)] = ptm_display(photos[static_cast<size_t>(i)], fit.exposure) / 255.0;
  });
  if (progress.cancelled()) return make_error(name + ": cancelled");
  auto hsh = fit_hsh(display, directions, order);
  if (!hsh) return make_error(name + ": " + hsh.message());
  progress.report(0.5, "fitting HSH");
  const int terms = hsh_terms(order);
  const int w = fit.size.width, h = fit.size.height;

  // One scale and bias per term over every pixel and colour: coefficient = byte / 255 * scale + bias.
  std::vector<float> scale(static_cast<size_t>(terms)), bias(static_cast<size_t>(terms));
  for (int k = 0; k < terms; ++k) {
    float lo = std::numeric_limits<float>::max(), hi = std::numeric_limits<float>::lowest();
    for (const cv::Mat& c : hsh->coefficients)
      for (int y = 0; y < h; ++y) {
        const float* p = c.ptr<float>(y);
        for (int x = 0; x < w; ++x) {
          lo = std::min(lo, p[x * terms + k]);
          hi = std::max(hi, p[x * terms + k]);
        }
      }
    bias[static_cast<size_t>(k)] = lo;
    scale[static_cast<size_t>(k)] = hi - lo > 1e-12f ? hi - lo : 1.0f;
  }
  // bytes[((y * w + x) * 3 + colour) * terms + k], colour 0 = R (the Mats are B, G, R)
  std::vector<uint8_t> bytes(static_cast<size_t>(w) * h * 3 * static_cast<size_t>(terms));
  cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y)
      for (int colour = 0; colour < 3; ++colour) {
        const float* p = hsh->coefficients[static_cast<size_t>(2 - colour)].ptr<float>(y);
        for (int x = 0; x < w; ++x)
          for (int k = 0; k < terms; ++k) {
            const float v = (p[x * terms + k] - bias[static_cast<size_t>(k)]) / scale[static_cast<size_t>(k)] * 255.0f;
            bytes[((static_cast<size_t>(y) * w + x) * 3 + static_cast<size_t>(colour)) * terms + static_cast<size_t>(k)] =
                static_cast<uint8_t>(std::clamp<long>(std::lround(v), 0, 255));
          }
      }
  });
  if (progress.cancelled()) return make_error(name + ": cancelled");
  progress.report(0.7, "fitting HSH");

  // The residual of what the file stores, and the photos' own spread, in 8-bit levels.
  std::vector<std::vector<double>> lamp_basis;
  for (const auto& d : directions) lamp_basis.push_back(hsh_basis(d, order));
  std::vector<double> lamp_sq(n, 0.0);
  std::vector<long long> hist(kBins + 1, 0);
  double spread_sq = 0;
  std::vector<double> coef(static_cast<size_t>(terms));
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int colour = 0; colour < 3; ++colour) {
        const uint8_t* b = &bytes[((static_cast<size_t>(y) * w + x) * 3 + static_cast<size_t>(colour)) * terms];
        for (int k = 0; k < terms; ++k)
          coef[static_cast<size_t>(k)] = b[k] / 255.0 * scale[static_cast<size_t>(k)] + bias[static_cast<size_t>(k)];
        double mean = 0;
        for (size_t i = 0; i < n; ++i) mean += display[i].at<cv::Vec3f>(y, x)[2 - colour] * 255.0 / static_cast<double>(n);
        for (size_t i = 0; i < n; ++i) {
          double v = 0;
          for (int k = 0; k < terms; ++k) v += coef[static_cast<size_t>(k)] * lamp_basis[i][static_cast<size_t>(k)];
          const double t = display[i].at<cv::Vec3f>(y, x)[2 - colour] * 255.0;
          const double e = std::clamp(v, 0.0, 1.0) * 255.0 - t;
          lamp_sq[i] += e * e;
          hist[static_cast<size_t>(std::min<double>(kBins, std::abs(e) * 100))]++;
          spread_sq += (t - mean) * (t - mean);
        }
      }
  const double per_lamp = static_cast<double>(w) * h * 3;
  summarise_residual(lamp_sq, hist, spread_sq, per_lamp, fit);
  progress.report(0.9, "fitting HSH");

  std::string out = "#HSH1.2\n3\n" + std::to_string(w) + " " + std::to_string(h) + " 3\n" + std::to_string(terms) + " 2 1\n";
  const size_t header = out.size();
  out.resize(header + 2 * sizeof(float) * static_cast<size_t>(terms) + bytes.size());
  char* dst = out.data() + header;
  std::memcpy(dst, scale.data(), sizeof(float) * scale.size());
  dst += sizeof(float) * scale.size();
  std::memcpy(dst, bias.data(), sizeof(float) * bias.size());
  dst += sizeof(float) * bias.size();
  const size_t row = static_cast<size_t>(w) * 3 * static_cast<size_t>(terms);
  // rows top to bottom: RTIViewer (Hsh::loadData) shows file row j as image row j from the top, and Relight
  // (LRti::loadHSH) reads and writes them so; a PTM's rows go the other way (export_ptm)
  for (int y = 0; y < h; ++y, dst += row) std::memcpy(dst, &bytes[static_cast<size_t>(y) * row], row);
  if (progress.cancelled()) return make_error(name + ": cancelled");
  if (Status s = io::write_file_atomic(file, out); !s) return s.error();
  progress.report(1.0, "fitting HSH");
  return fit;
}

}  // namespace veneer::repaint
