#include "veneer/repaint/live.hpp"

#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

namespace veneer::repaint {

LiveRepainter::LiveRepainter(const Map& map, cv::Size source_size, const cv::Mat& backdrop,
                             std::shared_ptr<const fast::BlendPlan> blend)
    : map_xy_(map.xy.clone()), source_size_(source_size), blend_(std::move(blend)) {
  if (blend_ && (blend_->destination_size != map.xy.size() || blend_->source_size != source_size)) blend_.reset();
  cv::Mat channels[2];
  cv::split(map_xy_, channels);
  mask_ = channels[0] >= 0;
  mapped_box_ = cv::boundingRect(mask_);
  map_nan_ = map_xy_.clone();
  map_nan_.setTo(cv::Scalar::all(std::numeric_limits<float>::quiet_NaN()), ~mask_);
  if (!backdrop.empty()) {
    cv::Mat b = backdrop;
    if (b.type() != CV_8UC3) b.convertTo(b, CV_8UC3, 255.0);
    if (b.size() != map_xy_.size()) cv::resize(b, b, map_xy_.size(), 0, 0, cv::INTER_AREA);
    backdrop_ = b;
  }
}

void LiveRepainter::prepare(cv::Size frame_size) {
  const float sx = static_cast<float>(frame_size.width) / static_cast<float>(source_size_.width);
  const float sy = static_cast<float>(frame_size.height) / static_cast<float>(source_size_.height);
  table_x_.create(map_xy_.size(), CV_32FC1);
  table_y_.create(map_xy_.size(), CV_32FC1);
  for (int y = 0; y < map_xy_.rows; ++y) {
    const cv::Vec2f* m = map_xy_.ptr<cv::Vec2f>(y);
    float* tx = table_x_.ptr<float>(y);
    float* ty = table_y_.ptr<float>(y);
    for (int x = 0; x < map_xy_.cols; ++x) {
      // Pixel centres: source pixel (u, v) covers [u, u+1) at source size, so
      // its centre lands at (u + 0.5) * s - 0.5 in the frame.
      const bool mapped = m[x][0] >= 0;
      tx[x] = mapped ? (m[x][0] + 0.5f) * sx - 0.5f : -1e6f;
      ty[x] = mapped ? (m[x][1] + 0.5f) * sy - 0.5f : -1e6f;
    }
  }
  prepared_for_ = frame_size;
}

cv::Mat LiveRepainter::apply(const cv::Mat& frame) {
  if (!ready() || frame.empty()) return {};
  if (frame.size() != prepared_for_) prepare(frame.size());
  cv::Mat background;
  if (!backdrop_.empty()) {
    if (frame.type() == CV_8UC3) {
      background = backdrop_.clone();
    } else {
      backdrop_.convertTo(background, frame.type(), 1.0 / 255.0);
    }
  } else {
    background = cv::Mat(map_xy_.size(), frame.type(), cv::Scalar::all(0));
  }
  if (blend_ && (frame.type() == CV_8UC3 || frame.type() == CV_32FC3)) {
    // the frame at the source's size, through the blend's weights: only the
    // mapped pixels are touched (the frame is not converted as a whole)
    cv::Mat at_source = frame;
    if (at_source.size() != source_size_) cv::resize(frame, at_source, source_size_, 0, 0, cv::INTER_AREA);
    if (fast::apply_blend(*blend_, at_source, background)) return background;
  }
  // Unmapped pixels point far outside the frame, so BORDER_TRANSPARENT keeps
  // the backdrop there; mapped ones gather their source pixel.
  cv::remap(frame, background, table_x_, table_y_, cv::INTER_NEAREST, cv::BORDER_TRANSPARENT);
  return background;
}

cv::Mat LiveRepainter::apply(const cv::Mat& frame, const cv::Matx23d& source_to_frame) {
  if (!ready() || frame.empty()) return {};
  if (blend_) {
    cv::Mat at_source;
    cv::warpAffine(frame, at_source, cv::Mat(source_to_frame), source_size_, cv::INTER_LINEAR | cv::WARP_INVERSE_MAP,
                   cv::BORDER_REPLICATE);
    return apply(at_source);
  }
  cv::Mat background;
  if (!backdrop_.empty()) {
    if (frame.type() == CV_8UC3) background = backdrop_.clone();
    else backdrop_.convertTo(background, frame.type(), 1.0 / 255.0);
  } else {
    background = cv::Mat(map_xy_.size(), frame.type(), cv::Scalar::all(0));
  }
  // The gather table is the map carried by the motion: one SIMD affine
  // transform of the map's coordinates (unmapped ones are NaN and stay NaN),
  // turned into remap's fixed-point form (NaN lands far outside the frame, so
  // BORDER_TRANSPARENT keeps the backdrop there), then one bilinear remap.
  // Each step is OpenCV's vectorised, threaded code: a hand-written fused
  // loop was 3-4x slower than this at 1024x680 (scalar bilinear on 3 bytes).
  // Only the box of the mapped destination pixels is touched (a real map
  // covers the destination object, not the whole frame).
  prepared_for_ = {};  // the tables no longer hold the fixed lookup
  if (mapped_box_.empty()) return background;
  cv::transform(map_nan_(mapped_box_), table_float_, cv::Matx23f(source_to_frame));
  cv::Mat box = background(mapped_box_);
  if (bilinear_) {
    cv::convertMaps(table_float_, cv::noArray(), table_xy_, table_frac_, CV_16SC2);
    cv::remap(frame, box, table_xy_, table_frac_, cv::INTER_LINEAR, cv::BORDER_TRANSPARENT);
  } else {
    cv::convertMaps(table_float_, cv::noArray(), table_xy_, cv::noArray(), CV_16SC2, true);
    cv::remap(frame, box, table_xy_, cv::noArray(), cv::INTER_NEAREST, cv::BORDER_TRANSPARENT);
  }
  return background;
}

}  // namespace veneer::repaint
