#pragma once
// Repainting: the destination with the source's photo pasted through a map
// (plain or blended across seams), and the pictures of a map a user looks at.
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/match/fast.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::repaint {

using match::Map;
namespace fast = match::fast;

cv::Mat median_photo(const std::vector<cv::Mat>& photos);  // per-pixel, per-channel median
// The live view's backdrop: per pixel the photo that lights it second most (grey; the brightest when there
// is one photo), so no lamp's shadow stays in it -- the median photo keeps every shadow most lamps cast
// (behind the object, under it), which then stood still around the object while the live lamp moved
// (issue 47) -- and a highlight of one lamp does not either. Linear CV_32FC3.
cv::Mat lit_photo(const std::vector<cv::Mat>& photos);
// The destination `backdrop` with the source's `photo` pasted through `map`
// (linear BGR CV_32FC3; backdrop may be empty = black).
cv::Mat repaint(const Map& map, const cv::Mat& photo, const cv::Mat& backdrop = {});
// The same with the chunks blended (StyleBlit's optional blending,
// fast::blend_repaint): each mapped pixel averages its neighbours' matches
// within `radius` px continued to it, Gaussian-weighted. Inside a chunk they
// all agree, so texture stays sharp; seams and speckle are softened.
// `source_mask` (CV_8UC1, empty = all) keeps continuations on the object.
// `guide` (optional): proposals weighed by how well their source normal fits
// the destination's, so outlines stay sharp (fast::BlendGuide).
// radius 0 = repaint(). Fails, naming it, on a radius outside 0..16 or a
// mask or guide that does not fit the photo.
Expected<cv::Mat> repaint_blended(const Map& map, const cv::Mat& photo, const cv::Mat& source_mask, int radius,
                                  const cv::Mat& backdrop = {}, const fast::BlendGuide* guide = nullptr);
// `backdrop` (empty = black) with the plan's pixels blended from `photo`
// (a plan from fast::blend_plan, made once and used for many photos).
Expected<cv::Mat> repaint_planned(const fast::BlendPlan& plan, const cv::Mat& photo, const cv::Mat& backdrop = {});
// How well each match fits (8-bit BGR): white = distance 0, black = 4x the
// median distance or more, or not mapped.
cv::Mat confidence_picture(const Map& map);
// The thesis's picture of a map: R = x / width, G = y / height, B = 1 (8-bit BGR), black unmapped.
cv::Mat map_picture(const Map& map, cv::Size source_size);
// Reuse counts as a heat map over the grey source picture (8-bit BGR).
cv::Mat reuse_picture(const cv::Mat& counts, const cv::Mat& source_photo);

// The thesis's origin tool: destination (left) and source (right) side by
// side (linear photos, tonemapped), a line from each chosen destination pixel
// to its source pixel; unmapped points get a red cross.
cv::Mat origin_picture(const Map& map, const cv::Mat& destination_photo, const cv::Mat& source_photo,
                       const std::vector<cv::Point>& points);
// About `count` mapped destination pixels spread over the object (a grid), for origin_picture.
std::vector<cv::Point> spread_points(const Map& map, int count);


}  // namespace veneer::repaint
