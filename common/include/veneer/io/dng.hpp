#pragma once
// A minimal DNG writer: what a camera would have recorded for a linear photo,
// as an uncompressed Bayer mosaic (RGGB) with its black and white levels,
// colour matrix and as-shot white balance. It exists so the RAW path
// (raw.hpp) is tested on files the project makes itself from the simulator's
// renders (`veneer simulate --dng`), not on camera files it cannot ship.
#include <string>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"

namespace veneer {

struct DngOptions {
  int black_level = 512;     // sensor counts of black (0 .. white_level - 1)
  int white_level = 16383;   // sensor counts of the clipping point (14-bit sensor), <= 65535
  // The camera's raw response to white light, [r, g, b] with green 1: the
  // DNG's AsShotNeutral. The mosaic holds photo * neutral, so a decoder that
  // applies the as-shot white balance gets the photo back. (0, 1] each.
  cv::Vec3d as_shot_neutral{0.55, 1.0, 0.75};
  std::string camera_model = "Veneer simulated camera";  // Make/Model/UniqueCameraModel
  Status check() const;
};

// The DNG bytes for a linear photo (CV_32FC3 BGR, 1.0 = white; values are
// clipped to [0, 1]). Width and height must be even (whole Bayer cells).
Expected<std::string> encode_dng(const cv::Mat& linear_bgr, const DngOptions& options = {});

// Gives every photo of `set` (and its ambient frame) a DNG of itself in
// set.raw / set.ambient_raw, encoded in parallel, so write_set stores a set
// whose RAW files are the simulator's linear renders.
Status add_dng_raw_files(ImageSet& set, const DngOptions& options = {});

}  // namespace veneer
