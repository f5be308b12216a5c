#pragma once
// A minimal DNG writer: what a camera would have recorded for a linear photo,
// as a Bayer mosaic (RGGB) with its black and white levels, colour matrix and
// as-shot white balance, compressed losslessly as cameras do (Compression 7:
// lossless JPEG in 256x256 tiles, two components, predictor 1), with a
// reduced developed JPEG preview in a SubIFD (NewSubFileType 1) that a
// reader takes without decoding the mosaic (find_dng_preview). It exists so
// the RAW path (raw.hpp) is tested on files the project makes itself from the
// simulator's renders (`veneer simulate --dng`, the rig's camera twin), not
// on camera files it cannot ship.
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::io {

struct DngOptions {
  int black_level = 512;     // sensor counts of black (0 .. white_level - 1)
  int white_level = 16383;   // sensor counts of the clipping point (14-bit sensor), <= 65535
  // The camera's raw response to white light, [r, g, b] with green 1: the
  // DNG's AsShotNeutral. The mosaic holds photo * neutral, so a decoder that
  // applies the as-shot white balance gets the photo back. (0, 1] each.
  cv::Vec3d as_shot_neutral{0.55, 1.0, 0.75};
  std::string camera_model = "Veneer simulated camera";  // Make/Model/UniqueCameraModel
  bool compress = true;      // lossless JPEG tiles (Compression 7); false = one uncompressed strip
  int preview_divisor = 4;   // embedded preview at 1/this of the width and height (rounded); 0 = none, 1..16
  int preview_quality = 85;  // the preview's JPEG quality, 1..100
  Status check() const;
};

// The DNG bytes for a linear photo (CV_32FC3 BGR, 1.0 = white; values are
// clipped to [0, 1]). Width and height must be even (whole Bayer cells).
Expected<std::string> encode_dng(const cv::Mat& linear_bgr, const DngOptions& options = {});

// Where a DNG (or any TIFF-based RAW file) keeps its largest JPEG preview: an
// IFD (IFD0's chain or one SubIFD level down) with NewSubFileType bit 0 set
// (a reduced image), JPEG compression (6 or 7), 3 samples of 8 bits and one
// strip (or JPEGInterchangeFormat), whose bytes start with a JPEG SOI.
struct DngPreview {
  uint64_t offset = 0;  // of the JPEG bytes in the file
  uint64_t length = 0;
  cv::Size size;        // as the IFD declares it
};
// From the file's bytes (a header prefix suffices when the IFDs lie in it);
// an error naming the problem when the file has no such preview.
Expected<DngPreview> find_dng_preview(std::string_view bytes, uint64_t file_size, const std::string& name);
// From a file on disk, reading only its IFDs (not the mosaic).
Expected<DngPreview> find_dng_preview(const std::filesystem::path& file);
// The preview's JPEG bytes.
Expected<std::string> read_dng_preview(const std::filesystem::path& file);

// Gives every photo of `set` (and its ambient frame) a DNG of itself in
// set.raw / set.ambient_raw, encoded in parallel, so write_set stores a set
// whose RAW files are the simulator's linear renders.
Status add_dng_raw_files(ImageSet& set, const DngOptions& options = {});

}  // namespace veneer::io
