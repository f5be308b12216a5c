#pragma once
// The live look, measured (issue 40): a repainted live sequence (what
// `veneer repaint --video` writes) scored frame by frame against the truth
// frames of `veneer simulate --light-path ... --material SOURCE` (the
// destination's shape in the source's material under the same moving lamp),
// with look.py's per-pixel measure (eval/look.hpp), each frame a lamp:
//
//   shading, frame f: |log(result_f / result median) - log(truth_f / truth
//     median)| over the truth's object mask where both are lit (medians and
//     maxima over the sequence's frames), its mean, median and p90;
//   texture_corr, frame f: look.py's -- the high-pass (log minus a 3 px
//     Gaussian) of the repainted frame correlated with that of the SOURCE's
//     median photo warped through the map (nearest pixel), over the mask
//     eroded by 3 px: whether the texture comes from the source through the
//     map. Without a map and source (LiveLookTexture empty) the older form:
//     against the truth frame through an identity map;
//   light, frame f: the angle between the light the repaint estimated in the
//     frame (report.json's per_frame light direction) and the path's lamp
//     (light_path.json's direction), when both are known.
//
// Truth scored against itself gives 0 and 1. Pictures: 8-bit files are
// sRGB-encoded (the live view's frames, the repainted frames) and go through
// the inverse sRGB curve; 16-bit files are linear (the truth frames).
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/eval/look.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::eval {

struct FrameLook {
  std::string file;                    // the repainted frame's file ("" when scored from memory)
  ShadingError shading;                // samples = 0: no pixel lit in both (the figures are then 0)
  std::optional<double> texture_corr;  // empty when no pixel is left inside the eroded mask
  bool lost = false;                   // the repaint marked the frame lost (report.json)
  std::optional<double> light_angle_deg;  // the estimated light's angle to the true one [deg] (report.json has
                                          // a light for the frame)
};

struct LiveLook {
  std::vector<FrameLook> frames;
  double shading_mean = 0;                  // mean over the frames with samples of their shading mean
  std::optional<double> texture_corr_mean;  // mean over the frames that have one
  std::optional<double> texture_corr_min;   // the lowest frame's
  bool texture_from_source = false;         // texture_corr is look.py's (the source through the map), not the
                                            // truth through an identity map
  std::optional<double> light_angle_median_deg;  // median over the frames with an estimate
  std::optional<double> light_angle_max_deg;
  ShadingError pooled;                      // every frame's lit pixels together (look.py over the sequence)
  std::string json() const;                 // {"frames":[{"frame","file","shading_mean",...}],"mean":{...},"pooled":{...}}
  std::string table() const;                // one row per frame and a mean row, fixed-width text
};

// What texture_corr compares the repainted frames with (look.py's form):
// `map_xy` the map the frames were repainted through (CV_32FC2/3, source x,
// y; negative = unmapped; the frames' size) and `source_median` the per-pixel
// median of the source's grey photos at the map's scale (median_image of
// look_gray of each). Both empty: the truth frame through an identity map.
struct LiveLookTexture {
  cv::Mat map_xy, source_median;
  bool empty() const { return map_xy.empty() || source_median.empty(); }
};

// `result[f]` the repainted frame f and `truth[f]` the truth frame f (linear,
// 1 or 3 channels, float or any depth; same count, same size); `mask` the
// truth's object (CV_8UC1, empty = every pixel). Fails naming a mismatch, or
// when no pixel of any frame is lit in both.
Expected<LiveLook> live_look(const std::vector<cv::Mat>& result, const std::vector<cv::Mat>& truth,
                             const cv::Mat& mask = {}, const LiveLookTexture& texture = {});

// A picture file as the measure reads it: CV_32FC3 linear; 8-bit through the
// inverse sRGB curve, 16-bit as linear.
Expected<cv::Mat> read_live_picture(const std::filesystem::path& file);

// `repainted`: a `veneer repaint --video` folder (its report.json's frames in
// order, and each frame's estimated light, else frame_*.png by name);
// `sequence`: a `veneer simulate --light-path --material` folder
// (light_path.json with truth frames and truth/mask.png); `map` (a transfer
// folder or its map.pfm) and `source_set` (the source's set folder): the
// texture as look.py measures it (both, or neither: then the identity form);
// the map must have the frames' size (a map at scale 1, as the repaint needs).
Expected<LiveLook> live_look_folders(const std::filesystem::path& repainted, const std::filesystem::path& sequence,
                                     const std::filesystem::path& map = {},
                                     const std::filesystem::path& source_set = {});

}  // namespace veneer::eval
