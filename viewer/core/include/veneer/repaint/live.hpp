#pragma once
// Live repaint: every frame of the source's live video, carried through the
// map onto the destination. The map is turned once into gather tables scaled
// to the frame size, so each frame costs one parallel gather (cv::remap with
// nearest neighbour) and stays within a couple of milliseconds at 1024x680.
#include <opencv2/core.hpp>

#include <memory>

#include "veneer/match/fast.hpp"
#include "veneer/match/matcher.hpp"

namespace veneer::repaint {

using match::Map;
namespace fast = match::fast;

class LiveRepainter {
 public:
  LiveRepainter() = default;
  // `map` was computed against a source of `source_size` pixels. `backdrop`
  // (8-bit BGR, any size; resized to the map's) shows where the destination
  // is not mapped — usually the destination's own picture; empty = black.
  // `blend` (optional, TransferResult::blend): frames are blended as the
  // transfer's pictures were (each frame brought to the source's size first).
  LiveRepainter(const Map& map, cv::Size source_size, const cv::Mat& backdrop = {},
                std::shared_ptr<const fast::BlendPlan> blend = nullptr);

  bool ready() const { return !map_xy_.empty(); }
  cv::Size destination_size() const { return map_xy_.size(); }

  // `frame`: 8-bit BGR (or CV_32FC3) of the source, any size with the source's
  // aspect (coordinates are scaled by frame/source size). Returns the
  // destination-sized picture of the same type as `frame`.
  cv::Mat apply(const cv::Mat& frame);
  // The same for a frame in which the source has moved: `source_to_frame`
  // takes the map's source pixels (at source_size) to the frame's pixels
  // (registration, match/track.hpp). Each frame's gather table is made anew
  // (one pass over the destination) and sampled bilinearly; with a blend,
  // the frame is first warped back onto the source's pixels.
  cv::Mat apply(const cv::Mat& frame, const cv::Matx23d& source_to_frame);
  // A moved frame sampled bilinearly (default) or at the nearest pixel (as
  // the fixed lookup is; bench_track: about a third of the cost on a loaded
  // 2-core machine, at up to half a pixel of jitter).
  void set_bilinear(bool on) { bilinear_ = on; }

 private:
  void prepare(cv::Size frame_size);

  cv::Mat map_xy_;        // CV_32FC2 source coordinates at source_size_, -1 unmapped
  cv::Size source_size_;
  cv::Mat backdrop_;      // 8-bit BGR at the destination size
  cv::Mat mask_;          // CV_8UC1 255 where mapped
  cv::Size prepared_for_;
  cv::Mat table_x_, table_y_;  // CV_32FC1 gather tables for the current frame size
  cv::Mat map_nan_;       // map_xy_ with NaN where unmapped
  cv::Rect mapped_box_;   // the mapped destination pixels' bounding box
  bool bilinear_ = true;
  cv::Mat table_float_;   // a moved frame's gather table (CV_32FC2)
  cv::Mat table_xy_, table_frac_;  // the same in remap's fixed point (CV_16SC2 + CV_16UC1)
  std::shared_ptr<const fast::BlendPlan> blend_;
};

}  // namespace veneer::repaint
