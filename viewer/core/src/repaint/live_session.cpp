#include "veneer/repaint/live_session.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <numeric>

#include <opencv2/imgproc.hpp>

namespace veneer::repaint {

namespace {

double ms_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

std::string fixed(double v, int digits) {
  char text[32];
  std::snprintf(text, sizeof text, "%.*f", digits, v);
  return text;
}

}  // namespace

std::string describe_size(cv::Size size) {
  std::string text = std::to_string(size.width) + "x" + std::to_string(size.height);
  if (size.width <= 0 || size.height <= 0) return text;
  const double aspect = static_cast<double>(size.width) / size.height;
  static const std::pair<int, int> common[] = {{1, 1}, {5, 4}, {4, 3}, {3, 2}, {16, 10}, {16, 9}, {21, 9},
                                               {4, 5}, {3, 4}, {2, 3}, {9, 16}};
  for (const auto& [w, h] : common)
    if (std::abs(aspect / (static_cast<double>(w) / h) - 1) < 0.01)
      return text + " (" + std::to_string(w) + ":" + std::to_string(h) + ")";
  return text + " (" + fixed(aspect, 2) + ":1)";
}

std::string LiveGeometry::describe() const {
  if (same) return describe_size(live) + ", the stills' size: taken as framed alike";
  const cv::Vec2d from = -offset / scale;
  return describe_size(live) + " shows the stills' " + describe_size(still) + " at x" + fixed(scale, 3) +
         ", its top left at still pixel (" + fixed(from[0], 1) + ", " + fixed(from[1], 1) + ")";
}

namespace {

cv::Matx33d to33(const cv::Matx23d& a) { return {a(0, 0), a(0, 1), a(0, 2), a(1, 0), a(1, 1), a(1, 2), 0, 0, 1}; }
cv::Matx23d to23(const cv::Matx33d& a) { return {a(0, 0), a(0, 1), a(0, 2), a(1, 0), a(1, 1), a(1, 2)}; }

}  // namespace

// The tracker of a live view `scale` (< 1) times the stills' size: the
// object's region of the stills in grey, reduced to the live view's pixels,
// so that ECC compares the frame with a template of its own resolution (its
// high-pass and pyramid are in frame pixels). On the full-size stills, a
// 1024 px live view of 5600 px stills (x0.18) was not found at all (ECC
// 0.03), and of the 1280 px live-size stills (x0.8) fell under the threshold
// (ECC 0.82, the reduced stills 0.87; simulated orange, issue 42).
struct LiveSession::Reduced {
  std::unique_ptr<Tracker> tracker;
  cv::Matx33d still_to_tracker = cv::Matx33d::eye();  // still pixel -> the reduced stills' pixel
};

std::shared_ptr<LiveSession::Reduced> LiveSession::reduce_stills(double scale) const {
  if (photos_.empty() || !(scale > 0 && scale < 1)) return nullptr;
  const cv::Rect whole(0, 0, still_size_.width, still_size_.height);
  cv::Rect box = mask_.empty() ? whole : cv::boundingRect(mask_);
  if (box.area() == 0) box = whole;
  // the tracker's margin at the reduced size, and a pixel more for the area resize
  const int grow = static_cast<int>(std::ceil((options_.margin_px + 2) / scale));
  box = cv::Rect(box.x - grow, box.y - grow, box.width + 2 * grow, box.height + 2 * grow) & whole;
  const cv::Size small(std::max(1, static_cast<int>(std::lround(box.width * scale))),
                       std::max(1, static_cast<int>(std::lround(box.height * scale))));
  const double sx = static_cast<double>(small.width) / box.width, sy = static_cast<double>(small.height) / box.height;
  std::vector<cv::Mat> reduced(photos_.size());
  for (size_t i = 0; i < photos_.size(); ++i) {
    if (photos_[i].size() != still_size_) return nullptr;
    cv::Mat grey = photos_[i](box);
    if (grey.channels() == 3) cv::cvtColor(grey, grey, cv::COLOR_BGR2GRAY);
    cv::resize(grey, reduced[i], small, 0, 0, cv::INTER_AREA);
  }
  cv::Mat mask;
  if (!mask_.empty()) cv::resize(mask_(box), mask, small, 0, 0, cv::INTER_NEAREST);
  auto out = std::make_shared<Reduced>();
  out->tracker = std::make_unique<Tracker>(reduced, mask, options_);
  if (!out->tracker->ready()) return nullptr;
  // pixel centres: reduced = (still - box corner + 0.5) * s - 0.5
  out->still_to_tracker = cv::Matx33d(sx, 0, (0.5 - box.x) * sx - 0.5, 0, sy, (0.5 - box.y) * sy - 0.5, 0, 0, 1);
  return out;
}

cv::Mat lost_picture(const cv::Mat& backdrop, cv::Size size) {
  cv::Mat out = backdrop.empty() ? cv::Mat(size, CV_8UC3, cv::Scalar::all(40)) : backdrop.clone();
  if (out.size() != size) cv::resize(out, out, size, 0, 0, cv::INTER_AREA);
  out = out * 0.5 + cv::Scalar(0, 0, 110);  // dimmed and red: not a picture to trust
  const double font = std::max(0.35, out.cols / 900.0);
  cv::putText(out, "LOST - hold still / recapture", {8, std::max(16, out.rows / 8)}, cv::FONT_HERSHEY_SIMPLEX, font,
              cv::Scalar(255, 255, 255), std::max(1, out.cols / 500), cv::LINE_AA);
  return out;
}

LiveSession::LiveSession(const std::vector<cv::Mat>& photos, const cv::Mat& mask, const Map& map,
                         cv::Size source_size, const cv::Mat& backdrop,
                         std::shared_ptr<const fast::BlendPlan> blend, const TrackOptions& options)
    : tracker_(photos, mask, options),
      repainter_(map, source_size, backdrop, std::move(blend)),
      mask_(mask),
      photos_(photos),
      options_(options) {
  repainter_.set_bilinear(false);  // the live budget (set_smooth)
  still_size_ = photos.empty() ? cv::Size() : photos[0].size();
  // map's source pixels (at source_size) -> still pixels (pixel centres)
  const double kx = source_size.width > 0 ? static_cast<double>(still_size_.width) / source_size.width : 1.0;
  const double ky = source_size.height > 0 ? static_cast<double>(still_size_.height) / source_size.height : 1.0;
  map_to_still_ = cv::Matx33d(kx, 0, 0.5 * kx - 0.5, 0, ky, 0.5 * ky - 0.5, 0, 0, 1);
  if (!backdrop.empty()) {
    backdrop.convertTo(backdrop_, CV_8U, backdrop.depth() == CV_8U ? 1.0 : 255.0);
    if (backdrop_.channels() == 1) cv::cvtColor(backdrop_, backdrop_, cv::COLOR_GRAY2BGR);
  }
  if (!mask.empty()) cv::findContours(mask.clone(), contours_, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
}

LiveSession::LiveSession(const std::vector<cv::Mat>& photos, const cv::Mat& mask, const Map& map,
                         cv::Size source_size, std::shared_ptr<const LiveLook> live_look, const cv::Mat& backdrop,
                         std::shared_ptr<const fast::BlendPlan> blend, const TrackOptions& options)
    : LiveSession(photos, mask, map, source_size, backdrop, std::move(blend), options) {
  live_look_ = std::move(live_look);
  if (live_look_ && !backdrop_.empty() && backdrop_.size() != live_look_->destination_size())
    cv::resize(backdrop_, look_backdrop_, live_look_->destination_size(), 0, 0, cv::INTER_AREA);
  else
    look_backdrop_ = backdrop_;
}

void LiveSession::reset() {
  geometry_.reset();
  tracker_.reset();
  reduced_.reset();
  still_to_tracker_ = cv::Matx33d::eye();
  last_good_.reset();
  held_ = 0;
}

// The live view related to the stills: taken as framed alike at the stills'
// size; else the framings a camera's live view makes, the stills' full width
// or their full height, centred (a 16:9 view of a 3:2 sensor crops top and
// bottom), each refined by the tracker (on the stills reduced to the live
// view's scale when it is smaller), and the best one that is one scale taken.
Status LiveSession::fix_geometry(const cv::Mat& frame) {
  reduced_.reset();
  still_to_tracker_ = cv::Matx33d::eye();
  LiveGeometry g;
  g.still = still_size_;
  g.live = frame.size();
  if (!tracker_.ready()) return make_error("live view: the source's stills gave the tracker nothing to follow");
  if (frame.size() == still_size_) {
    tracker_.reset();
    geometry_ = g;
    return {};
  }
  g.same = false;
  struct Candidate {
    const char* name;
    double scale;
    TrackResult result;  // in still pixels
    double sx = 0, sy = 0;
    std::shared_ptr<Reduced> reduced;
  };
  std::vector<Candidate> candidates;
  const double by_width = static_cast<double>(frame.cols) / still_size_.width;
  const double by_height = static_cast<double>(frame.rows) / still_size_.height;
  candidates.push_back({"full width", by_width, {}, 0, 0, nullptr});
  if (std::abs(by_height / by_width - 1) > 0.005) candidates.push_back({"full height", by_height, {}, 0, 0, nullptr});
  Candidate* best = nullptr;
  for (auto& c : candidates) {
    c.reduced = reduce_stills(c.scale);
    Tracker& tracker = c.reduced ? *c.reduced->tracker : tracker_;
    const cv::Matx33d to_tracker = c.reduced ? c.reduced->still_to_tracker : cv::Matx33d::eye();
    // the still's centre at the live view's centre
    const double ox = (frame.cols - 1) / 2.0 - c.scale * (still_size_.width - 1) / 2.0;
    const double oy = (frame.rows - 1) / 2.0 - c.scale * (still_size_.height - 1) / 2.0;
    tracker.seed(to23(cv::Matx33d(c.scale, 0, ox, 0, c.scale, oy, 0, 0, 1) * to_tracker.inv()));
    // twice on the same frame: the second starts where the first ended
    c.result = tracker.track(frame);
    if (!c.result.lost) c.result = tracker.track(frame);
    c.result.still_to_frame = to23(to33(c.result.still_to_frame) * to_tracker);
    const auto& a = c.result.still_to_frame;
    c.sx = std::hypot(a(0, 0), a(1, 0));
    c.sy = std::hypot(a(0, 1), a(1, 1));
    const bool uniform = std::abs(c.sx / c.sy - 1) < 0.03;
    if (!c.result.lost && uniform && (!best || c.result.correlation > best->result.correlation)) best = &c;
  }
  if (!best) {
    std::string tried;
    for (const auto& c : candidates) {
      tried += std::string(tried.empty() ? "" : "; ") + c.name + " (x" + fixed(c.scale, 3) + "): ";
      tried += c.result.lost ? "not found (ECC " + fixed(c.result.correlation, 2) + ")"
                             : "x and y scales " + fixed(c.sx, 3) + " / " + fixed(c.sy, 3) + ", not one scale";
    }
    tracker_.reset();
    return make_error("the live view " + describe_size(frame.size()) + " cannot be related to the stills " +
                      describe_size(still_size_) + " by one scale and a crop (" + tried +
                      "). Make the camera's live view show the object as the stills do (not stretched, the object "
                      "in view), or capture the stills in the live view's framing");
  }
  const auto& a = best->result.still_to_frame;
  g.scale = std::sqrt(std::abs(a(0, 0) * a(1, 1) - a(0, 1) * a(1, 0)));
  g.offset = {a(0, 2), a(1, 2)};
  g.correlation = best->result.correlation;
  if (best->reduced) {  // left seeded by its own estimate
    reduced_ = best->reduced;
    still_to_tracker_ = reduced_->still_to_tracker;
  } else {
    tracker_.seed(a);
  }
  geometry_ = g;
  return {};
}

namespace {

Expected<cv::Mat> as_bgr8(const cv::Mat& frame) {
  if (frame.empty()) return make_error("live frame: empty");
  if (frame.type() == CV_8UC3) return frame;
  if (frame.type() == CV_8UC1) {
    cv::Mat bgr;
    cv::cvtColor(frame, bgr, cv::COLOR_GRAY2BGR);
    return bgr;
  }
  return make_error("live frame: expected 8-bit BGR or grey, got " + std::to_string(frame.channels()) +
                    " channels of depth " + std::to_string(frame.depth()));
}

}  // namespace

LiveFrame LiveSession::finish(const cv::Mat& frame, const TrackResult& r, double track_ms) {
  LiveFrame out;
  out.lost = r.lost;
  out.quality = r.correlation;
  out.still_to_frame = r.still_to_frame;
  out.track_ms = track_ms;
  const auto t0 = std::chrono::steady_clock::now();
  if (r.lost) {
    out.repainted = lost_picture(backdrop_, repainter_.destination_size());
  } else {
    const auto& e = r.still_to_frame;
    const cv::Matx33d m = cv::Matx33d(e(0, 0), e(0, 1), e(0, 2), e(1, 0), e(1, 1), e(1, 2), 0, 0, 1) * map_to_still_;
    const cv::Matx23d source_to_frame(m(0, 0), m(0, 1), m(0, 2), m(1, 0), m(1, 1), m(1, 2));
    bool painted = false;
    if (look_ == Look::shaded && live_look_) {
      LiveLight light = live_look_->estimate_light(frame, source_to_frame);
      out.light_ms = ms_since(t0);
      const LiveLight* use = nullptr;
      if (light.explained) {
        last_good_ = light;
        held_ = 0;
        use = &light;
      } else if (last_good_ && held_ < live_look_->options().light.hold_frames) {
        ++held_;
        light.fallback = "held the last good light";
        use = &*last_good_;
      } else {
        light.fallback = "pixel copy";
      }
      if (use) {
        const auto t1 = std::chrono::steady_clock::now();
        // at the frame's own exposure: the light's intensity is the frame's over the source's stills, so the
        // destination is painted as bright as the camera would show it in the source's material (issue 47: a
        // picture exposed for its 99th percentile at 0.9 was 0.62 of the truth's, its outline speckle set it)
        out.repainted = live_look_->paint(frame, source_to_frame, *use, look_backdrop_);
        out.shade_ms = ms_since(t1);
        out.look = Look::shaded;
        painted = true;
      }
      out.light = std::move(light);
    }
    if (!painted) out.repainted = repainter_.apply(frame, source_to_frame);
  }
  out.repaint_ms = ms_since(t0);
  size_t longest = 0;
  for (size_t i = 0; i < contours_.size(); ++i)
    if (contours_[i].size() > contours_[longest].size()) longest = i;
  if (!contours_.empty())
    for (const auto& p : contours_[longest]) {
      const cv::Vec2d q = r.still_to_frame * cv::Vec3d(p.x, p.y, 1);
      out.outline.emplace_back(static_cast<float>(q[0]), static_cast<float>(q[1]));
    }
  return out;
}

Expected<LiveFrame> LiveSession::process(const cv::Mat& input) { return run(input, true); }

Expected<LiveFrame> LiveSession::process_untracked(const cv::Mat& input) { return run(input, false); }

Expected<LiveFrame> LiveSession::run(const cv::Mat& input, bool track) {
  if (!ready()) return make_error("live session: not ready (the source set's photos, mask or the map are empty)");
  auto frame = as_bgr8(input);
  if (!frame) return frame.error();
  if (!geometry_) {
    if (auto st = fix_geometry(*frame); !st) return st.error();
  } else if (frame->size() != geometry_->live) {
    return make_error("live frame " + describe_size(frame->size()) + ": this session's live view is " +
                      describe_size(geometry_->live) + "; start a new session for a new framing");
  }
  if (!track) {
    TrackResult r;
    r.still_to_frame =
        cv::Matx23d(geometry_->scale, 0, geometry_->offset[0], 0, geometry_->scale, geometry_->offset[1]);
    return finish(*frame, r, 0.0);
  }
  const auto t0 = std::chrono::steady_clock::now();
  TrackResult r = (reduced_ ? *reduced_->tracker : tracker_).track(*frame);
  r.still_to_frame = to23(to33(r.still_to_frame) * still_to_tracker_);  // in still pixels
  return finish(*frame, r, ms_since(t0));
}

}  // namespace veneer::repaint
