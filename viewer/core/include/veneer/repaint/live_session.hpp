#pragma once
// One live view's session (issue 27), what the viewer's Live tab and
// `veneer repaint --video` / `veneer rig live` run per frame: each frame is
// registered to the source's stills (match/track.hpp), carried through the
// map onto the destination (match/live.hpp), and reported with the source's
// outline where it was found, a quality figure and a lost state.
//
// A live view need not frame like the stills: cameras show a 16:9 crop of a
// 3:2 sensor at another size. The first frame of another size than the
// stills is related to them once per session as a single uniform scale plus
// an offset (the crop), never separate x and y scales: the candidates a
// camera makes (the stills' full width or full height, centred) are each
// refined by the tracker's ECC on the object, and one is taken only when the
// estimate is uniform (x and y scales within 3 %) and correlates; otherwise
// the session refuses, naming both geometries. A live view smaller than the
// stills (a camera's 1024 px live view of 21 Mpx stills) is tracked on the
// stills reduced to its scale, so ECC compares pictures of one resolution.
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/match/fast.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/repaint/live.hpp"
#include "veneer/repaint/live_look.hpp"
#include "veneer/repaint/look.hpp"
#include "veneer/repaint/track.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::repaint {

using match::Map;
namespace fast = match::fast;

// How a live view shows the stills: live pixel = scale * still pixel + offset.
struct LiveGeometry {
  cv::Size still, live;
  double scale = 1.0;          // live pixels per still pixel, the same in x and y
  cv::Vec2d offset{0, 0};      // [live px]; a crop shows as a negative offset
  double correlation = 0;      // ECC's on the frame it was found on
  bool same = true;            // the live view has the stills' size: taken as framed alike, not searched
  // "320x180 (16:9) shows the stills' 256x170 (3:2) at x1.250, crop from still (0.0, 13.2) px"
  std::string describe() const;
};

// "1024x680 (3:2)"
std::string describe_size(cv::Size size);

struct LiveFrame {
  cv::Mat repainted;                // destination-sized 8-bit BGR: the frame through the map, or the
                                    // lost picture (the backdrop dimmed, "LOST")
  std::vector<cv::Point2f> outline; // the source's outline in the frame where registration put it (frame px)
  double quality = 0;               // ECC correlation (0..1; lost below TrackOptions::min_correlation)
  bool lost = false;                // registration failed: `repainted` is not to be trusted
  cv::Matx23d still_to_frame = cv::Matx23d(1, 0, 0, 0, 1, 0);
  double track_ms = 0, repaint_ms = 0;
  Look look = Look::copy;           // what `repainted` shows: the shaded look at the frame's light, or the
                                    // pixel copy (the copy look, no LiveLook, a lost frame, or the fallback)
  std::optional<LiveLight> light;   // the light estimated in the frame (shaded look, frame not lost); when
                                    // one lamp does not explain it, `light->fallback` says what was painted:
                                    // "held the last good light" (for LightEstimateOptions::hold_frames
                                    // frames) or "pixel copy"
  double light_ms = 0, shade_ms = 0;  // of repaint_ms: the light estimate, and the painting at it
};

class LiveSession {
 public:
  // `photos`: the source set's photos (linear CV_32FC3, one per lamp) and
  // `mask` the object in them (CV_8UC1, the stills' size); `map` was made
  // against the source at `source_size` (the map's scale; the stills when
  // equal); `backdrop` (8-bit BGR) shows where the destination is not
  // mapped; `blend` as LiveRepainter's.
  LiveSession(const std::vector<cv::Mat>& photos, const cv::Mat& mask, const Map& map, cv::Size source_size,
              const cv::Mat& backdrop = {}, std::shared_ptr<const fast::BlendPlan> blend = nullptr,
              const TrackOptions& options = {});
  // The same with the live look (live_look.hpp) made for `map`: frames are
  // painted shaded by default (set_look). The old constructor above paints
  // the pixel copy only.
  LiveSession(const std::vector<cv::Mat>& photos, const cv::Mat& mask, const Map& map, cv::Size source_size,
              std::shared_ptr<const LiveLook> live_look, const cv::Mat& backdrop = {},
              std::shared_ptr<const fast::BlendPlan> blend = nullptr, const TrackOptions& options = {});
  // (frames are gathered at the nearest pixel unless set_smooth(true))
  bool ready() const { return tracker_.ready() && repainter_.ready(); }
  // Tracks and repaints one frame (8-bit BGR). The first frame fixes the
  // live geometry; an error (naming both geometries) when it cannot be
  // related to the stills, or when a later frame changes size.
  Expected<LiveFrame> process(const cv::Mat& frame);
  // Without registration: the stills' pose carried by the live geometry (the old live view).
  Expected<LiveFrame> process_untracked(const cv::Mat& frame);
  const std::optional<LiveGeometry>& geometry() const { return geometry_; }
  // Frames gathered bilinearly instead of at the nearest pixel (the live
  // default: bench_track, 1024x680 on the loaded 2-core machine, the
  // bilinear gather alone took 8-12 ms median, the nearest 1-2 ms, at up to
  // half a pixel of jitter). `veneer repaint --video` turns it on.
  void set_smooth(bool on) { repainter_.set_bilinear(on); }
  // Shaded (the default; needs the LiveLook constructor, else frames stay the
  // copy) or the pixel copy through the map.
  void set_look(Look look) { look_ = look; }
  Look look() const { return look_; }
  bool has_live_look() const { return live_look_ != nullptr; }
  // A new session on the same sets (the object was put back, the camera moved).
  void reset();
  const cv::Mat& still_mask() const { return mask_; }

 private:
  Expected<LiveFrame> run(const cv::Mat& frame, bool track);
  // Relates the first frame to the stills (see above); a live view smaller
  // than the stills is tracked on the stills reduced to its scale.
  Status fix_geometry(const cv::Mat& frame);
  struct Reduced;
  std::shared_ptr<Reduced> reduce_stills(double scale) const;  // null when it gives the tracker nothing
  LiveFrame finish(const cv::Mat& frame, const TrackResult& r, double track_ms);
  Tracker tracker_;
  LiveRepainter repainter_;
  cv::Mat mask_;
  std::vector<cv::Mat> photos_;  // the stills (shared, not copied): reduced for a smaller live view
  TrackOptions options_;
  std::shared_ptr<Reduced> reduced_;                       // the tracker used when the live view is smaller
  cv::Matx33d still_to_tracker_ = cv::Matx33d::eye();      // still pixel -> the pixel of the tracker used
  cv::Size still_size_;
  cv::Matx33d map_to_still_;
  cv::Mat backdrop_;
  std::vector<std::vector<cv::Point>> contours_;
  std::optional<LiveGeometry> geometry_;
  std::shared_ptr<const LiveLook> live_look_;
  cv::Mat look_backdrop_;                // backdrop_ at the destination's size
  Look look_ = Look::shaded;
  std::optional<LiveLight> last_good_;   // the last light one lamp explained
  int held_ = 0;                         // frames the last good light has been held for
};

// The backdrop dimmed and red with "LOST - hold still / recapture".
cv::Mat lost_picture(const cv::Mat& backdrop, cv::Size size);

}  // namespace veneer::repaint
