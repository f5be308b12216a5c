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
//   texture_corr, frame f: the high-pass (log minus a 3 px Gaussian) of the
//     repainted frame correlated with the truth frame's (an identity map: the
//     truth is already on the destination), over the mask eroded by 3 px.
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
};

struct LiveLook {
  std::vector<FrameLook> frames;
  double shading_mean = 0;                  // mean over the frames with samples of their shading mean
  std::optional<double> texture_corr_mean;  // mean over the frames that have one
  ShadingError pooled;                      // every frame's lit pixels together (look.py over the sequence)
  std::string json() const;                 // {"frames":[{"frame","file","shading_mean",...}],"mean":{...},"pooled":{...}}
  std::string table() const;                // one row per frame and a mean row, fixed-width text
};

// `result[f]` the repainted frame f and `truth[f]` the truth frame f (linear,
// 1 or 3 channels, float or any depth; same count, same size); `mask` the
// truth's object (CV_8UC1, empty = every pixel). Fails naming a mismatch, or
// when no pixel of any frame is lit in both.
Expected<LiveLook> live_look(const std::vector<cv::Mat>& result, const std::vector<cv::Mat>& truth,
                             const cv::Mat& mask = {});

// A picture file as the measure reads it: CV_32FC3 linear; 8-bit through the
// inverse sRGB curve, 16-bit as linear.
Expected<cv::Mat> read_live_picture(const std::filesystem::path& file);

// `repainted`: a `veneer repaint --video` folder (its report.json's frames in
// order, else frame_*.png by name); `sequence`: a `veneer simulate
// --light-path --material` folder (light_path.json with truth frames and
// truth/mask.png).
Expected<LiveLook> live_look_folders(const std::filesystem::path& repainted, const std::filesystem::path& sequence);

}  // namespace veneer::eval
