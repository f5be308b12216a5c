// The `combined` correspondence: a multi-scale PatchMatch over everything the
// rig gives for a pixel, with a coherence term (see combined.hpp).
#include "combined.hpp"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <string>
#include <random>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

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
        const cv::Vec3f c = images[j].at<cv::Vec3f>(y, x);
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
  cv::resize(v.normals, in.normals, small, 0, 0, cv::INTER_AREA);
  for (auto it = in.normals.begin<cv::Vec3f>(); it != in.normals.end<cv::Vec3f>(); ++it) {
    cv::Vec3f& n = *it;
    const float len = std::sqrt(n.dot(n));
    if (len > 1e-6f) n /= len;
  }
  cv::Mat mf;
  v.mask.convertTo(mf, CV_32F, 1.0 / 255);
  cv::resize(mf, mf, small, 0, 0, cv::INTER_AREA);
  in.mask = mf > 0.5;
  in.images.resize(v.images.size());
  for (size_t j = 0; j < v.images.size(); ++j) cv::resize(v.images[j], in.images[j], small, 0, 0, cv::INTER_AREA);
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

  float patch_cost(int px, int py, int qx, int qy) const {
    float total = 0, wsum = 0;
    for (size_t k = 0; k < kOffsets.size(); ++k) {
      const int dx = px + kOffsets[k].x, dy = py + kOffsets[k].y;
      if (!d.valid(dx, dy)) continue;
      const int sx = qx + kOffsets[k].x, sy = qy + kOffsets[k].y;
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
  // one pixel off the neighbour's own step (a uniform scale of 0.5..1.5 stays within it).
  float incoherence(int px, int py, int qx, int qy) const {
    int broken = 0;
    for (const cv::Point o : {cv::Point(1, 0), cv::Point(-1, 0), cv::Point(0, 1), cv::Point(0, -1)}) {
      const int nx = px + o.x, ny = py + o.y;
      if (!d.valid(nx, ny)) continue;
      const cv::Point2i m = match[static_cast<size_t>(ny) * d.size.width + nx];
      if (m.x < 0) continue;
      const int ex = m.x - qx - o.x, ey = m.y - qy - o.y;
      if (ex * ex + ey * ey > 1) ++broken;
    }
    return coherence * broken;
  }
  float total(int px, int py, int qx, int qy, float patch) const { return patch + incoherence(px, py, qx, qy); }

  // Tries (qx, qy) for p; keeps it when better.
  inline void try_candidate(int px, int py, int qx, int qy, cv::Point2i& best, float& best_patch, float& best_total) const {
    if (!s.valid(qx, qy) || (qx == best.x && qy == best.y)) return;
    const float pc = patch_cost(px, py, qx, qy);
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
  if (why)
    *why = "the motion keeps the normals to " + std::to_string(m) + " deg (median), the nearest normal to " +
           std::to_string(n);
  return m <= std::max(4.0, 3.0 * n);
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
    Matcher m{d, s, coherence, {}, {}};
    m.match.assign(static_cast<size_t>(d.size.area()), cv::Point2i(-1, -1));
    m.cost.assign(static_cast<size_t>(d.size.area()), 0.0f);
    const std::vector<cv::Point2i> seed = seed_by_normal(d, s);
    // Start: the coarser level's match, scaled up, or the seed.
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
            const int qx = 2 * c.x + (p.x - 2 * cx), qy = 2 * c.y + (p.y - 2 * cy);
            if (s.valid(qx, qy)) {
              const float pc = m.patch_cost(p.x, p.y, qx, qy);
              if (pc < best_cost) {
                best = {qx, qy};
                best_cost = pc;
              }
            }
          }
        }
        if (!level_motion.empty()) {
          // The object's motion found on the coarser level, at this level's scale.
          const double* A = level_motion.ptr<double>(0);
          const double* B = level_motion.ptr<double>(1);
          const int qx = static_cast<int>(std::lround(A[0] * p.x + A[1] * p.y + A[2] * 2.0));
          const int qy = static_cast<int>(std::lround(B[0] * p.x + B[1] * p.y + B[2] * 2.0));
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
    // Search radius: the whole source at the coarsest level, a few pixels below it.
    const int max_radius = lv == levels - 1 ? std::max(s.size.width, s.size.height) : 4;
    const int bands = std::max(1, std::min(64, d.box.height / 16));
    const int level_iterations = lv == levels - 1 ? iterations : std::min(iterations, 2);
    for (int it = 0; it < level_iterations; ++it) {
      if (progress.cancelled()) return make_error("cancelled during combined");
      const bool forward = it % 2 == 0;
      tbb::parallel_for(0, bands, [&](int band) {
        std::mt19937 rng(options.seed * 7919u + static_cast<unsigned>(lv * 131 + it * 17 + band));
        const int y0 = d.box.y + d.box.height * band / bands, y1 = d.box.y + d.box.height * (band + 1) / bands;
        const int x0 = d.box.x, x1 = d.box.x + d.box.width;
        const int step = forward ? 1 : -1;
        for (int y = forward ? y0 : y1 - 1; forward ? y < y1 : y >= y0; y += step) {
          for (int x = forward ? x0 : x1 - 1; forward ? x < x1 : x >= x0; x += step) {
            if (!d.valid(x, y)) continue;
            const size_t at = static_cast<size_t>(y) * d.size.width + x;
            cv::Point2i best = m.match[at];
            float best_patch = m.cost[at];
            float best_total = m.total(x, y, best.x, best.y, best_patch);
            // Propagation from the neighbours already visited.
            for (const cv::Point o : {cv::Point(-step, 0), cv::Point(0, -step)}) {
              const int nx = x + o.x, ny = y + o.y;
              if (!d.valid(nx, ny)) continue;
              const cv::Point2i q = m.match[static_cast<size_t>(ny) * d.size.width + nx];
              if (q.x < 0) continue;
              m.try_candidate(x, y, q.x - o.x, q.y - o.y, best, best_patch, best_total);
            }
            // The seed, and random search around the best.
            const cv::Point2i sd = seed[at];
            if (sd.x >= 0) m.try_candidate(x, y, sd.x, sd.y, best, best_patch, best_total);
            for (int r = max_radius; r >= 1; r /= 2) {
              std::uniform_int_distribution<int> u(-r, r);
              m.try_candidate(x, y, best.x + u(rng), best.y + u(rng), best, best_patch, best_total);
            }
            m.match[at] = best;
            m.cost[at] = best_patch;
          }
        }
      });
      progress.report((levels - 1 - lv + (it + 1.0) / level_iterations) / levels, "combined");
    }
    if (lv == levels - 1) {
      // Is the destination the source moved (scaled, turned, cropped)? Then
      // the finer levels follow that motion; else the objects differ, and
      // coherent chunks of the nearest normals serve better than patches
      // (whose shapes differ between objects).
      // At this size a scaled and turned copy's integer matches are coarse:
      // a motion a third of them follow is taken as a guess here; the full
      // size decides (a majority follows it there, and it keeps the normals).
      double share = 0;
      level_motion = global_motion(d, m.match, options.seed, &share, 0.35);
      if (level_motion.empty())
        return different_objects(destination, source, options, progress,
                                 "no motion at 1/" + std::to_string(1 << lv) + " size: the best follows " +
                                     std::to_string(static_cast<int>(100 * share)) + " % of the matches (35 % needed)");
    } else if (lv > 0 && !level_motion.empty()) {
      cv::Mat up = level_motion.clone();
      up.at<double>(0, 2) *= 2.0;
      up.at<double>(1, 2) *= 2.0;
      cv::Mat refit = refit_motion(d, m.match, up, 1.0);
      level_motion = refit.empty() ? up : refit;
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
      std::string why;
      if (!motion_keeps_normals(d, s, motion, seed, &why))
        return different_objects(destination, source, options, progress, why + ": not one object moved");
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
