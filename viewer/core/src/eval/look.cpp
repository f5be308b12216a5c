// The look of a transfer (look.hpp): a port of shared/tools/look.py.
#include "veneer/eval/look.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <mutex>
#include <sstream>

#include "veneer/io/codecs.hpp"
#include <opencv2/imgproc.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"

namespace veneer::eval {
namespace fs = std::filesystem;

namespace {

constexpr float kEps = 1e-6f;       // look.py's eps
constexpr float kLitShare = 0.05f;  // lit: above this share of the pixel's brightest sample
constexpr double kHighPassSigma = 3.0;  // px
constexpr int kErodeSide = 7;           // the mask eroded by 3 px

// Order statistics of the errors without holding them all (a full-resolution
// set is ~250 M pixel-lamp pairs): a first pass counts them into bins, a
// second keeps only the values of the bins that hold the ranks wanted.
constexpr int kBins = 1 << 16;
constexpr double kBinRange = 16.0;  // errors at or past it share the last bin
int bin_of(double e) { return std::min(kBins - 1, static_cast<int>(e * (kBins / kBinRange))); }

struct ShadingInputs {
  const std::vector<cv::Mat>* result;
  const std::vector<cv::Mat>* reference;
  cv::Mat mask;  // CV_8UC1 or empty
  cv::Mat rm, rx, dm, dx;  // medians and maxima over the lamps
  cv::Mat log_rm, log_dm;  // log(median + eps), where compared
};

cv::Mat log_of(const cv::Mat& median, const cv::Mat& mask) {
  cv::Mat out(median.size(), CV_32FC1, cv::Scalar(0));
  for (int y = 0; y < median.rows; ++y) {
    const float* m = median.ptr<float>(y);
    const uchar* k = mask.empty() ? nullptr : mask.ptr<uchar>(y);
    float* o = out.ptr<float>(y);
    for (int x = 0; x < median.cols; ++x)
      if (!k || k[x]) o[x] = std::log(m[x] + kEps);
  }
  return out;
}

// A pixel's grey: the mean of its channels (CV_32FC3 photos are read in
// place, never copied to grey: a grey copy of a set is a third of its frames).
inline float grey_at(const float* row, int x, int channels) {
  return channels == 3 ? (row[3 * x] + row[3 * x + 1] + row[3 * x + 2]) * (1.0f / 3) : row[x];
}

cv::Mat max_image(const std::vector<cv::Mat>& photos, const cv::Mat& mask) {
  cv::Mat out(photos[0].size(), CV_32FC1, cv::Scalar(0));
  const int channels = photos[0].channels();
  cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      const uchar* k = mask.empty() ? nullptr : mask.ptr<uchar>(y);
      float* o = out.ptr<float>(y);
      for (const cv::Mat& p : photos) {
        const float* row = p.ptr<float>(y);
        for (int x = 0; x < out.cols; ++x)
          if (!k || k[x]) o[x] = std::max(o[x], grey_at(row, x, channels));
      }
    }
  });
  return out;
}

// Calls f(row stripe index, error) for every lit pixel-lamp pair of rows [r0, r1).
template <class F>
void for_each_error(const ShadingInputs& in, int r0, int r1, F&& f) {
  const size_t lamps = in.result->size();
  const int rc = (*in.result)[0].channels(), dc = (*in.reference)[0].channels();
  for (int y = r0; y < r1; ++y) {
    const uchar* mk = in.mask.empty() ? nullptr : in.mask.ptr<uchar>(y);
    const float *rm = in.rm.ptr<float>(y), *rx = in.rx.ptr<float>(y), *dm = in.dm.ptr<float>(y),
                *dx = in.dx.ptr<float>(y), *lrm = in.log_rm.ptr<float>(y), *ldm = in.log_dm.ptr<float>(y);
    for (size_t l = 0; l < lamps; ++l) {
      const float* r = (*in.result)[l].ptr<float>(y);
      const float* d = (*in.reference)[l].ptr<float>(y);
      for (int x = 0; x < in.rm.cols; ++x) {
        if (mk && !mk[x]) continue;
        const float rv = grey_at(r, x, rc), dv = grey_at(d, x, dc);
        if (!(dv > kLitShare * dx[x] && rv > kLitShare * rx[x] && dm[x] > kEps && rm[x] > kEps)) continue;
        // in float, as look.py's numpy computes it
        f(static_cast<double>(std::abs((std::log(rv + kEps) - lrm[x]) - (std::log(dv + kEps) - ldm[x]))));
      }
    }
  }
}

Status check_images(const std::vector<cv::Mat>& images, cv::Size size, const char* what) {
  for (size_t i = 0; i < images.size(); ++i)
    if (images[i].size() != size)
      return make_error(std::string(what) + " " + std::to_string(i) + " is " + std::to_string(images[i].cols) + "x" +
                        std::to_string(images[i].rows) + ", not " + std::to_string(size.width) + "x" +
                        std::to_string(size.height));
  return {};
}

// The photos as the figures read them: CV_32FC3 ones as they are (every one
// of them), anything else in grey.
std::vector<cv::Mat> readable(const std::vector<cv::Mat>& images) {
  const bool colour = std::all_of(images.begin(), images.end(), [](const cv::Mat& m) { return m.type() == CV_32FC3; });
  if (colour) return images;
  std::vector<cv::Mat> g(images.size());
  cv::parallel_for_(cv::Range(0, static_cast<int>(images.size())), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) g[i] = look_gray(images[i]);
  });
  return g;
}

// numpy's linear interpolation between order statistics: the value at
// fractional rank q * (n - 1) of the sorted values, given value(rank).
template <class V>
double quantile(long long n, double q, V&& value) {
  const double idx = q * static_cast<double>(n - 1);
  const long long lo = static_cast<long long>(std::floor(idx));
  const long long hi = std::min(lo + 1, n - 1);
  const double a = value(lo), b = value(hi);
  return a + (b - a) * (idx - static_cast<double>(lo));
}

cv::Mat object_mask(const cv::Mat& mask, cv::Size size, Status& status) {
  if (mask.empty()) return {};
  if (mask.size() != size || mask.type() != CV_8UC1) {
    status = make_error("the mask must be 8-bit, one channel, " + std::to_string(size.width) + "x" +
                        std::to_string(size.height));
    return {};
  }
  return mask;
}

}  // namespace

cv::Mat look_gray(const cv::Mat& image) {
  if (image.type() == CV_32FC1) return image;  // already one: shared, not copied
  cv::Mat f;
  image.convertTo(f, CV_32F);
  if (f.channels() == 1) return f;
  cv::Mat g;
  cv::transform(f, g, cv::Mat(1, f.channels(), CV_32F, cv::Scalar(1.0 / f.channels())));
  return g;
}

cv::Mat median_image(const std::vector<cv::Mat>& gray) { return median_image(gray, cv::Mat()); }

cv::Mat median_image(const std::vector<cv::Mat>& gray, const cv::Mat& mask) {
  if (gray.empty()) return {};
  const int n = static_cast<int>(gray.size());
  cv::Mat out(gray[0].size(), CV_32FC1, cv::Scalar(0));
  cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& rows) {
    std::vector<float> v(n);
    std::vector<const float*> p(n);
    const bool colour = gray[0].type() == CV_32FC3;  // look_gray's mean, pixel by pixel
    for (int y = rows.start; y < rows.end; ++y) {
      for (int i = 0; i < n; ++i) p[i] = gray[i].ptr<float>(y);
      float* o = out.ptr<float>(y);
      const uchar* m = mask.empty() ? nullptr : mask.ptr<uchar>(y);
      for (int x = 0; x < out.cols; ++x) {
        if (m && !m[x]) continue;
        if (colour) {
          for (int i = 0; i < n; ++i) v[i] = (p[i][3 * x] + p[i][3 * x + 1] + p[i][3 * x + 2]) * (1.0f / 3);
        } else {
          for (int i = 0; i < n; ++i) v[i] = p[i][x];
        }
        const int h = n / 2;
        std::nth_element(v.begin(), v.begin() + h, v.end());
        if (n % 2) {
          o[x] = v[h];
        } else {
          const float below = *std::max_element(v.begin(), v.begin() + h);
          o[x] = (below + v[h]) * 0.5f;
        }
      }
    }
  });
  return out;
}

// Checks a result against its reference (one picture per lamp, one size) and
// fills `in` with what every shading measure compares: the pictures as
// readable grey (`r`, `d`, which `in` points at), the mask, the medians and
// maxima over the lamps and the medians' logs (only where compared).
Status prepare_shading(const std::vector<cv::Mat>& result, const std::vector<cv::Mat>& reference, const cv::Mat& mask,
                       std::vector<cv::Mat>& r, std::vector<cv::Mat>& d, ShadingInputs& in) {
  if (result.size() != reference.size())
    return make_error(std::to_string(result.size()) + " result pictures for " + std::to_string(reference.size()) +
                      " lamps");
  if (result.empty()) return make_error("no lamp to compare");
  const cv::Size size = reference[0].size();
  if (Status s = check_images(reference, size, "reference photo"); !s) return s;
  if (Status s = check_images(result, size, "result picture"); !s) return s;
  Status status;
  in.mask = object_mask(mask, size, status);
  if (!status) return status;
  r = readable(result);
  d = readable(reference);
  in.result = &r;
  in.reference = &d;
  in.rm = median_image(r, in.mask);
  in.dm = median_image(d, in.mask);
  in.log_rm = log_of(in.rm, in.mask);
  in.log_dm = log_of(in.dm, in.mask);
  in.rx = max_image(r, in.mask);
  in.dx = max_image(d, in.mask);
  return Status::success();
}

Expected<ShadingError> shading_error(const std::vector<cv::Mat>& result, const std::vector<cv::Mat>& reference,
                                     const cv::Mat& mask) {
  std::vector<cv::Mat> r, d;
  ShadingInputs in;
  if (Status s = prepare_shading(result, reference, mask, r, d, in); !s) return s.error();
  const cv::Size size = reference[0].size();

  const int stripes = std::min(size.height, 16);
  auto stripe_rows = [&](int s) { return std::pair(size.height * s / stripes, size.height * (s + 1) / stripes); };
  // Pass 1: count, sum, histogram.
  std::vector<long long> counts(kBins, 0);
  long long n = 0;
  double sum = 0;
  std::mutex merge;
  cv::parallel_for_(cv::Range(0, stripes), [&](const cv::Range& range) {
    std::vector<long long> h(kBins, 0);
    long long c = 0;
    double s = 0;
    for (int i = range.start; i < range.end; ++i) {
      const auto [r0, r1] = stripe_rows(i);
      for_each_error(in, r0, r1, [&](double e) {
        ++h[bin_of(e)];
        ++c;
        s += e;
      });
    }
    std::lock_guard lock(merge);
    for (int b = 0; b < kBins; ++b) counts[b] += h[b];
    n += c;
    sum += s;
  });
  if (n == 0) return make_error("no lit pixel to compare");

  // The ranks the median and the 90th percentile interpolate between, and their bins.
  std::vector<long long> start(kBins + 1, 0);
  for (int b = 0; b < kBins; ++b) start[b + 1] = start[b] + counts[b];
  auto bin_of_rank = [&](long long rank) {
    return static_cast<int>(std::upper_bound(start.begin(), start.end(), rank) - start.begin()) - 1;
  };
  std::vector<int> wanted;
  for (double q : {0.5, 0.9}) {
    const long long lo = static_cast<long long>(std::floor(q * static_cast<double>(n - 1)));
    for (long long rank : {lo, std::min(lo + 1, n - 1)}) wanted.push_back(bin_of_rank(rank));
  }
  std::sort(wanted.begin(), wanted.end());
  wanted.erase(std::unique(wanted.begin(), wanted.end()), wanted.end());
  // Pass 2: the values of those bins.
  std::vector<std::vector<double>> values(wanted.size());
  cv::parallel_for_(cv::Range(0, stripes), [&](const cv::Range& range) {
    std::vector<std::vector<double>> v(wanted.size());
    for (int i = range.start; i < range.end; ++i) {
      const auto [r0, r1] = stripe_rows(i);
      for_each_error(in, r0, r1, [&](double e) {
        const auto it = std::lower_bound(wanted.begin(), wanted.end(), bin_of(e));
        if (it != wanted.end() && *it == bin_of(e)) v[it - wanted.begin()].push_back(e);
      });
    }
    std::lock_guard lock(merge);
    for (size_t k = 0; k < v.size(); ++k) values[k].insert(values[k].end(), v[k].begin(), v[k].end());
  });
  for (auto& v : values) std::sort(v.begin(), v.end());
  auto value = [&](long long rank) {
    const int b = bin_of_rank(rank);
    const size_t k = std::lower_bound(wanted.begin(), wanted.end(), b) - wanted.begin();
    return values[k][static_cast<size_t>(rank - start[b])];
  };
  ShadingError out;
  out.samples = n;
  out.mean = sum / static_cast<double>(n);
  out.median = quantile(n, 0.5, value);
  out.p90 = quantile(n, 0.9, value);
  return out;
}

Expected<std::vector<ShadingError>> shading_error_per_lamp(const std::vector<cv::Mat>& result,
                                                          const std::vector<cv::Mat>& reference, const cv::Mat& mask) {
  std::vector<cv::Mat> r, d;
  ShadingInputs in;
  if (Status s = prepare_shading(result, reference, mask, r, d, in); !s) return s.error();
  const cv::Size size = reference[0].size();
  // One lamp at a time: its errors are one picture's lit pixels, few enough to hold.
  std::vector<ShadingError> out(result.size());
  cv::parallel_for_(cv::Range(0, static_cast<int>(result.size())), [&](const cv::Range& lamps) {
    for (int l = lamps.start; l < lamps.end; ++l) {
      const std::vector<cv::Mat> one_r{r[static_cast<size_t>(l)]}, one_d{d[static_cast<size_t>(l)]};
      ShadingInputs lamp = in;
      lamp.result = &one_r;
      lamp.reference = &one_d;
      std::vector<double> e;
      for_each_error(lamp, 0, size.height, [&](double v) { e.push_back(v); });
      ShadingError& s = out[static_cast<size_t>(l)];
      s.samples = static_cast<long long>(e.size());
      if (e.empty()) continue;
      std::sort(e.begin(), e.end());
      double sum = 0;
      for (double v : e) sum += v;
      s.mean = sum / static_cast<double>(e.size());
      auto value = [&](long long rank) { return e[static_cast<size_t>(rank)]; };
      s.median = quantile(s.samples, 0.5, value);
      s.p90 = quantile(s.samples, 0.9, value);
    }
  });
  return out;
}

Expected<double> texture_corr(const cv::Mat& result_median, const cv::Mat& source_median, const cv::Mat& map_xy,
                              const cv::Mat& mask) {
  const cv::Size size = result_median.size();
  if (map_xy.size() != size || map_xy.depth() != CV_32F || map_xy.channels() < 2)
    return make_error("the map must be float with source x, y, the result median's size (" +
                      std::to_string(size.width) + "x" + std::to_string(size.height) + ")");
  if (source_median.empty()) return make_error("no source median photo");
  Status status;
  const cv::Mat object = object_mask(mask, size, status);
  if (!status) return status.error();
  const cv::Mat med = look_gray(result_median), src = look_gray(source_median);
  const int channels = map_xy.channels();
  // ok: in the mask and mapped; W: the source's median warped through the map, nearest pixel.
  cv::Mat ok(size, CV_8UC1, cv::Scalar(0)), warped(size, CV_32FC1, cv::Scalar(0));
  for (int y = 0; y < size.height; ++y) {
    const float* m = map_xy.ptr<float>(y);
    for (int x = 0; x < size.width; ++x) {
      const float mx = m[x * channels], my = m[x * channels + 1];
      if ((!object.empty() && !object.at<uchar>(y, x)) || !(mx >= 0 && my >= 0)) continue;
      ok.at<uchar>(y, x) = 1;
      const int xi = std::clamp(static_cast<int>(std::nearbyint(mx)), 0, src.cols - 1);
      const int yi = std::clamp(static_cast<int>(std::nearbyint(my)), 0, src.rows - 1);
      warped.at<float>(y, x) = src.at<float>(yi, xi);
    }
  }
  // look.py's floor of the logs: 1e-3 of each picture's brightest value
  double top_med = 0, top_warped = 0;
  cv::minMaxLoc(med, nullptr, &top_med);
  cv::minMaxLoc(warped, nullptr, &top_warped);
  // The rest within the mapped pixels' bounds and a margin wider than the
  // Gaussian's reach (12 px) and the erosion's: the same figures as over the
  // whole picture (zeros around the object either way), for the object's area
  // (the bull is 3 % of its frame).
  const int margin = 16;
  const cv::Rect bounds = cv::boundingRect(ok);
  if (bounds.empty()) return make_error("no mapped pixel left 3 px inside the mask");
  const cv::Rect roi = (bounds + cv::Size(2 * margin, 2 * margin) - cv::Point(margin, margin)) & cv::Rect(cv::Point(), size);
  const cv::Mat ok_roi = ok(roi);
  cv::Mat okf, weight;
  ok_roi.convertTo(okf, CV_32F);
  cv::GaussianBlur(okf, weight, cv::Size(0, 0), kHighPassSigma);
  cv::max(weight, 1e-6, weight);
  auto high_pass = [&](const cv::Mat& im, double top) {
    const float floor = static_cast<float>(1e-3 * std::max(top, 1e-6));
    cv::Mat lg(roi.size(), CV_32FC1, cv::Scalar(0));
    for (int y = 0; y < roi.height; ++y)
      for (int x = 0; x < roi.width; ++x)
        if (ok_roi.at<uchar>(y, x)) lg.at<float>(y, x) = std::log(im.at<float>(y, x) + floor);
    cv::Mat blurred;
    cv::GaussianBlur(lg, blurred, cv::Size(0, 0), kHighPassSigma);
    return cv::Mat(lg - blurred / weight);
  };
  cv::Mat inner;
  cv::erode(ok_roi, inner, cv::Mat::ones(kErodeSide, kErodeSide, CV_8U));
  const cv::Mat a = high_pass(med(roi), top_med), b = high_pass(warped(roi), top_warped);
  const int count = cv::countNonZero(inner);
  if (count == 0) return make_error("no mapped pixel left 3 px inside the mask");
  const double ma = cv::mean(a, inner)[0], mb = cv::mean(b, inner)[0];
  double ab = 0, aa = 0, bb = 0;
  for (int y = 0; y < roi.height; ++y)
    for (int x = 0; x < roi.width; ++x) {
      if (!inner.at<uchar>(y, x)) continue;
      const double u = a.at<float>(y, x) - ma, v = b.at<float>(y, x) - mb;
      ab += u * v;
      aa += u * u;
      bb += v * v;
    }
  return ab / std::max(std::sqrt(aa * bb), 1e-12);
}

Expected<std::vector<cv::Mat>> look_photos(const fs::path& set_folder) {
  std::vector<fs::path> files;
  if (fs::exists(set_folder / "filenames.txt")) {
    std::ifstream in(set_folder / "filenames.txt");
    std::string name;
    while (in >> name) files.push_back(set_folder / name);
  } else {
    auto text = io::read_file_bytes(set_folder / "set.json");
    if (!text) return text.error();
    auto manifest = io::parse_manifest(*text, set_folder);
    if (!manifest) return manifest.error();
    for (const fs::path& f : manifest->image_files) files.push_back(set_folder / f);
  }
  if (files.empty()) return make_error(set_folder.string() + ": no photos listed");
  std::vector<cv::Mat> photos(files.size());
  std::vector<std::string> errors(files.size());
  cv::parallel_for_(cv::Range(0, static_cast<int>(files.size())), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) {
      auto im = io::read_linear_image(files[i]);
      if (im) photos[i] = look_gray(*im);
      else errors[i] = im.message();
    }
  });
  for (const std::string& e : errors)
    if (!e.empty()) return make_error(e);
  return photos;
}

Expected<Look> look_folders(const fs::path& transfer_out, const fs::path& reference_set, const fs::path& source_set) {
  auto reference = look_photos(reference_set);
  if (!reference) return reference.error();
  std::vector<fs::path> files;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(transfer_out, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("result_light_", 0) == 0 && entry.path().extension() == ".png") files.push_back(entry.path());
  }
  if (ec) return make_error(transfer_out.string() + ": " + ec.message());
  std::sort(files.begin(), files.end());
  if (files.size() != reference->size())
    return make_error(std::to_string(files.size()) + " result pictures for " + std::to_string(reference->size()) +
                      " lamps");
  std::vector<cv::Mat> result(files.size());
  for (size_t i = 0; i < files.size(); ++i) {
    auto im = io::read_linear_image(files[i]);
    if (!im) return im.error();
    result[i] = look_gray(*im);
  }
  cv::Mat mask;
  if (fs::exists(reference_set / "mask.png")) {
    const cv::Mat m = veneer::io::codecs::imread((reference_set / "mask.png").string(), cv::IMREAD_GRAYSCALE);
    if (m.empty()) return make_error((reference_set / "mask.png").string() + ": cannot be read");
    mask = m > 127;
  }
  Look look;
  auto shading = shading_error(result, *reference, mask);
  if (!shading) return shading.error();
  look.shading = *shading;
  if (!source_set.empty()) {
    auto source = look_photos(source_set);
    if (!source) return source.error();
    auto median = io::read_linear_image(transfer_out / "result_median.png");
    if (!median) return median.error();
    auto map = io::read_pfm(transfer_out / "map.pfm", /*xyz_order=*/true);
    if (!map) return map.error();
    auto corr = texture_corr(*median, median_image(*source), *map, mask);
    if (!corr) return corr.error();
    look.texture_corr = *corr;
  }
  return look;
}

std::string look_json(const Look& look) {
  std::ostringstream o;
  o.precision(17);
  o << "{\"shading_mean\": " << look.shading.mean << ", \"shading_median\": " << look.shading.median
    << ", \"shading_p90\": " << look.shading.p90 << ", \"samples\": " << look.shading.samples;
  if (look.texture_corr) o << ", \"texture_corr\": " << *look.texture_corr;
  o << "}";
  return o.str();
}

}  // namespace veneer::eval
