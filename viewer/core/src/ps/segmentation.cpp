// Segmentation of the object (see segmentation.hpp).
#include "veneer/ps/segmentation.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/core/hal/hal.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/util/enum_names.hpp"

namespace veneer::ps {

constexpr EnumName<SegmentMethod> kSegmentMethodNames[] = {
    {SegmentMethod::automatic, "automatic"}, {SegmentMethod::supplied, "supplied"},
    {SegmentMethod::contrast, "contrast"},   {SegmentMethod::threshold, "threshold"},
    {SegmentMethod::otsu, "otsu"},           {SegmentMethod::none, "none"}};

const char* segment_method_name(SegmentMethod m) { return name_of(kSegmentMethodNames, m, "automatic"); }

Expected<SegmentMethod> parse_segment_method(const std::string& s) {
  return parse_name(kSegmentMethodNames, s, "segmentation method");
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
  if (!(border_fraction > 0 && border_fraction <= 0.25))
    return make_error("border_fraction must be in (0, 0.25], got " + std::to_string(border_fraction));
  if (!(contrast_low > 1 && contrast_high >= contrast_low && contrast_high < 1e3))
    return make_error("contrast thresholds must satisfy 1 < low <= high, got " + std::to_string(contrast_low) + " and " +
                      std::to_string(contrast_high));
  if (!(outline_sigmas >= 0 && outline_sigmas <= 100))
    return make_error("outline_sigmas must be in [0, 100], got " + std::to_string(outline_sigmas));
  return Status::success();
}

namespace {

// Row y of `photo` (CV_32FC3, or CV_16FC3: io::ReadOptions::half_floats) as
// float pixels: its own row, or widened into `buffer`.
const cv::Vec3f* float_row(const cv::Mat& photo, int y, std::vector<cv::Vec3f>& buffer) {
  if (photo.depth() == CV_32F) return photo.ptr<cv::Vec3f>(y);
  buffer.resize(static_cast<size_t>(photo.cols));
  cv::hal::cvt16f32f(photo.ptr<cv::float16_t>(y), &buffer[0][0], photo.cols * 3);
  return buffer.data();
}

// Mean grey intensity over the lamps, ambient removed.
cv::Mat summed_intensity(const io::ImageSet& set, bool subtract_ambient) {
  const cv::Size size = set.images[0].size();
  cv::Mat acc(size, CV_32FC3, cv::Scalar::all(0));
  const bool half = set.images[0].depth() == CV_16F;
  for (const cv::Mat& im : set.images) {
    if (!half) {
      cv::add(acc, im, acc);
      continue;
    }
    std::vector<cv::Vec3f> wide;  // half floats: added a row at a time
    for (int y = 0; y < size.height; ++y) {
      const cv::Vec3f* p = float_row(im, y, wide);
      cv::Vec3f* a = acc.ptr<cv::Vec3f>(y);
      for (int x = 0; x < size.width; ++x) a[x] += p[x];
    }
  }
  if (subtract_ambient && !set.ambient.empty() && set.ambient.size() == size &&
      set.ambient.type() == set.images[0].type()) {
    cv::Mat ambient = set.ambient;
    if (half) ambient.convertTo(ambient, CV_32FC3);
    cv::scaleAdd(ambient, -double(set.images.size()), acc, acc);
  }
  cv::Mat grey(size, CV_32FC1);
  const float s = 1.f / (3.f * set.images.size());
  for (int y = 0; y < size.height; ++y) {
    const cv::Vec3f* a = acc.ptr<cv::Vec3f>(y);
    float* g = grey.ptr<float>(y);
    for (int x = 0; x < size.width; ++x) g[x] = std::max(0.f, (a[x][0] + a[x][1] + a[x][2]) * s);
  }
  return grey;
}

// The brightest grey over lamps, ambient removed: lit by some lamp.
cv::Mat brightest_intensity(const io::ImageSet& set, bool subtract_ambient) {
  const cv::Size size = set.images[0].size();
  cv::Mat out(size, CV_32FC1, cv::Scalar(0));
  const bool amb = subtract_ambient && !set.ambient.empty() && set.ambient.size() == size &&
                   set.ambient.type() == set.images[0].type();
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& rows) {
    std::vector<cv::Vec3f> ambient_row, photo_row;  // half floats widened a row at a time
    for (int y = rows.start; y < rows.end; ++y) {
      float* o = out.ptr<float>(y);
      const cv::Vec3f* a = amb ? float_row(set.ambient, y, ambient_row) : nullptr;
      for (const cv::Mat& im : set.images) {
        const cv::Vec3f* p = float_row(im, y, photo_row);
        for (int x = 0; x < size.width; ++x) {
          float g = p[x][0] + p[x][1] + p[x][2];
          if (a) g -= a[x][0] + a[x][1] + a[x][2];
          o[x] = std::max(o[x], g * (1.f / 3.f));
        }
      }
    }
  });
  return out;
}

float percentile(std::vector<float>& v, double q) {
  if (v.empty()) return 0.f;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(q * double(v.size() - 1)));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

// The backdrop's level in the brightest-lamp image: the 98th percentile over a
// band along each of the top, left and right edges, the middle of the three
// (so an object that reaches one edge does not raise it).
float backdrop_level(const cv::Mat& bright, double fraction) {
  const int b = std::max(2, static_cast<int>(fraction * std::min(bright.rows, bright.cols)));
  std::vector<float> side[3];
  for (int y = 0; y < bright.rows; ++y) {
    const float* p = bright.ptr<float>(y);
    for (int x = 0; x < bright.cols; ++x) {
      if (y < b) side[0].push_back(p[x]);
      if (x < b) side[1].push_back(p[x]);
      if (x >= bright.cols - b) side[2].push_back(p[x]);
    }
  }
  float lv[3];
  for (int i = 0; i < 3; ++i) lv[i] = percentile(side[i], 0.98);
  std::sort(lv, lv + 3);
  return lv[1];
}

// Hysteresis: pixels above `low` connected (8-neighbours) to a pixel above `high`.
cv::Mat hysteresis(const cv::Mat& img, float low, float high) {
  cv::Mat lo = img > low;
  cv::Mat labels;
  const int n = cv::connectedComponents(lo, labels, 8, CV_32S);
  std::vector<uint8_t> keep(n, 0);
  for (int y = 0; y < img.rows; ++y) {
    const float* p = img.ptr<float>(y);
    const int* l = labels.ptr<int>(y);
    for (int x = 0; x < img.cols; ++x)
      if (l[x] > 0 && p[x] > high) keep[l[x]] = 255;
  }
  for (int y = 0; y < img.rows; ++y) {
    const int* l = labels.ptr<int>(y);
    uint8_t* m = lo.ptr<uint8_t>(y);
    for (int x = 0; x < img.cols; ++x) m[x] = keep[l[x]];
  }
  return lo;
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

// The outline the thresholds miss: each pixel beside the object (an
// 8-neighbour) whose brightest-lamp value stands above the backdrop around it
// by `sigmas` times that backdrop's spread (median and MAD of the pixels 2-3 px
// away that are neither object nor beside it) and lies at least halfway from
// it to the object's pixels next to it. The dim outline of a dark part seen
// at a grazing angle, a thin horn's tip the opening took, a pixel the object
// covers half of are kept; the backdrop's noise and the lens's fringe (less
// than half the object) are not.
cv::Mat with_outline(const cv::Mat& mask, const cv::Mat& bright, double sigmas) {
  cv::Mat near;
  cv::dilate(mask, near, cv::Mat());
  const cv::Mat ring = near & ~mask;
  cv::Mat out = mask.clone();
  const int W = mask.cols, H = mask.rows, r = 3;
  std::vector<float> backdrop, spread;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (!ring.at<uint8_t>(y, x)) continue;
      backdrop.clear();
      float object = 0;
      int n_object = 0;
      for (int qy = std::max(0, y - r); qy <= std::min(H - 1, y + r); ++qy)
        for (int qx = std::max(0, x - r); qx <= std::min(W - 1, x + r); ++qx) {
          const float v = bright.at<float>(qy, qx);
          if (mask.at<uint8_t>(qy, qx)) {
            if (std::abs(qx - x) <= 1 && std::abs(qy - y) <= 1) object += v, ++n_object;
          } else if (!ring.at<uint8_t>(qy, qx)) {
            backdrop.push_back(v);
          }
        }
      if (backdrop.size() < 5 || n_object == 0) continue;
      const float level = percentile(backdrop, 0.5);
      spread.clear();
      for (const float v : backdrop) spread.push_back(std::abs(v - level));
      const float sigma = 1.4826f * percentile(spread, 0.5);
      const float b = bright.at<float>(y, x);
      if (b > level + static_cast<float>(sigmas) * sigma && b >= 0.5f * (object / n_object + level))
        out.at<uint8_t>(y, x) = 255;
    }
  return out;
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

Expected<Segmentation> segment(const io::ImageSet& set, const SegmentOptions& options) {
  if (Status st = options.check(); !st) return make_error("segmentation options: " + st.message());
  if (set.images.empty()) return make_error("the set has no images to segment");
  const cv::Size size = set.images[0].size();
  for (size_t i = 0; i < set.images.size(); ++i)
    if (set.images[i].size() != size || set.images[i].type() != set.images[0].type() ||
        (set.images[i].type() != CV_32FC3 && set.images[i].type() != CV_16FC3))
      return make_error("image " + std::to_string(i) + " differs in size or type from image 0");
  Segmentation seg;
  SegmentMethod method = options.method;
  if (method == SegmentMethod::automatic) method = set.mask.empty() ? SegmentMethod::contrast : SegmentMethod::supplied;
  seg.method_used = method;
  cv::Mat mask;
  if (method == SegmentMethod::supplied) {
    if (set.mask.empty()) return make_error("the set supplies no mask (use threshold or otsu)");
    if (set.mask.size() != size || set.mask.type() != CV_8UC1)
      return make_error("the set's mask does not match its images (size or type)");
    mask = set.mask.clone();
  } else if (method == SegmentMethod::contrast) {
    seg.summed = brightest_intensity(set, options.subtract_ambient);
    double peak = 0;
    cv::minMaxLoc(seg.summed, nullptr, &peak);
    seg.backdrop = backdrop_level(seg.summed, options.border_fraction);
    // Floors for a black backdrop (no light reaches it, no noise): a fraction of the peak.
    seg.threshold = std::max(options.contrast_low * seg.backdrop, 0.002 * peak);
    const double high = std::max(options.contrast_high * seg.backdrop, 0.02 * peak);
    mask = hysteresis(seg.summed, static_cast<float>(seg.threshold), static_cast<float>(high));
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
  if (method == SegmentMethod::contrast && options.outline_sigmas > 0) {
    cv::Mat outlined = with_outline(mask, seg.summed, options.outline_sigmas);
    if (options.rect) {
      cv::Mat inside(size, CV_8UC1, cv::Scalar(0));
      inside(*options.rect & cv::Rect(0, 0, size.width, size.height)).setTo(255);
      outlined &= inside;
    }
    mask |= outlined;
  }
  seg.object_pixels = cv::countNonZero(mask);
  if (seg.object_pixels == 0)
    return make_error(std::string("segmentation (") + segment_method_name(method) + ") found no object pixels");
  seg.mask = mask;
  return seg;
}

}  // namespace veneer::ps

namespace veneer::ps {

namespace {

inline float dot3(const cv::Vec3f& a, const cv::Vec3f& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// The contested pixels (CV_8UC1) that go with the support: each side (the
// support's pixels, the rest of the mask) grows from its own pixels through
// contested pixels one step (8-neighbours) at a time, and a pixel goes to the
// side that reaches it first; one both reach in the same step goes to the side
// whose normal there is nearer its own (the leg's outline just above a
// plinth's edge to the leg, the plinth's rim against a hoof to the plinth).
// Pixels neither side reaches go to the support. Works within the contested
// pixels' bounding box (at full resolution a plinth is a fraction of the frame).
cv::Mat nearer_to_support(const cv::Mat& contested_full, const cv::Mat& support_full, const cv::Mat& rest_full,
                          const cv::Mat& normals_full) {
  cv::Mat out(contested_full.size(), CV_8UC1, cv::Scalar(0));
  if (cv::countNonZero(contested_full) == 0) return out;
  const cv::Rect box = (cv::boundingRect(contested_full) + cv::Size(2, 2) - cv::Point(1, 1)) &
                       cv::Rect(0, 0, contested_full.cols, contested_full.rows);
  const cv::Mat contested = contested_full(box), support = support_full(box), rest = rest_full(box),
                normals = normals_full(box);
  const int W = box.width, H = box.height;
  cv::Mat owner(box.size(), CV_8UC1, cv::Scalar(0));  // 1 support, 2 rest
  cv::Mat best[2] = {cv::Mat(box.size(), CV_32F, cv::Scalar(-2)),
                     cv::Mat(box.size(), CV_32F, cv::Scalar(-2))};  // the nearest normal's cosine per side
  std::vector<cv::Point> front[2], claimed;
  cv::Mat beside;  // only pixels beside a contested one can claim it
  cv::dilate(contested, beside, cv::Mat());
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (!beside.at<uint8_t>(y, x)) continue;
      if (support.at<uint8_t>(y, x)) front[0].push_back({x, y});
      else if (rest.at<uint8_t>(y, x)) front[1].push_back({x, y});
    }
  while (!front[0].empty() || !front[1].empty()) {
    claimed.clear();
    for (int side = 0; side < 2; ++side)
      for (const cv::Point& p : front[side]) {
        const cv::Vec3f np = normals.at<cv::Vec3f>(p);
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int qx = p.x + dx, qy = p.y + dy;
            if (qx < 0 || qy < 0 || qx >= W || qy >= H) continue;
            if (!contested.at<uint8_t>(qy, qx) || owner.at<uint8_t>(qy, qx)) continue;
            float& b = best[side].at<float>(qy, qx);
            if (b < -1.5f && best[1 - side].at<float>(qy, qx) < -1.5f) claimed.push_back({qx, qy});
            b = std::max(b, dot3(np, normals.at<cv::Vec3f>(qy, qx)));
          }
      }
    front[0].clear();
    front[1].clear();
    for (const cv::Point& q : claimed) {
      const int side = best[0].at<float>(q) > best[1].at<float>(q) ? 0 : 1;
      owner.at<uint8_t>(q) = static_cast<uint8_t>(side + 1);
      front[side].push_back(q);
    }
  }
  cv::Mat(contested & (owner != 2)).copyTo(out(box));
  return out;
}

}  // namespace

SupportRemoval drop_supports(cv::Mat& mask, const cv::Mat& normals, const SupportOptions& o) {
  SupportRemoval out;
  if (mask.empty() || normals.size() != mask.size() || normals.type() != CV_32FC3 || mask.type() != CV_8UC1) return out;
  const int W = mask.cols, H = mask.rows;
  const int total = cv::countNonZero(mask);
  if (total < 100) return out;
  const float cos_step = static_cast<float>(std::cos(o.plane_deg * CV_PI / 180));
  const float cos_region = static_cast<float>(std::cos(o.region_deg * CV_PI / 180));
  // 1. Flat regions: grow from each unlabelled pixel while neighbours agree
  //    with the pixel they come from and with the region's running mean.
  cv::Mat labels(mask.size(), CV_32S, cv::Scalar(-1));
  struct Region {
    cv::Vec3f mean;
    int area = 0, bottom = 0;
  };
  std::vector<Region> regions;
  std::vector<cv::Point> stack;
  const cv::Point nb4[4] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (!mask.at<uint8_t>(y, x) || labels.at<int>(y, x) >= 0) continue;
      const cv::Vec3f n0 = normals.at<cv::Vec3f>(y, x);
      if (dot3(n0, n0) < 0.5f) continue;
      const int id = static_cast<int>(regions.size());
      Region r;
      cv::Vec3f sum = n0;
      r.area = 1;
      r.bottom = y;
      labels.at<int>(y, x) = id;
      stack.assign(1, {x, y});
      while (!stack.empty()) {
        const cv::Point p = stack.back();
        stack.pop_back();
        const cv::Vec3f np = normals.at<cv::Vec3f>(p);
        const cv::Vec3f mean = sum / cv::norm(sum);
        for (const cv::Point& d : nb4) {
          const cv::Point q = p + d;
          if (q.x < 0 || q.y < 0 || q.x >= W || q.y >= H) continue;
          if (!mask.at<uint8_t>(q) || labels.at<int>(q) >= 0) continue;
          const cv::Vec3f nq = normals.at<cv::Vec3f>(q);
          if (dot3(nq, np) < cos_step || dot3(nq, mean) < cos_region) continue;
          labels.at<int>(q) = id;
          sum += nq;
          ++r.area;
          r.bottom = std::max(r.bottom, q.y);
          stack.push_back(q);
        }
      }
      r.mean = sum / cv::norm(sum);
      regions.push_back(r);
    }
  // 2. Planes: large flat regions. The object's bottom row.
  int bottom = 0, top = H;
  for (int y = 0; y < H; ++y)
    if (cv::countNonZero(mask.row(y))) {
      top = std::min(top, y);
      bottom = y;
    }
  const int min_plane = std::max(50, static_cast<int>(o.min_plane_fraction * total));
  std::vector<uint8_t> support(regions.size(), 0);
  const int reach = std::max(2, static_cast<int>(0.03 * (bottom - top + 1)));
  bool any = false;
  for (size_t i = 0; i < regions.size(); ++i)
    if (regions[i].area >= min_plane && regions[i].bottom >= bottom - reach) support[i] = 1, any = true;
  if (!any) return out;
  // 3. Flat regions touching the support, or across a seam of at most
  //    seam_px, join it (a plinth's top and front; a top cut by the penumbrae
  //    of cast shadows). A region too small to be a plane joins only when it
  //    is as flat as a support region near it (a piece of the top between
  //    two shadow edges).
  const int seam = std::max(0, o.seam_px);
  const cv::Mat near_kernel = cv::getStructuringElement(cv::MORPH_RECT, {2 * seam + 1, 2 * seam + 1});
  // A region joins through the support label seen at its last pixel (row by
  // row) within seam px of the support: the largest support label within
  // seam px there. Worked out incrementally (issue 48: at 5600x3750 a plinth
  // took 35 rounds of whole-box passes and dilations, 4.1 of drop_supports'
  // 5.2 s): `spread` holds, per pixel of the mask's box, the largest support
  // label within seam px (-1: none) and only grows, by the windows around
  // the regions that joined last; `last` holds each region's last pixel with
  // a support label near it. The result is the one of recomputing it all each
  // round, to the bit (tests/core/ps: SupportRemoval.*).
  const cv::Rect box = cv::boundingRect(mask);
  const int BW = box.width, BH = box.height;
  cv::Mat spread(box.size(), CV_32S, cv::Scalar(-1));
  std::vector<int64_t> last(regions.size(), -1);
  // each region's pixels (box indices, row by row), as offsets into one array
  std::vector<int64_t> start(regions.size() + 1, 0);
  for (int y = 0; y < BH; ++y) {
    const int* l = labels.ptr<int>(y + box.y) + box.x;
    for (int x = 0; x < BW; ++x)
      if (l[x] >= 0) ++start[static_cast<size_t>(l[x]) + 1];
  }
  for (size_t i = 0; i < regions.size(); ++i) start[i + 1] += start[i];
  std::vector<int64_t> pixels(static_cast<size_t>(start.back()));
  {
    std::vector<int64_t> at(start.begin(), start.end() - 1);
    for (int y = 0; y < BH; ++y) {
      const int* l = labels.ptr<int>(y + box.y) + box.x;
      for (int x = 0; x < BW; ++x)
        if (l[x] >= 0) pixels[static_cast<size_t>(at[static_cast<size_t>(l[x])]++)] = int64_t(y) * BW + x;
    }
  }
  std::vector<uint8_t> touched_flag(regions.size(), 0);
  std::vector<int> touched;
  // Spreads region r's label (it just joined the support) over seam px
  // around its pixels, run by run along the rows.
  auto spread_region = [&](int r) {
    const int64_t* px = pixels.data() + start[static_cast<size_t>(r)];
    const int64_t n = start[static_cast<size_t>(r) + 1] - start[static_cast<size_t>(r)];
    for (int64_t k = 0; k < n;) {
      const int y = static_cast<int>(px[k] / BW), x0 = static_cast<int>(px[k] % BW);
      int64_t e = k + 1;
      while (e < n && px[e] == px[e - 1] + 1 && px[e] / BW == y) ++e;
      const int x1 = x0 + static_cast<int>(e - k) - 1;
      const int xa = std::max(0, x0 - seam), xb = std::min(BW - 1, x1 + seam);
      for (int wy = std::max(0, y - seam); wy <= std::min(BH - 1, y + seam); ++wy) {
        int* sp = spread.ptr<int>(wy);
        const int* lab = labels.ptr<int>(wy + box.y) + box.x;
        for (int wx = xa; wx <= xb; ++wx) {
          if (sp[wx] >= r) continue;
          const bool was = sp[wx] >= 0;
          sp[wx] = r;
          const int l = lab[wx];
          if (l < 0 || support[static_cast<size_t>(l)]) continue;
          const int64_t idx = int64_t(wy) * BW + wx;
          if (!was) last[static_cast<size_t>(l)] = std::max(last[static_cast<size_t>(l)], idx);
          if (!touched_flag[static_cast<size_t>(l)]) touched_flag[static_cast<size_t>(l)] = 1, touched.push_back(l);
        }
      }
      k = e;
    }
  };
  std::vector<int> joined;
  for (size_t i = 0; i < regions.size(); ++i)
    if (support[i]) joined.push_back(static_cast<int>(i));
  while (!joined.empty()) {
    for (int r : joined) spread_region(r);
    joined.clear();
    // the regions whose nearest support label may have changed, in id order (as the rounds decide them)
    std::sort(touched.begin(), touched.end());
    for (int t : touched) {
      const size_t i = static_cast<size_t>(t);
      touched_flag[i] = 0;
      if (support[i] || last[i] < 0) continue;
      const int via = spread.at<int>(static_cast<int>(last[i] / BW), static_cast<int>(last[i] % BW));
      const bool plane = regions[i].area >= min_plane;
      const bool same_face =
          regions[i].area >= 4 && dot3(regions[i].mean, regions[static_cast<size_t>(via)].mean) >= cos_region;
      if (plane || same_face) joined.push_back(t);
    }
    touched.clear();
    for (int r : joined) support[static_cast<size_t>(r)] = 1;
  }
  // 4. Guards: small enough, and touched by the rest along a small part of its outline.
  // Faces: the support's regions grouped by their normal (pieces of one face cut by seams count once).
  int area = 0, planes = 0;
  std::vector<cv::Vec3f> faces;
  for (size_t i = 0; i < regions.size(); ++i) {
    if (!support[i]) continue;
    area += regions[i].area;
    bool known = false;
    for (const cv::Vec3f& f : faces) known = known || dot3(f, regions[i].mean) >= cos_region;
    if (!known) faces.push_back(regions[i].mean);
  }
  planes = static_cast<int>(faces.size());
  if (area > o.max_support_fraction * total) return out;
  // 4b. With it go the pixels next to it that lean its way (its cast shadows,
  //     solved less well).
  auto in_support = [&](int x, int y) {
    const int l = labels.at<int>(y, x);
    return l >= 0 && support[l];
  };
  cv::Mat dropped(mask.size(), CV_8UC1, cv::Scalar(0));
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      if (in_support(x, y)) dropped.at<uint8_t>(y, x) = 255;
  const float cos_absorb = static_cast<float>(std::cos(o.absorb_deg * CV_PI / 180));
  stack.clear();
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      if (dropped.at<uint8_t>(y, x)) stack.push_back({x, y});
  cv::Mat from(mask.size(), CV_32S, cv::Scalar(-1));  // the support region a pixel was absorbed from
  for (const cv::Point& p : stack) from.at<int>(p) = labels.at<int>(p);
  while (!stack.empty()) {
    const cv::Point p = stack.back();
    stack.pop_back();
    const cv::Vec3f ref = regions[static_cast<size_t>(from.at<int>(p))].mean;
    for (const cv::Point& d : nb4) {
      const cv::Point q = p + d;
      if (q.x < 0 || q.y < 0 || q.x >= W || q.y >= H) continue;
      if (!mask.at<uint8_t>(q) || dropped.at<uint8_t>(q)) continue;
      const cv::Vec3f nq = normals.at<cv::Vec3f>(q);
      if (dot3(nq, nq) > 0.5f && dot3(nq, ref) < cos_absorb) continue;
      dropped.at<uint8_t>(q) = 255;
      from.at<int>(q) = from.at<int>(p);
      stack.push_back(q);
    }
  }
  // 4c. The seams between its faces and pieces (narrower than 2 seam_px) go with it.
  //     And its rim: the mask's pixels within seam_px of both the support and
  //     the background (the lens mixes the plinth's edge with the backdrop;
  //     such pixels fit no face and would stay as an outline of the plinth).
  //     Both sweep up pixels of what stands on it too (a hoof's corners the
  //     closing fills, a leg's outline just above the plinth's back edge), so
  //     each such pixel goes to the side nearer to it: the support's faces or
  //     the rest of the mask.
  if (seam > 0) {
    cv::Mat closed;
    cv::morphologyEx(dropped, closed, cv::MORPH_CLOSE, near_kernel);
    closed &= mask;
    cv::Mat near_support, near_outside;
    cv::dilate(closed, near_support, near_kernel);
    cv::dilate(~mask, near_outside, near_kernel);
    const cv::Mat contested = (closed | (near_support & near_outside & mask)) & ~dropped;
    dropped |= nearer_to_support(contested, dropped, mask & ~dropped & ~contested, normals);
  }
  if (cv::countNonZero(dropped) > o.max_support_fraction * total) return out;
  // 5. Touched by what stands on it along a small part of its outline? What
  //    stands on it is the largest part of the rest (8-connected): bits of the
  //    mask the support alone touches (an end face too small to be a plane,
  //    pixels of its top in the penumbrae of cast shadows, which the lens
  //    blurs) go with it in step 6 and are no contact.
  cv::Mat kept = mask & ~dropped;
  cv::Mat cl, stats, cent;
  const int n = cv::connectedComponentsWithStats(kept, cl, stats, cent, 8, CV_32S);
  int best = 0;
  for (int l = 1; l < n; ++l)
    if (best == 0 || stats.at<int>(l, cv::CC_STAT_AREA) > stats.at<int>(best, cv::CC_STAT_AREA)) best = l;
  if (best == 0) return out;
  int outline = 0, contact = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (!dropped.at<uint8_t>(y, x)) continue;
      bool edge = false, touch = false;
      for (const cv::Point& d : nb4) {
        const int qx = x + d.x, qy = y + d.y;
        if (qx < 0 || qy < 0 || qx >= W || qy >= H || !dropped.at<uint8_t>(qy, qx)) {
          edge = true;
          if (qx >= 0 && qy >= 0 && qx < W && qy < H && cl.at<int>(qy, qx) == best) touch = true;
        }
      }
      outline += edge;
      contact += touch;
    }
  if (outline == 0 || contact > o.max_contact_fraction * outline) return out;
  // 6. Drop it; keep the largest remaining part.
  const int remaining = stats.at<int>(best, cv::CC_STAT_AREA);
  if (remaining < (1.0 - o.max_support_fraction) * total * 0.8) return out;  // that was not a base
  kept = cl == best;
  out.removed_pixels = total - remaining;
  out.planes = planes;
  mask = kept;
  return out;
}

SupportRemoval drop_supports(PsResult& r, const SupportOptions& options) {
  const cv::Mat before = r.mask.clone();
  SupportRemoval out = drop_supports(r.mask, r.normals, options);
  if (out.removed_pixels == 0) return out;
  const cv::Mat gone = before & ~r.mask;
  for (cv::Mat* m : {&r.normals, &r.albedo, &r.reliable, &r.residual, &r.depth})
    if (!m->empty()) m->setTo(cv::Scalar::all(0), gone);
  r.solved_pixels = cv::countNonZero(r.mask);
  r.unreliable_pixels = r.solved_pixels - cv::countNonZero(r.reliable & r.mask);
  return out;
}

}  // namespace veneer::ps
