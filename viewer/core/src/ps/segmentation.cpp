// Segmentation of the object (see segmentation.hpp).
#include "veneer/ps/segmentation.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace veneer::ps {

const char* segment_method_name(SegmentMethod m) {
  switch (m) {
    case SegmentMethod::automatic: return "automatic";
    case SegmentMethod::supplied: return "supplied";
    case SegmentMethod::threshold: return "threshold";
    case SegmentMethod::otsu: return "otsu";
    case SegmentMethod::none: return "none";
  }
  return "automatic";
}

Expected<SegmentMethod> parse_segment_method(const std::string& s) {
  for (SegmentMethod m : {SegmentMethod::automatic, SegmentMethod::supplied, SegmentMethod::threshold,
                          SegmentMethod::otsu, SegmentMethod::none})
    if (s == segment_method_name(m)) return m;
  return make_error("unknown segmentation method '" + s + "' (automatic, supplied, threshold, otsu, none)");
}

Status SegmentOptions::check() const {
  if (!(threshold >= 0 && threshold < 1)) return make_error("threshold must be in [0, 1), got " + std::to_string(threshold));
  if (rect && (rect->width <= 0 || rect->height <= 0))
    return make_error("the rectangle must have a positive width and height");
  if (open_radius < 0 || open_radius > 50) return make_error("open_radius must be in 0..50, got " + std::to_string(open_radius));
  if (!(min_component_fraction >= 0 && min_component_fraction < 1))
    return make_error("min_component_fraction must be in [0, 1), got " + std::to_string(min_component_fraction));
  if (!(max_hole_fraction >= 0 && max_hole_fraction < 1))
    return make_error("max_hole_fraction must be in [0, 1), got " + std::to_string(max_hole_fraction));
  return Status::success();
}

namespace {

// Mean grey intensity over the lamps, ambient removed.
cv::Mat summed_intensity(const ImageSet& set, bool subtract_ambient) {
  const cv::Size size = set.images[0].size();
  cv::Mat acc(size, CV_32FC3, cv::Scalar::all(0));
  for (const cv::Mat& im : set.images) cv::add(acc, im, acc);
  if (subtract_ambient && !set.ambient.empty() && set.ambient.size() == size && set.ambient.type() == CV_32FC3)
    cv::scaleAdd(set.ambient, -double(set.images.size()), acc, acc);
  cv::Mat grey(size, CV_32FC1);
  const float s = 1.f / (3.f * set.images.size());
  for (int y = 0; y < size.height; ++y) {
    const cv::Vec3f* a = acc.ptr<cv::Vec3f>(y);
    float* g = grey.ptr<float>(y);
    for (int x = 0; x < size.width; ++x) g[x] = std::max(0.f, (a[x][0] + a[x][1] + a[x][2]) * s);
  }
  return grey;
}

// Otsu's threshold on the logarithm of a float image (values >= 0, floored at
// 1e-3 of full scale): the dim limb of a bright object sits far above a dark
// table on a log scale, while on a linear one Otsu cuts into the object.
double otsu(const cv::Mat& img) {
  constexpr float floor_v = 1e-3f;
  double maxv = 0;
  cv::minMaxLoc(img, nullptr, &maxv);
  if (!(maxv > floor_v)) return maxv;
  const double lo = std::log(double(floor_v)), hi = std::log(maxv);
  const int bins = 1024;
  std::vector<double> hist(bins, 0.0);
  const double sc = (bins - 1) / (hi - lo);
  for (int y = 0; y < img.rows; ++y) {
    const float* p = img.ptr<float>(y);
    for (int x = 0; x < img.cols; ++x)
      hist[std::clamp(int((std::log(std::max(p[x], floor_v)) - lo) * sc), 0, bins - 1)] += 1;
  }
  double total = double(img.total()), sum = 0;
  for (int i = 0; i < bins; ++i) sum += i * hist[i];
  double w0 = 0, sum0 = 0, best = -1;
  int best_i = 0;
  for (int i = 0; i < bins; ++i) {
    w0 += hist[i];
    sum0 += i * hist[i];
    const double w1 = total - w0;
    if (w0 <= 0 || w1 <= 0) continue;
    const double m0 = sum0 / w0, m1 = (sum - sum0) / w1;
    const double between = w0 * w1 * (m0 - m1) * (m0 - m1);
    if (between > best) {
      best = between;
      best_i = i;
    }
  }
  return std::exp(lo + (best_i + 1) / sc);  // object: value >= threshold
}

}  // namespace

cv::Mat clean_mask(const cv::Mat& mask_in, const SegmentOptions& options) {
  cv::Mat mask = mask_in.clone();
  if (options.open_radius > 0) {
    const int r = options.open_radius;
    cv::Mat k = cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * r + 1, 2 * r + 1));
    cv::morphologyEx(mask, mask, cv::MORPH_OPEN, k);
  }
  const double area = double(mask.total());
  cv::Mat labels, stats, centroids;
  // Specks: object components below the minimum area.
  const int nl = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);
  const double min_area = options.min_component_fraction * area;
  std::vector<uint8_t> keep(nl, 0);
  for (int l = 1; l < nl; ++l) keep[l] = stats.at<int>(l, cv::CC_STAT_AREA) >= min_area ? 255 : 0;
  for (int y = 0; y < mask.rows; ++y) {
    const int* lb = labels.ptr<int>(y);
    uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 0; x < mask.cols; ++x) m[x] = keep[lb[x]];
  }
  // Holes: background components not touching the border, below the maximum area.
  cv::Mat inv = 255 - mask;
  const int nh = cv::connectedComponentsWithStats(inv, labels, stats, centroids, 4, CV_32S);
  const double max_hole = options.max_hole_fraction * area;
  std::vector<uint8_t> fill(nh, 0);
  for (int l = 1; l < nh; ++l) {
    const int x = stats.at<int>(l, cv::CC_STAT_LEFT), y = stats.at<int>(l, cv::CC_STAT_TOP);
    const int w = stats.at<int>(l, cv::CC_STAT_WIDTH), h = stats.at<int>(l, cv::CC_STAT_HEIGHT);
    const bool border = x == 0 || y == 0 || x + w == mask.cols || y + h == mask.rows;
    fill[l] = (!border && stats.at<int>(l, cv::CC_STAT_AREA) <= max_hole) ? 255 : 0;
  }
  for (int y = 0; y < mask.rows; ++y) {
    const int* lb = labels.ptr<int>(y);
    uint8_t* m = mask.ptr<uint8_t>(y);
    for (int x = 0; x < mask.cols; ++x)
      if (fill[lb[x]]) m[x] = 255;
  }
  return mask;
}

Expected<Segmentation> segment(const ImageSet& set, const SegmentOptions& options) {
  if (Status st = options.check(); !st) return make_error("segmentation options: " + st.message());
  if (set.images.empty()) return make_error("the set has no images to segment");
  const cv::Size size = set.images[0].size();
  for (size_t i = 0; i < set.images.size(); ++i)
    if (set.images[i].size() != size || set.images[i].type() != CV_32FC3)
      return make_error("image " + std::to_string(i) + " differs in size or type from image 0");
  Segmentation seg;
  SegmentMethod method = options.method;
  if (method == SegmentMethod::automatic) method = set.mask.empty() ? SegmentMethod::otsu : SegmentMethod::supplied;
  seg.method_used = method;
  cv::Mat mask;
  if (method == SegmentMethod::supplied) {
    if (set.mask.empty()) return make_error("the set supplies no mask (use threshold or otsu)");
    if (set.mask.size() != size || set.mask.type() != CV_8UC1)
      return make_error("the set's mask does not match its images (size or type)");
    mask = set.mask.clone();
  } else {
    seg.summed = summed_intensity(set, options.subtract_ambient);
    if (method == SegmentMethod::none) {
      mask = cv::Mat(size, CV_8UC1, cv::Scalar(255));
    } else {
      seg.threshold = method == SegmentMethod::otsu ? otsu(seg.summed) : options.threshold;
      mask = cv::Mat(size, CV_8UC1);
      for (int y = 0; y < size.height; ++y) {
        const float* g = seg.summed.ptr<float>(y);
        uint8_t* m = mask.ptr<uint8_t>(y);
        for (int x = 0; x < size.width; ++x) m[x] = g[x] >= seg.threshold && g[x] > 0.f ? 255 : 0;
      }
    }
  }
  if (options.rect) {
    const cv::Rect r = *options.rect & cv::Rect(0, 0, size.width, size.height);
    if (r.area() == 0)
      return make_error("the rectangle " + std::to_string(options.rect->x) + "," + std::to_string(options.rect->y) +
                        "," + std::to_string(options.rect->width) + "," + std::to_string(options.rect->height) +
                        " lies outside the " + std::to_string(size.width) + "x" + std::to_string(size.height) + " image");
    cv::Mat limited(size, CV_8UC1, cv::Scalar(0));
    mask(r).copyTo(limited(r));
    mask = limited;
  }
  // A supplied mask is the user's word; cleaning is for thresholded ones.
  if (options.clean && method != SegmentMethod::supplied && method != SegmentMethod::none) mask = clean_mask(mask, options);
  seg.object_pixels = cv::countNonZero(mask);
  if (seg.object_pixels == 0)
    return make_error(std::string("segmentation (") + segment_method_name(method) + ") found no object pixels");
  seg.mask = mask;
  return seg;
}

}  // namespace veneer::ps
