#pragma once
// Correspondence: for every destination pixel, the source pixel whose
// appearance should be shown there (DESIGN.md "correspondence map").
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::match {

enum class Feature { normals, intensities };
enum class Method { linear, flann, candidates, patchmatch, regiongrow, baseline, coherent, combined };
const char* method_name(Method);
const char* feature_name(Feature);
Expected<Method> parse_method(const std::string&);
Expected<Feature> parse_feature(const std::string&);

// One object as the matcher sees it.
struct ObjectView {
  cv::Mat normals;              // CV_32FC3 x,y,z (rig frame)
  cv::Mat mask;                 // CV_8UC1, 255 = object; only these pixels take part
  std::vector<cv::Mat> images;  // CV_32FC3 BGR, one per lamp (intensity feature, `combined`, repaint);
                                // `combined` also reads CV_16FC3 (half floats, widened as it reads them)
  std::vector<std::string> lamps;  // optional lamp ids, one per image: when both views give them,
                                   // the intensity feature requires the same lamps in the same order
};

// The correspondence map (DESIGN.md): xy = source x, y in pixels (CV_32FC2),
// -1,-1 where a destination pixel is not mapped; distance = match distance (CV_32F).
// What `combined` made of one motion of the whole object (the destination
// the source moved, scaled, turned or cropped): whether it looked (the other
// methods do not), whether it found and took one, and if not, why.
struct ObjectMotion {
  bool searched = false;
  bool found = false;
  cv::Matx23d affine{1, 0, 0, 0, 1, 0};  // source pixel = affine * destination pixel (when found)
  double share = 0;                       // destination object pixels the motion maps (when found), 0..1
  std::string note;                       // why no motion was taken ("" when found)
};

struct Map {
  Map() = default;
  Map(cv::Mat xy_, cv::Mat distance_, ObjectMotion motion_ = {})
      : xy(std::move(xy_)), distance(std::move(distance_)), motion(std::move(motion_)) {}
  cv::Mat xy;
  cv::Mat distance;
  ObjectMotion motion;
  bool valid(int x, int y) const { return xy.at<cv::Vec2f>(y, x)[0] >= 0; }
};

struct MatchOptions {
  Method method = Method::linear;      // which algorithm
  Feature feature = Feature::normals;  // what is compared
  int patch = 1;                       // patch side: 1, 3, 5 or 7 (mirrored borders)
  int candidates = 10;                 // K for `candidates` (1..100)
  double threshold = 0.05;             // `regiongrow` smoothness threshold (>= 0; 0 = direct matching)
  int iterations = 5;                  // `patchmatch` iterations; `combined`: iterations per pyramid level
  double coherent_threshold = 0.10;    // `coherent` normal error allowed for a chunk, radians-ish (|dn|); on
                                       // intensities converted when the destination has normals (fast engine)
  double uniformity = 0.0;             // reuse penalty weight for `coherent`/`patchmatch` (0 = off)
  bool coherent_grow = true;           // `coherent`: chunks grow into the pixels no chunk took
  double coherent_smooth = 2.0;        // `coherent`: a broken neighbour pair costs this x coherent_threshold (0 = off)
  int coherent_sweeps = 4;             // `coherent`: at most this many refinement rounds
  double coherent_guide = 0.0;         // `coherent` on normals: match against the source's normals smoothed
                                       // over this many px (Gaussian sigma, 0..32; 0 = off), so its small
                                       // relief (dimples, grain) is copied whole as texture
  bool fast = true;                    // use the fast engine where it applies (false = faithful thesis code)
  unsigned seed = 1;                   // random init/jitter seed (same seed, same map)
  int threads = 0;                     // 0 = all cores
  Status check() const;
  bool operator==(const MatchOptions&) const = default;  // the same options make the same map
};

Expected<Map> compute_map(const ObjectView& destination, const ObjectView& source,
                          const MatchOptions& options, const Progress& progress = {});

}  // namespace veneer::match
