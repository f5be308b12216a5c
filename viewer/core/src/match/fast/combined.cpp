// The `combined` correspondence: a multi-scale PatchMatch over everything the
// rig gives for a pixel, with a coherence term (see combined.hpp).
#include "combined.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <memory>
#include <string>
#include <random>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/task_arena.h>

#include "veneer/match/fast.hpp"

namespace veneer::match::fast {

namespace {

// One level of one object: features per pixel (dims floats, padded to a
// multiple of 8), -1 rows off the object.
struct Level {
  cv::Size size;
  cv::Rect box;               // the object's bounding box with a margin: features are kept there only
  int dims = 0, stride = 0;
  std::vector<float> f;       // box.area() * stride
  std::vector<uint8_t> on;    // object pixel (box.area())
  cv::Mat normals;            // CV_32FC3 (for the seed)
  std::vector<cv::Point> pixels;

  bool valid(int x, int y) const {
    const int bx = x - box.x, by = y - box.y;
    return bx >= 0 && by >= 0 && bx < box.width && by < box.height && on[static_cast<size_t>(by) * box.width + bx];
  }
  const float* at(int x, int y) const {
    return f.data() + (static_cast<size_t>(y - box.y) * box.width + (x - box.x)) * stride;
  }
};

struct Weights {
  float normal = 1.0f;    // |dn|^2
  float shading = 0.5f;   // the per-lamp grey pattern, normalised (albedo-free)
  float chroma = 0.5f;    // the mean colour's chromaticity
  float lum = 0.02f;      // log of the mean grey (albedo x shading)
};

// A photo's pixel as float: the photos are CV_32FC3 or half floats
// (CV_16FC3, io::ReadOptions::half_floats), which widen exactly.
inline cv::Vec3f photo_at(const cv::Mat& photo, int y, int x) {
  if (photo.depth() == CV_32F) return photo.at<cv::Vec3f>(y, x);
  const cv::float16_t* h = photo.ptr<cv::float16_t>(y) + 3 * x;
  return {static_cast<float>(h[0]), static_cast<float>(h[1]), static_cast<float>(h[2])};
}

// The pixel's features: normal, shading pattern, chroma, log luminance.
Level make_level(const cv::Mat& normals, const cv::Mat& mask, const std::vector<cv::Mat>& images,
                 const Weights& w) {
  Level l;
  l.size = normals.size();
  const int lamps = static_cast<int>(images.size());
  l.dims = 3 + lamps + 3;
  l.stride = (l.dims + 7) / 8 * 8;
  l.box = cv::boundingRect(mask);
  if (l.box.area() == 0) l.box = cv::Rect(0, 0, 1, 1);
  l.f.assign(static_cast<size_t>(l.box.area()) * l.stride, 0.0f);
  l.on.assign(static_cast<size_t>(l.box.area()), 0);
  l.normals = normals;
  const float sn = std::sqrt(w.normal), ss = std::sqrt(w.shading), sc = std::sqrt(w.chroma), sl = std::sqrt(w.lum);
  std::vector<float> grey(lamps);
  for (int y = l.box.y; y < l.box.y + l.box.height; ++y) {
    for (int x = l.box.x; x < l.box.x + l.box.width; ++x) {
      if (!mask.at<uchar>(y, x)) continue;
      cv::Vec3f n = normals.at<cv::Vec3f>(y, x);
      // A pixel without a normal still takes part (every object pixel is
      // mapped): on its photos alone, its normal part a constant.
      if (!(std::isfinite(n[0]) && std::isfinite(n[1]) && std::isfinite(n[2])) || n.dot(n) < 0.25f) n = {0, 0, 0};
      float* f = const_cast<float*>(l.at(x, y));
      f[0] = sn * n[0];
      f[1] = sn * n[1];
      f[2] = sn * n[2];
      cv::Vec3f mean(0, 0, 0);
      double norm = 0;
      for (int j = 0; j < lamps; ++j) {
        const cv::Vec3f c = photo_at(images[j], y, x);
        mean += c;
        grey[j] = std::max(0.0f, (c[0] + c[1] + c[2]) / 3.0f);
        norm += static_cast<double>(grey[j]) * grey[j];
      }
      const float inv = norm > 0 ? static_cast<float>(1.0 / std::sqrt(norm)) : 0.0f;
      for (int j = 0; j < lamps; ++j) f[3 + j] = ss * grey[j] * inv;
      mean /= std::max(1, lamps);
      const float sum = std::max(1e-6f, mean[0] + mean[1] + mean[2]);
      f[3 + lamps] = sc * mean[0] / sum;
      f[4 + lamps] = sc * mean[2] / sum;
      f[5 + lamps] = sl * std::log(std::max(1e-4f, sum / 3.0f));
      l.on[static_cast<size_t>(y - l.box.y) * l.box.width + (x - l.box.x)] = 1;
      l.pixels.emplace_back(x, y);
    }
  }
  return l;
}

// An object's inputs at a level ([0] = full size); features are made per
// level when it is reached (a pair of different objects needs only the coarsest).
struct Pyramid {
  struct Inputs {
    cv::Mat normals, mask;
    std::vector<cv::Mat> images;
  };
};

// Level i straight from the full size (one area-average per image, not a
// chain: the probe needs only the coarsest).
Pyramid::Inputs downscaled(const ObjectView& v, int i) {
  if (i == 0) return {v.normals, v.mask, v.images};
  Pyramid::Inputs in;
  const int f = 1 << i;
  const cv::Size small((v.normals.cols + f - 1) / f, (v.normals.rows + f - 1) / f);
  cv::Mat mf;
  v.mask.convertTo(mf, CV_32F, 1.0 / 255);
  cv::resize(mf, mf, small, 0, 0, cv::INTER_AREA);
  in.mask = mf > 0.5;
  // The normals and photos are read on the object alone: when the level
  // divides the frame exactly, only the blocks under the reduced mask's box
  // are reduced, the rest left 0 (issue 48: reducing whole photos was a third
  // of the demo pair's map). Each reduced pixel is its own block's mean, so
  // the values are the whole frame's to the bit for 3 channels (not for 1:
  // OpenCV's 2x2 SIMD path sums in another order; test
  // core/CombinedPhotos.AreaReducedPartsAreTheWholeFramesToTheBit). A
  // half-float photo is widened (the part reduced, into one buffer for all),
  // then reduced as a float one is.
  const cv::Rect box = cv::boundingRect(in.mask);
  const bool crop = v.normals.cols % f == 0 && v.normals.rows % f == 0 && box.area() > 0;
  const cv::Rect from = crop ? cv::Rect(box.x * f, box.y * f, box.width * f, box.height * f)
                             : cv::Rect(0, 0, v.normals.cols, v.normals.rows);
  cv::Mat wide;
  auto reduce = [&](const cv::Mat& full) {  // CV_32FC3 or CV_16FC3 (run_combined checks)
    cv::Mat part = full(from), out;
    if (part.depth() != CV_32F) {
      part.convertTo(wide, CV_32F);
      part = wide;
    }
    if (!crop) {
      cv::resize(part, out, small, 0, 0, cv::INTER_AREA);
      return out;
    }
    out = cv::Mat(small, CV_32FC3, cv::Scalar::all(0));
    cv::Mat inside = out(box);
    cv::resize(part, inside, box.size(), 0, 0, cv::INTER_AREA);
    return out;
  };
  in.normals = reduce(v.normals);
  for (auto it = in.normals.begin<cv::Vec3f>(); it != in.normals.end<cv::Vec3f>(); ++it) {
    cv::Vec3f& n = *it;
    const float len = std::sqrt(n.dot(n));
    if (len > 1e-6f) n /= len;
  }
  in.images.reserve(v.images.size());
  for (const cv::Mat& photo : v.images) in.images.push_back(reduce(photo));
  return in;
}

// The patch: the centre (weight 2), 8 samples two pixels away and 8 four
// pixels away: wide enough to tell a smooth surface's pixels apart.
const std::array<cv::Point, 17> kOffsets = {
    cv::Point(0, 0),   cv::Point(-2, 0), cv::Point(2, 0),  cv::Point(0, -2), cv::Point(0, 2),  cv::Point(-2, -2),
    cv::Point(2, -2),  cv::Point(-2, 2), cv::Point(2, 2),  cv::Point(-4, 0), cv::Point(4, 0),  cv::Point(0, -4),
    cv::Point(0, 4),   cv::Point(-4, -4), cv::Point(4, -4), cv::Point(-4, 4), cv::Point(4, 4)};
const std::array<float, 17> kWeights = {2, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1};
constexpr float kOffObject = 1.0f;  // a patch sample that falls off the source object

inline float sq_dist(const float* a, const float* b, int stride) {
  float s = 0;
  for (int i = 0; i < stride; ++i) {
    const float d = a[i] - b[i];
    s += d * d;
  }
  return s;
}

struct Matcher {
  const Level& d;
  const Level& s;
  float coherence = 0.05f;  // cost of each 4-neighbour whose match lies more than 1.5 px away
  std::vector<cv::Point2i> match;  // per destination pixel (size.area()), (-1,-1) = none
  std::vector<float> cost;         // patch cost (no coherence part)
  // The motion's linear part (source step per destination step): the patch
  // is sampled through it on the source, so a copy at half or twice the size,
  // or turned, compares sample for sample; identity until a motion is guessed.
  cv::Matx22f linear = cv::Matx22f::eye();
  std::array<cv::Point, 17> source_offsets = kOffsets;

  void set_linear(const cv::Matx22f& l) {
    linear = l;
    for (size_t k = 0; k < kOffsets.size(); ++k) source_offsets[k] = step(kOffsets[k]);
  }
  // Where a destination step `o` lands on the source, to the nearest pixel.
  cv::Point step(cv::Point o) const {
    const cv::Vec2f v = linear * cv::Vec2f(static_cast<float>(o.x), static_cast<float>(o.y));
    return {static_cast<int>(std::lround(v[0])), static_cast<int>(std::lround(v[1]))};
  }

  float patch_cost(int px, int py, int qx, int qy) const {
    float total = 0, wsum = 0;
    for (size_t k = 0; k < kOffsets.size(); ++k) {
      const int dx = px + kOffsets[k].x, dy = py + kOffsets[k].y;
      if (!d.valid(dx, dy)) continue;
      const int sx = qx + source_offsets[k].x, sy = qy + source_offsets[k].y;
      wsum += kWeights[k];
      if (!s.valid(sx, sy)) {
        total += kWeights[k] * kOffObject;
        continue;
      }
      total += kWeights[k] * sq_dist(d.at(dx, dy), s.at(sx, sy), d.stride);
    }
    return wsum > 0 ? total / wsum : 0.0f;
  }
  // Neighbours whose current match does not continue (qx, qy): more than
  // one pixel off the neighbour's own step through `linear`.
  float incoherence(int px, int py, int qx, int qy) const {
    int broken = 0;
    for (const cv::Point o : {cv::Point(1, 0), cv::Point(-1, 0), cv::Point(0, 1), cv::Point(0, -1)}) {
      const int nx = px + o.x, ny = py + o.y;
      if (!d.valid(nx, ny)) continue;
      const cv::Point2i m = match[static_cast<size_t>(ny) * d.size.width + nx];
      if (m.x < 0) continue;
      const float ex = m.x - qx - (linear(0, 0) * o.x + linear(0, 1) * o.y);
      const float ey = m.y - qy - (linear(1, 0) * o.x + linear(1, 1) * o.y);
      if (ex * ex + ey * ey > 1.01f) ++broken;
    }
    return coherence * broken;
  }
  float total(int px, int py, int qx, int qy, float patch) const { return patch + incoherence(px, py, qx, qy); }

  // The weight of p's patch samples on the destination object: patch_cost's divisor.
  float patch_weight(int px, int py) const {
    float wsum = 0;
    for (size_t k = 0; k < kOffsets.size(); ++k)
      if (d.valid(px + kOffsets[k].x, py + kOffsets[k].y)) wsum += kWeights[k];
    return wsum;
  }
  // patch_cost (its divisor `wsum` given), or `limit` as soon as the samples
  // summed so far show the whole cost would not be below it (each sample adds
  // >= 0, and the 1e-4 margin covers the rounding): a hopeless candidate's
  // other samples are not summed, and a comparison with `limit` comes out as
  // with patch_cost's value, to the bit.
  float patch_cost_within(int px, int py, int qx, int qy, float wsum, float limit) const {
    if (!(wsum > 0)) return 0.0f;
    const float stop = limit * wsum * 1.0001f;
    float total = 0;
    for (size_t k = 0; k < kOffsets.size(); ++k) {
      const int dx = px + kOffsets[k].x, dy = py + kOffsets[k].y;
      if (!d.valid(dx, dy)) continue;
      const int sx = qx + source_offsets[k].x, sy = qy + source_offsets[k].y;
      if (!s.valid(sx, sy)) {
        total += kWeights[k] * kOffObject;
      } else {
        total += kWeights[k] * sq_dist(d.at(dx, dy), s.at(sx, sy), d.stride);
      }
      if (total > stop) return limit;
    }
    return total / wsum;
  }

  // Tries (qx, qy) for p (its patch_weight `wsum`); keeps it when better.
  inline void try_candidate(int px, int py, float wsum, int qx, int qy, cv::Point2i& best, float& best_patch,
                            float& best_total) const {
    if (!s.valid(qx, qy) || (qx == best.x && qy == best.y)) return;
    const float pc = patch_cost_within(px, py, qx, qy, wsum, best_total);
    if (pc >= best_total) return;  // the coherence part is >= 0
    const float t = total(px, py, qx, qy, pc);
    if (t < best_total) {
      best = {qx, qy};
      best_patch = pc;
      best_total = t;
    }
  }
};

// Nearest source normal for every destination pixel of the level (the seed).
std::vector<cv::Point2i> seed_by_normal(const Level& d, const Level& s) {
  std::vector<cv::Point2i> out(static_cast<size_t>(d.size.area()), cv::Point2i(-1, -1));
  if (s.pixels.empty()) return out;
  std::vector<float> pts(s.pixels.size() * 3);
  for (size_t i = 0; i < s.pixels.size(); ++i) {
    const cv::Vec3f n = s.normals.at<cv::Vec3f>(s.pixels[i]);
    pts[3 * i] = n[0];
    pts[3 * i + 1] = n[1];
    pts[3 * i + 2] = n[2];
  }
  auto index = make_index("lookup");
  if (!index) index = make_index("kdtree");
  index->build(pts.data(), static_cast<int>(s.pixels.size()), 3);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, d.pixels.size(), 1024), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) {
      const cv::Point p = d.pixels[i];
      const cv::Vec3f n = d.normals.at<cv::Vec3f>(p);
      if (n.dot(n) < 0.25f) continue;
      int id = -1;
      float dist = 0;
      index->knn(&n[0], 1, &id, &dist);
      if (id >= 0) out[static_cast<size_t>(p.y) * d.size.width + p.x] = s.pixels[id];
    }
  });
  return out;
}

// Unmapped pixels of `mask` take the match of the nearest mapped pixel.
void fill_unmapped(Map& map, const cv::Mat& mask) {
  cv::Mat unmapped(map.xy.size(), CV_8U, cv::Scalar(0));
  bool any = false, some_mapped = false;
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x) {
      const bool mapped = map.xy.at<cv::Vec2f>(y, x)[0] >= 0;
      some_mapped = some_mapped || mapped;
      if (!mapped) {
        unmapped.at<uchar>(y, x) = 255;
        any = any || mask.at<uchar>(y, x);
      }
    }
  if (!any || !some_mapped) return;
  cv::Mat dist, labels;
  cv::distanceTransform(unmapped, dist, labels, cv::DIST_L2, cv::DIST_MASK_5, cv::DIST_LABEL_PIXEL);
  // label -> a mapped pixel's position
  std::vector<cv::Point> where;
  where.resize(static_cast<size_t>(map.xy.total()) + 1, cv::Point(-1, -1));
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x)
      if (!unmapped.at<uchar>(y, x)) where[static_cast<size_t>(labels.at<int>(y, x))] = {x, y};
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x) {
      if (!unmapped.at<uchar>(y, x) || !mask.at<uchar>(y, x)) continue;
      const cv::Point n = where[static_cast<size_t>(labels.at<int>(y, x))];
      if (n.x < 0) continue;
      map.xy.at<cv::Vec2f>(y, x) = map.xy.at<cv::Vec2f>(n);
      map.distance.at<float>(y, x) = map.distance.at<float>(n);
    }
}

// The affine motion (2x3, CV_64F) that most matches follow, or empty when
// fewer than `min_share` of a sample of them lie within 1.5 px of the best one.
cv::Mat global_motion(const Level& d, const std::vector<cv::Point2i>& match, unsigned seed, double* share_out = nullptr,
                      double min_share = 0.6) {
  std::vector<cv::Point2f> from, to;
  const size_t step = std::max<size_t>(1, d.pixels.size() / 1500);
  for (size_t i = 0; i < d.pixels.size(); i += step) {
    const cv::Point p = d.pixels[i];
    const cv::Point2i q = match[static_cast<size_t>(p.y) * d.size.width + p.x];
    if (q.x < 0) continue;
    from.emplace_back(static_cast<float>(p.x), static_cast<float>(p.y));
    to.emplace_back(static_cast<float>(q.x), static_cast<float>(q.y));
  }
  if (from.size() < 50) return {};
  cv::setRNGSeed(static_cast<int>(seed));
  std::vector<uchar> inliers;
  // 400 draws of 3 find a motion 60 % of the points follow with certainty ((1 - 0.6^3)^400 ~ 1e-42).
  cv::Mat A = cv::estimateAffine2D(from, to, inliers, cv::RANSAC, 1.5, 400, 0.995, 10);
  if (A.empty()) return {};
  const double share = static_cast<double>(std::count(inliers.begin(), inliers.end(), 1)) / from.size();
  if (share_out) *share_out = share;
  return share >= min_share ? A : cv::Mat();
}

cv::Matx22f linear_part(const cv::Mat& motion) {
  return {static_cast<float>(motion.at<double>(0, 0)), static_cast<float>(motion.at<double>(0, 1)),
          static_cast<float>(motion.at<double>(1, 0)), static_cast<float>(motion.at<double>(1, 1))};
}

// A guess of the object's motion from the masks: source = motion x destination.
struct MotionGuess {
  cv::Matx22f linear;  // scale and turn
  cv::Mat motion;      // 2x3 CV_64F: the linear part about the masks' centroids
};

// The guesses, likeliest first: the scale from the masks' areas (a crop
// biases it; the patches tolerate a fifth off), unturned; turned by the
// difference of the masks' principal axes (both ways) when both are
// elongated; unscaled; then turns in eighths (the patch compares up to a
// sixteenth of a turn off).
std::vector<MotionGuess> guess_motions(const Level& d, const Level& s) {
  struct Shape {
    double area = 0, cx = 0, cy = 0, axis = 0, elongation = 0;
  };
  auto shape_of = [](const Level& l) {
    Shape sh;
    double mx = 0, my = 0;
    for (const cv::Point p : l.pixels) {
      mx += p.x;
      my += p.y;
    }
    sh.area = static_cast<double>(l.pixels.size());
    if (sh.area == 0) return sh;
    sh.cx = mx / sh.area;
    sh.cy = my / sh.area;
    double m20 = 0, m02 = 0, m11 = 0;
    for (const cv::Point p : l.pixels) {
      const double dx = p.x - sh.cx, dy = p.y - sh.cy;
      m20 += dx * dx;
      m02 += dy * dy;
      m11 += dx * dy;
    }
    sh.axis = 0.5 * std::atan2(2 * m11, m20 - m02);
    sh.elongation = m20 + m02 > 0 ? std::hypot(m20 - m02, 2 * m11) / (m20 + m02) : 0.0;
    return sh;
  };
  const Shape a = shape_of(d), b = shape_of(s);
  const double area_scale = a.area > 0 && b.area > 0 ? std::sqrt(b.area / a.area) : 1.0;
  std::vector<std::pair<double, double>> tried;  // (scale, turn [rad])
  std::vector<MotionGuess> out;
  auto add = [&](double scale, double turn) {
    turn = std::remainder(turn, 2 * CV_PI);
    for (const auto& [sc, tn] : tried)
      if (std::abs(sc / scale - 1) < 0.1 && std::abs(std::remainder(tn - turn, 2 * CV_PI)) < 10 * CV_PI / 180) return;
    tried.emplace_back(scale, turn);
    const double c = scale * std::cos(turn), sn = scale * std::sin(turn);
    MotionGuess g;
    g.linear = cv::Matx22f(static_cast<float>(c), static_cast<float>(-sn), static_cast<float>(sn), static_cast<float>(c));
    g.motion = (cv::Mat_<double>(2, 3) << c, -sn, b.cx - (c * a.cx - sn * a.cy), sn, c, b.cy - (sn * a.cx + c * a.cy));
    out.push_back(g);
  };
  add(area_scale, 0);
  if (a.elongation > 0.15 && b.elongation > 0.15) {
    add(area_scale, b.axis - a.axis);
    add(area_scale, b.axis - a.axis + CV_PI);
  }
  add(1.0, 0);
  for (int q = 1; q < 8; ++q) add(area_scale, q * CV_PI / 4);
  return out;
}

// How much the pixels' features vary over two pixels (the median squared
// difference): the texture and relief a motion can be seen by; near 0 on a
// flat, uniform object.
// At the coarsest level (noise averaged away): a sphere filling it varies by
// ~1e-2, a flat uniform object under 0.5 % noise by ~3e-5.
constexpr double kLittleStructure = 1e-4;
double structure(const Level& l) {
  std::vector<double> v;
  const size_t step = std::max<size_t>(1, l.pixels.size() / 5000);
  for (size_t i = 0; i < l.pixels.size(); i += step) {
    const cv::Point p = l.pixels[i];
    if (l.valid(p.x + 2, p.y)) v.push_back(sq_dist(l.at(p.x, p.y), l.at(p.x + 2, p.y), l.stride));
    if (l.valid(p.x, p.y + 2)) v.push_back(sq_dist(l.at(p.x, p.y), l.at(p.x, p.y + 2), l.stride));
  }
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

// Said when an object's features hardly vary (too little texture or relief
// for any motion to be seen by), else "".
std::string featureless(const Level& d, const Level& s) {
  const double a = structure(d), b = structure(s);
  if (std::min(a, b) >= kLittleStructure) return "";
  char buf[200];
  std::snprintf(buf, sizeof buf, "the %s shows too little texture or relief to be placed (its features vary by %.4f over 2 px, under %.4f): ",
                a <= b ? "destination" : "source", std::min(a, b), kLittleStructure);
  return buf;
}

// "0.62-1.6x": the scales the guesses span.
std::string scale_range(const std::vector<MotionGuess>& guesses) {
  double lo = 1e9, hi = 0;
  for (const auto& g : guesses) {
    const double sc = std::sqrt(std::abs(g.linear(0, 0) * g.linear(1, 1) - g.linear(0, 1) * g.linear(1, 0)));
    lo = std::min(lo, sc);
    hi = std::max(hi, sc);
  }
  char buf[64];
  if (hi / lo < 1.05)
    std::snprintf(buf, sizeof buf, "%.2gx", 1 / lo);
  else
    std::snprintf(buf, sizeof buf, "%.2g-%.2gx", 1 / hi, 1 / lo);
  return buf;
}

// The median angle [deg] between a pixel's normal and its right-hand
// neighbour's: the normals' noise (and fine relief) at this size.
double roughness_deg(const Level& l) {
  std::vector<double> a;
  const size_t step = std::max<size_t>(1, l.pixels.size() / 20000);
  for (size_t i = 0; i < l.pixels.size(); i += step) {
    const cv::Point p = l.pixels[i];
    if (!l.valid(p.x + 1, p.y)) continue;
    const cv::Vec3f n = l.normals.at<cv::Vec3f>(p), m = l.normals.at<cv::Vec3f>(p.y, p.x + 1);
    if (n.dot(n) < 0.25f || m.dot(m) < 0.25f) continue;
    a.push_back(std::acos(std::clamp(static_cast<double>(n.dot(m)), -1.0, 1.0)) * 180.0 / CV_PI);
  }
  if (a.empty()) return 0;
  std::nth_element(a.begin(), a.begin() + a.size() / 2, a.end());
  return a[a.size() / 2];
}

// `coarse` (2x3 at 1/scale) at full size, refitted by least squares to the
// matches within 3 px of it when at least a third of them are; else empty.
cv::Mat refit_motion(const Level& d, const std::vector<cv::Point2i>& match, const cv::Mat& coarse, double scale) {
  if (coarse.empty()) return {};
  cv::Mat A = coarse.clone();
  A.at<double>(0, 2) *= scale;
  A.at<double>(1, 2) *= scale;
  std::vector<cv::Point2f> from, to;
  size_t total = 0;
  const size_t step = std::max<size_t>(1, d.pixels.size() / 4000);
  for (size_t i = 0; i < d.pixels.size(); i += step) {
    const cv::Point p = d.pixels[i];
    const cv::Point2i q = match[static_cast<size_t>(p.y) * d.size.width + p.x];
    if (q.x < 0) continue;
    ++total;
    const double tx = A.at<double>(0, 0) * p.x + A.at<double>(0, 1) * p.y + A.at<double>(0, 2);
    const double ty = A.at<double>(1, 0) * p.x + A.at<double>(1, 1) * p.y + A.at<double>(1, 2);
    if (std::hypot(tx - q.x, ty - q.y) > 3.0) continue;
    from.emplace_back(static_cast<float>(p.x), static_cast<float>(p.y));
    to.emplace_back(static_cast<float>(q.x), static_cast<float>(q.y));
  }
  if (total == 0 || from.size() < 50 || from.size() * 3 < total) return {};
  std::vector<uchar> inliers;
  cv::Mat R = cv::estimateAffine2D(from, to, inliers, cv::LMEDS);
  return R.empty() ? A : R;
}

// Median angle [deg] between each destination pixel's normal and the source
// normal the motion (or, for comparison, the nearest-normal seed) gives it;
// the motion passes when its median is within max(4 deg, 3x the seed's).
bool motion_keeps_normals(const Level& d, const Level& s, const cv::Mat& motion, const std::vector<cv::Point2i>& seed,
                          std::string* why) {
  const double* A = motion.ptr<double>(0);
  const double* B = motion.ptr<double>(1);
  std::vector<double> by_motion, by_seed;
  auto angle = [](const cv::Vec3f& a, const cv::Vec3f& b) {
    return std::acos(std::clamp(static_cast<double>(a.dot(b)), -1.0, 1.0)) * 180.0 / CV_PI;
  };
  for (const cv::Point p : d.pixels) {
    const cv::Vec3f n = d.normals.at<cv::Vec3f>(p);
    if (n.dot(n) < 0.25f) continue;
    const size_t at = static_cast<size_t>(p.y) * d.size.width + p.x;
    const int qx = static_cast<int>(std::lround(A[0] * p.x + A[1] * p.y + A[2]));
    const int qy = static_cast<int>(std::lround(B[0] * p.x + B[1] * p.y + B[2]));
    if (!s.valid(qx, qy)) {
      by_motion.push_back(90.0);
    } else {
      by_motion.push_back(angle(n, s.normals.at<cv::Vec3f>(qy, qx)));
    }
    if (seed[at].x >= 0) by_seed.push_back(angle(n, s.normals.at<cv::Vec3f>(seed[at].y, seed[at].x)));
  }
  if (by_motion.empty() || by_seed.empty()) return false;
  auto median = [](std::vector<double>& v) {
    auto mid = v.begin() + v.size() / 2;
    std::nth_element(v.begin(), mid, v.end());
    return *mid;
  };
  const double m = median(by_motion), n = median(by_seed);
  // Noisy normals (a dark or grainy set) differ by their noise even where
  // the motion is right: the allowance grows with it.
  const double rd = roughness_deg(d), rs = roughness_deg(s);
  const double noise = std::sqrt((rd * rd + rs * rs) / 2);
  const double allowed = std::max({4.0, 3.0 * n, 1.5 * noise});
  if (why)
    *why = "the motion keeps the normals to " + std::to_string(m) + " deg (median), the nearest normal to " +
           std::to_string(n) + ", noise " + std::to_string(noise) + ", allowed " + std::to_string(allowed);
  return m <= allowed;
}

// The motion checked against the data, unbiased by itself: for a sample of
// destination pixels, the patch's best position within `radius` px of where
// the motion puts it (to a tenth of a pixel by a parabola through the costs),
// kept where that best stands out of its window; the affine fitted to those
// by RANSAC (1 px). The search's own matches lean towards the motion that
// guided them (it is taken where it fits about as well), so a scale a few
// percent off at the coarsest size would otherwise stay so. Returns `motion`
// when too few positions agree.
cv::Mat polish_motion(Matcher& m, const cv::Mat& motion, unsigned seed, int rounds = 2, int radius = 2) {
  cv::Mat A = motion.clone();
  const Level& d = m.d;
  const Level& s = m.s;
  const int side = 2 * radius + 1;
  for (int round = 0; round < rounds; ++round) {
    m.set_linear(linear_part(A));
    const size_t step = std::max<size_t>(1, d.pixels.size() / 1500);
    const size_t n = (d.pixels.size() + step - 1) / step;
    std::vector<cv::Point2f> from(n, cv::Point2f(-1, -1)), to(n);
    std::vector<float> distinct(n, -1.0f);
    const double* a = A.ptr<double>(0);
    const double* b = A.ptr<double>(1);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 64), [&](const tbb::blocked_range<size_t>& r) {
      std::vector<float> c(static_cast<size_t>(side * side));
      for (size_t i = r.begin(); i != r.end(); ++i) {
        const cv::Point p = d.pixels[i * step];
        const double tx = a[0] * p.x + a[1] * p.y + a[2], ty = b[0] * p.x + b[1] * p.y + b[2];
        const int cx = static_cast<int>(std::lround(tx)), cy = static_cast<int>(std::lround(ty));
        float best = 1e30f, sum = 0;
        int bx = 0, by = 0, valid = 0;
        bool complete = true;
        for (int oy = -radius; oy <= radius && complete; ++oy)
          for (int ox = -radius; ox <= radius; ++ox) {
            if (!s.valid(cx + ox, cy + oy)) {
              complete = false;
              break;
            }
            const float v = m.patch_cost(p.x, p.y, cx + ox, cy + oy);
            c[static_cast<size_t>((oy + radius) * side + ox + radius)] = v;
            sum += v;
            ++valid;
            if (v < best) {
              best = v;
              bx = ox;
              by = oy;
            }
          }
        if (!complete || std::abs(bx) == radius || std::abs(by) == radius) continue;
        auto at = [&](int ox, int oy) { return c[static_cast<size_t>((oy + radius) * side + ox + radius)]; };
        auto vertex = [](float l, float c0, float r) {
          const float den = l - 2 * c0 + r;
          return den > 1e-12f ? std::clamp(0.5f * (l - r) / den, -0.5f, 0.5f) : 0.0f;
        };
        const float fx = static_cast<float>(cx + bx) + vertex(at(bx - 1, by), best, at(bx + 1, by));
        const float fy = static_cast<float>(cy + by) + vertex(at(bx, by - 1), best, at(bx, by + 1));
        from[i] = cv::Point2f(static_cast<float>(p.x), static_cast<float>(p.y));
        to[i] = cv::Point2f(fx, fy);
        distinct[i] = sum / valid - best;
      }
    });
    // The half of the positions that stand out most (texture, relief); flat
    // patches' minima wander in their window.
    std::vector<float> sorted;
    for (float v : distinct)
      if (v > 0) sorted.push_back(v);
    if (sorted.size() < 60) break;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const float cut = sorted[sorted.size() / 2];
    std::vector<cv::Point2f> f2, t2;
    for (size_t i = 0; i < n; ++i)
      if (distinct[i] >= cut) {
        f2.push_back(from[i]);
        t2.push_back(to[i]);
      }
    cv::setRNGSeed(static_cast<int>(seed) + 17 * round);
    std::vector<uchar> inliers;
    cv::Mat R = cv::estimateAffine2D(f2, t2, inliers, cv::RANSAC, 1.0, 500, 0.995, 10);
    if (R.empty() || std::count(inliers.begin(), inliers.end(), 1) * 3 < static_cast<long>(f2.size())) break;
    A = R;
  }
  m.set_linear(linear_part(A));
  return A;
}

// Two different objects: `coherent` on the normals (StyleBlit-style chunks of
// the nearest normal, seams refined), whose normal agreement stays near the
// exact nearest's while the texture stays in chunks.
Expected<Map> different_objects(const ObjectView& destination, const ObjectView& source, const MatchOptions& options,
                                const Progress& progress, const std::string& why) {
  MatchOptions o = options;
  o.method = Method::coherent;
  o.feature = Feature::normals;
  o.patch = 1;
  auto map = fast::compute_map(destination, source, o, progress, nullptr);
  if (!map) return map;
  // Every destination object pixel mapped: a pixel without a normal takes its
  // nearest mapped neighbour's match (the chunk it sits in).
  fill_unmapped(*map, destination.mask);
  map->motion.searched = true;
  map->motion.note = why;
  return map;
}

}  // namespace

Expected<Map> run_combined(const ObjectView& destination, const ObjectView& source, const MatchOptions& options,
                           const Progress& progress) {
  if (destination.images.empty() || destination.images.size() != source.images.size())
    return make_error("combined: both objects need their photos under the same lamps (" +
                      std::to_string(destination.images.size()) + " and " + std::to_string(source.images.size()) +
                      " given)");
  for (const ObjectView* v : {&destination, &source})
    for (const cv::Mat& photo : v->images)
      if ((photo.type() != CV_32FC3 && photo.type() != CV_16FC3) || photo.size() != v->mask.size())
        return make_error(std::string("combined: the ") + (v == &destination ? "destination" : "source") +
                          "'s photos must be CV_32FC3 or CV_16FC3 of the mask's size");
  Weights w;
  const float coherence = 0.05f;  // per broken 4-neighbour, in the units of a squared normal difference
  // Levels: halve until the smaller object's bounding side is about 48 px.
  const cv::Rect bd = cv::boundingRect(destination.mask), bs = cv::boundingRect(source.mask);
  const int side = std::max(1, std::min(std::max(bd.width, bd.height), std::max(bs.width, bs.height)));
  int levels = 1;
  while (levels < 6 && (side >> levels) >= 24) ++levels;
  const int iterations = std::max(1, options.iterations);
  std::vector<cv::Point2i> previous;
  cv::Size previous_size;
  // The object's motion (2x3), at the scale of the level last matched: found
  // on the coarsest level, refitted on each finer one to the matches that
  // follow it, so that at full size it is within a pixel or so (scaled up
  // from the coarsest alone it is off by up to half a coarse pixel, 4 px at
  // 1/8, and the full-size matches no longer seem to follow it).
  cv::Mat level_motion;
  for (int lv = levels - 1; lv >= 0; --lv) {
    Level d, s;
    auto make = [&](const ObjectView& v, Level& out) {
      const Pyramid::Inputs in = downscaled(v, lv);
      out = make_level(in.normals, in.mask, in.images, w);
    };
    tbb::parallel_invoke([&] { make(destination, d); }, [&] { make(source, s); });
    if (s.pixels.empty()) return make_error("combined: the source has no object pixels with normals");
    const std::vector<cv::Point2i> seed = seed_by_normal(d, s);
    // Start: the coarser level's match, scaled up, or the seed; and the
    // object's motion (`guide`, 2x3 at this level's scale) where its patch
    // fits about as well.
    auto initialise = [&](Matcher& m, const cv::Mat& guide) {
      m.match.assign(static_cast<size_t>(d.size.area()), cv::Point2i(-1, -1));
      m.cost.assign(static_cast<size_t>(d.size.area()), 0.0f);
      tbb::parallel_for(tbb::blocked_range<size_t>(0, d.pixels.size(), 2048), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) {
          const cv::Point p = d.pixels[i];
          const size_t at = static_cast<size_t>(p.y) * d.size.width + p.x;
          cv::Point2i best = seed[at];
          float best_cost = s.valid(best.x, best.y) ? m.patch_cost(p.x, p.y, best.x, best.y) : 1e30f;
          if (!previous.empty()) {
            const int cx = std::min(p.x / 2, previous_size.width - 1), cy = std::min(p.y / 2, previous_size.height - 1);
            const cv::Point2i c = previous[static_cast<size_t>(cy) * previous_size.width + cx];
            if (c.x >= 0) {
              const cv::Point o = m.step({p.x - 2 * cx, p.y - 2 * cy});
              const int qx = 2 * c.x + o.x, qy = 2 * c.y + o.y;
              if (s.valid(qx, qy)) {
                const float pc = m.patch_cost(p.x, p.y, qx, qy);
                if (pc < best_cost) {
                  best = {qx, qy};
                  best_cost = pc;
                }
              }
            }
          }
          if (!guide.empty()) {
            const double* A = guide.ptr<double>(0);
            const double* B = guide.ptr<double>(1);
            const int qx = static_cast<int>(std::lround(A[0] * p.x + A[1] * p.y + A[2]));
            const int qy = static_cast<int>(std::lround(B[0] * p.x + B[1] * p.y + B[2]));
            if (s.valid(qx, qy)) {
              const float pc = m.patch_cost(p.x, p.y, qx, qy);
              if (pc <= 1.5f * best_cost + 1e-3f) {
                best = {qx, qy};
                best_cost = pc;
              }
            }
          }
          m.match[at] = best;
          m.cost[at] = best_cost;
        }
      });
    };
    // PatchMatch: propagation (through the motion's linear part), the seed,
    // random search around the best within `max_radius`.
    auto search = [&](Matcher& m, int level_iterations, int max_radius, unsigned salt, int first = 0,
                      bool report = true) {
      const int bands = std::max(1, std::min(64, d.box.height / 16));
      for (int it = first; it < level_iterations; ++it) {
        if (progress.cancelled()) return false;
        const bool forward = it % 2 == 0;
        const int step = forward ? 1 : -1;
        const cv::Point back_x = m.step({-step, 0}), back_y = m.step({0, -step});
        // Bands side by side share a row edge (propagation and coherence read
        // the row beyond it): the even bands run first, then the odd, so each
        // reads a finished neighbour and the result does not depend on which
        // thread got where first (the same map on every run and machine).
        for (int parity = 0; parity < 2; ++parity) tbb::parallel_for(0, (bands + 1 - parity) / 2, [&](int half) {
          const int band = 2 * half + parity;
          std::mt19937 rng(options.seed * 7919u + static_cast<unsigned>(lv * 131 + it * 17 + band) + salt * 104729u);
          const int y0 = d.box.y + d.box.height * band / bands, y1 = d.box.y + d.box.height * (band + 1) / bands;
          const int x0 = d.box.x, x1 = d.box.x + d.box.width;
          for (int y = forward ? y0 : y1 - 1; forward ? y < y1 : y >= y0; y += step) {
            for (int x = forward ? x0 : x1 - 1; forward ? x < x1 : x >= x0; x += step) {
              if (!d.valid(x, y)) continue;
              const size_t at = static_cast<size_t>(y) * d.size.width + x;
              cv::Point2i best = m.match[at];
              float best_patch = m.cost[at];
              float best_total = m.total(x, y, best.x, best.y, best_patch);
              const float wsum = m.patch_weight(x, y);
              // Propagation from the neighbours already visited.
              for (int k = 0; k < 2; ++k) {
                const cv::Point o = k == 0 ? cv::Point(-step, 0) : cv::Point(0, -step);
                const cv::Point so = k == 0 ? back_x : back_y;
                const int nx = x + o.x, ny = y + o.y;
                if (!d.valid(nx, ny)) continue;
                const cv::Point2i q = m.match[static_cast<size_t>(ny) * d.size.width + nx];
                if (q.x < 0) continue;
                m.try_candidate(x, y, wsum, q.x - so.x, q.y - so.y, best, best_patch, best_total);
              }
              // The seed, and random search around the best.
              const cv::Point2i sd = seed[at];
              if (sd.x >= 0) m.try_candidate(x, y, wsum, sd.x, sd.y, best, best_patch, best_total);
              for (int r = max_radius; r >= 1; r /= 2) {
                std::uniform_int_distribution<int> u(-r, r);
                m.try_candidate(x, y, wsum, best.x + u(rng), best.y + u(rng), best, best_patch, best_total);
              }
              m.match[at] = best;
              m.cost[at] = best_patch;
            }
          }
        });
        if (report) progress.report((levels - 1 - lv + (it + 1.0) / level_iterations) / levels, "combined");
      }
      return true;
    };
    Matcher m{d, s, coherence, {}, {}};
    if (lv == levels - 1) {
      // Is the destination the source moved (scaled, turned, cropped)? Then
      // the finer levels follow that motion; else the objects differ, and
      // coherent chunks of the nearest normals serve better than patches
      // (whose shapes differ between objects).
      // Patches compare only at about the right scale and turn, so the search
      // runs under each guess of the motion the masks give (their areas'
      // ratio, their principal axes, quarter turns), the likeliest first,
      // until one is followed by half the matches; the best is kept.
      // At this size a scaled and turned copy's integer matches are coarse:
      // a motion a third of them follow is taken as a guess here; the full
      // size decides (a majority follows it there, and it keeps the normals).
      // An object whose features hardly vary (flat and of one colour) can be
      // placed anywhere: no motion is sought, and the note says why.
      if (const std::string flat = featureless(d, s); !flat.empty())
        return different_objects(destination, source, options, progress,
                                 flat.substr(0, flat.size() - 2) + ": no motion sought");
      const std::vector<MotionGuess> guesses = guess_motions(d, s);
      // Each guess is screened by one pass of the search; the best (or the
      // first a majority follows) gets the remaining passes. A pass at this
      // size is too small to keep both cores busy, so the guesses are
      // screened as many at a time as there are threads (each from its own
      // seeds, taken in order: the same choice as one at a time; issue 48).
      const int radius = std::max(s.size.width, s.size.height);
      double best_share = -1;
      size_t best_guess = 0;
      struct Screened {
        std::unique_ptr<Matcher> trial;
        double share = 0;
        bool ok = false;
      };
      const size_t at_once = static_cast<size_t>(std::max(1, tbb::this_task_arena::max_concurrency()));
      bool decided = false;
      for (size_t first = 0; first < guesses.size() && !decided; first += at_once) {
        const size_t last = std::min(guesses.size(), first + at_once);
        std::vector<Screened> screened(last - first);
        tbb::parallel_for(first, last, [&](size_t g) {
          Screened& sc = screened[g - first];
          sc.trial = std::make_unique<Matcher>(Matcher{d, s, coherence, {}, {}});
          sc.trial->set_linear(guesses[g].linear);
          initialise(*sc.trial, guesses[g].motion);
          if (!search(*sc.trial, 1, radius, static_cast<unsigned>(g), 0, false)) return;
          global_motion(d, sc.trial->match, options.seed, &sc.share, 0.35);
          sc.ok = true;
        });
        for (size_t g = first; g < last; ++g) {
          Screened& sc = screened[g - first];
          if (!sc.ok) return make_error("cancelled during combined");
          if (sc.share > best_share) {
            best_share = sc.share;
            best_guess = g;
            m.match = std::move(sc.trial->match);
            m.cost = std::move(sc.trial->cost);
            m.set_linear(sc.trial->linear);
          }
          if (sc.share >= 0.5) {
            decided = true;
            break;
          }
        }
        progress.report((static_cast<double>(last) / guesses.size() / iterations) / levels, "combined");
      }
      if (!search(m, iterations, radius, static_cast<unsigned>(best_guess), 1))
        return make_error("cancelled during combined");
      level_motion = global_motion(d, m.match, options.seed, &best_share, 0.35);
      if (level_motion.empty())
        return different_objects(destination, source, options, progress,
                                 "no one motion (scale " + scale_range(guesses) +
                                     ", turned, cropped; " + std::to_string(guesses.size()) +
                                     " guesses from the masks) moves the destination onto the source: at 1/" +
                                     std::to_string(1 << lv) + " size the best is followed by " +
                                     std::to_string(static_cast<int>(100 * best_share)) +
                                     " % of the matches (35 % needed)");
      m.set_linear(linear_part(level_motion));
    } else {
      m.set_linear(linear_part(level_motion));
      cv::Mat guide = level_motion.clone();
      guide.at<double>(0, 2) *= 2.0;
      guide.at<double>(1, 2) *= 2.0;
      initialise(m, guide);
      if (!search(m, std::min(iterations, 2), 4, 0)) return make_error("cancelled during combined");
      if (lv > 0) {
        cv::Mat refit = refit_motion(d, m.match, guide, 1.0);
        level_motion = polish_motion(m, refit.empty() ? guide : refit, options.seed, 1);
      }
    }
    if (lv == 0) {
      // One motion for the whole object (the destination is the source moved,
      // scaled, turned or cropped): an affine fit to the matches by RANSAC.
      // When most pixels follow it, it is taken wherever its patch fits about
      // as well as the pixel's own match (where the photos can't tell, the
      // object's motion can), at its exact sub-pixel position.
      std::vector<uint8_t> on_motion(static_cast<size_t>(d.size.area()), 0);
      cv::Mat motion = global_motion(d, m.match, options.seed);
      // Fine matches are noisier than coarse ones (a resampled copy's patches
      // differ pixel by pixel): without a majority at full size, the coarse
      // motion, scaled up, is refitted to the matches that follow it.
      if (motion.empty()) motion = refit_motion(d, m.match, level_motion, levels > 1 ? 2.0 : 1.0);
      // Two similar blobs can follow one affine motion too: it is the same
      // object only when the motion also keeps the normals about as well as
      // the nearest normal does for each pixel.
      // (No motion at full size either: not one object moved after all.)
      if (motion.empty())
        return different_objects(destination, source, options, progress,
                                 "the motion found at 1/" + std::to_string(1 << (levels - 1)) +
                                     " size is not followed at full size");
      motion = polish_motion(m, motion, options.seed);
      std::string why;
      if (!motion_keeps_normals(d, s, motion, seed, &why))
        return different_objects(destination, source, options, progress, why + ": not one object moved");
      m.set_linear(linear_part(motion));
      if (!motion.empty()) {
        const double a = motion.at<double>(0, 0), b = motion.at<double>(0, 1), c = motion.at<double>(0, 2);
        const double e = motion.at<double>(1, 0), f = motion.at<double>(1, 1), g = motion.at<double>(1, 2);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, d.pixels.size(), 1024), [&](const tbb::blocked_range<size_t>& r) {
          for (size_t i = r.begin(); i != r.end(); ++i) {
            const cv::Point p = d.pixels[i];
            const size_t at = static_cast<size_t>(p.y) * d.size.width + p.x;
            const double tx = a * p.x + b * p.y + c, ty = e * p.x + f * p.y + g;
            const int qx = static_cast<int>(std::lround(tx)), qy = static_cast<int>(std::lround(ty));
            if (!s.valid(qx, qy)) continue;
            const float pc = m.patch_cost(p.x, p.y, qx, qy);
            if (pc <= 1.5f * m.cost[at] + 1e-3f) {
              m.match[at] = {qx, qy};
              m.cost[at] = pc;
              on_motion[at] = 1;
            }
          }
        });
      }
      // Sub-pixel: the mean of the motions of the neighbours within 2 px that
      // agree with the pixel's own to a pixel (a smooth scale or turn shows
      // between the integer matches).
      Map map;
      map.xy = cv::Mat(d.size, CV_32FC2, cv::Scalar(-1, -1));
      map.distance = cv::Mat(d.size, CV_32F, cv::Scalar(0));
      map.motion.searched = true;
      map.motion.found = true;
      map.motion.affine = cv::Matx23d(motion);
      map.motion.share = d.pixels.empty() ? 0.0
                                          : static_cast<double>(std::count(on_motion.begin(), on_motion.end(), 1)) /
                                                d.pixels.size();
      tbb::parallel_for(tbb::blocked_range<size_t>(0, d.pixels.size(), 1024), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i != r.end(); ++i) {
          const cv::Point p = d.pixels[i];
          const size_t at = static_cast<size_t>(p.y) * d.size.width + p.x;
          const cv::Point2i q = m.match[at];
          if (q.x < 0) continue;
          if (on_motion[at]) {
            const double* A = motion.ptr<double>(0);
            const double* B = motion.ptr<double>(1);
            map.xy.at<cv::Vec2f>(p) = cv::Vec2f(static_cast<float>(A[0] * p.x + A[1] * p.y + A[2]),
                                                static_cast<float>(B[0] * p.x + B[1] * p.y + B[2]));
            map.distance.at<float>(p) = std::sqrt(m.cost[at]);
            continue;
          }
          double sx = q.x, sy = q.y;
          int n = 1;
          for (int oy = -2; oy <= 2; ++oy)
            for (int ox = -2; ox <= 2; ++ox) {
              if (!ox && !oy) continue;
              const int nx = p.x + ox, ny = p.y + oy;
              if (!d.valid(nx, ny)) continue;
              const cv::Point2i o = m.match[static_cast<size_t>(ny) * d.size.width + nx];
              if (o.x < 0) continue;
              const int px = o.x - ox, py = o.y - oy;
              if (std::abs(px - q.x) > 1 || std::abs(py - q.y) > 1) continue;
              sx += px;
              sy += py;
              ++n;
            }
          float fx = static_cast<float>(sx / n), fy = static_cast<float>(sy / n);
          // Stay on the source object: keep the integer match when the mean leaves it.
          if (!s.valid(static_cast<int>(std::lround(fx)), static_cast<int>(std::lround(fy)))) {
            fx = static_cast<float>(q.x);
            fy = static_cast<float>(q.y);
          }
          map.xy.at<cv::Vec2f>(p) = cv::Vec2f(fx, fy);
          map.distance.at<float>(p) = std::sqrt(m.cost[at]);
        }
      });
      return map;
    }
    previous = std::move(m.match);
    previous_size = d.size;
  }
  return make_error("unreachable");
}

}  // namespace veneer::match::fast
