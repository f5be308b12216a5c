#pragma once
// Simulated motion with truth (issue 27): the source object moving in front of
// the camera as a live view would see it, with the true motion per frame, so
// registration can be measured. Coordinates are the still's pixels (the set
// rendered with the same RenderOptions): frame 0 is the still's pose.
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/sim/simulator.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::sim {

// The total motion over a sequence, reached at its last frame (each frame
// gets the fraction i / (frames - 1) of it). Parsed from the CLI's SPEC.
struct MotionSpec {
  cv::Vec2d shift_px{0, 0};  // shift=DX:DY, image-plane pixels (x right, y down)
  double rotate_deg = 0;     // rotate=A, in-plane about the object's centre, positive counter-clockwise in the picture
  double scale = 1.0;        // scale=S, about the object's centre (> 0)
  double turn_deg = 0;       // turn=A, small out-of-plane turn about the vertical axis (|A| < 30), approximated
                             // as horizontal foreshortening cos(A) about the centre (no parallax, no occlusion)
  bool lamp_sweep = false;   // lamp=sweep: the hand lamp moves from upper left to upper right; lamp=fixed: stays on top
  cv::Size view{0, 0};       // view=WxH: the live view is W x H pixels showing the stills' field cropped to its aspect,
                             // centred (a 16:9 live view of a 3:2 sensor shows its full width); 0x0 = the stills'
  bool operator==(const MotionSpec&) const = default;
};

// "shift=30:0,rotate=5,scale=1.05,turn=3,lamp=sweep" (any subset, any order;
// empty = no motion). The error names the bad part.
Expected<MotionSpec> parse_motion(const std::string& spec);

struct MotionFrame {
  cv::Matx23d still_to_frame;  // still pixel (x, y, 1) -> frame pixel, pixel centres at integers
  cv::Vec3d lamp_m;            // the hand lamp's position, rig frame [m]
};

// The live view's framing: still pixel -> live pixel (one scale, the crop centred), as spec.view describes.
cv::Matx23d view_transform(cv::Size still, cv::Size view);

// The true motion of frame `index` of `frames`, about `centre` (still pixels),
// in the still's framing (simulate_motion adds the view's).
MotionFrame motion_at(const MotionSpec& spec, int index, int frames, cv::Point2d centre);

struct MotionSequence {
  std::vector<cv::Mat> frames;        // 8-bit BGR, sRGB-encoded at a fixed exposure (what a live view gives)
  std::vector<MotionFrame> truth;     // one per frame
  cv::Point2d centre;                 // the object's centre in the still (mask centroid)
  cv::Mat mask;                       // the object's mask in the still (CV_8UC1)
};

// Renders `frames` frames of scene `scene_name` (placement and size from
// `options`) lit by the hand lamp (+ options.ambient), each warped by its true
// motion and, with spec.view, framed as that live view (truth included). Frame noise: options.seed, one stream per frame.
Expected<MotionSequence> simulate_motion(const std::string& scene_name, const RenderOptions& options,
                                         const MotionSpec& spec, int frames, const Progress& progress = {});

// motion.json: {"format":"veneer-motion/1","size":[w,h],"spec":"...","centre":[x,y],
//  "frames":[{"file":"frame_0000.png","still_to_frame":[[a,b,c],[d,e,f]],"lamp_m":[x,y,z]}, ...]}
Status write_motion_json(const std::filesystem::path& file, const MotionSequence& seq, const std::string& spec,
                         const std::vector<std::string>& files);
// The truth back (empty when the folder has no motion.json).
struct MotionTruth {
  std::vector<std::string> files;
  std::vector<MotionFrame> truth;
  cv::Size size;
};
Expected<MotionTruth> read_motion_json(const std::filesystem::path& file);

}  // namespace veneer::sim
