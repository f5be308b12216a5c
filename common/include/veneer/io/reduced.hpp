#pragma once
// Reduced decodes: a set's photos at the live view's size (1024-1920 px
// wide), made without decoding the full-resolution photo first.
//  - raw-binned:   the RAW's Bayer mosaic as LibRaw unpacks it (no
//                  demosaic), each k x k block (k even) averaged per colour
//                  into one pixel, then scaled exactly as decode_raw_linear
//                  scales (black level, white level, as-shot white balance,
//                  camera -> linear sRGB): the same photometric scale as the
//                  full decode, area-averaged;
//  - jpeg-reduced: a developed JPEG decoded at 1/2, 1/4 or 1/8 in the DCT
//                  (libjpeg's scaled IDCT), through the inverse sRGB curve;
//  - raw-preview:  the preview a RAW file embeds (LibRaw unpack_thumb),
//                  through the inverse sRGB curve (a camera's rendering: its
//                  scale is not the RAW's);
//  - developed:    the developed photo decoded whole and area-resized (a
//                  16-bit PNG has no reduced decode).
// Every photo comes out CV_32FC3 BGR, linear, 1.0 = white, as read_set's.
#include <filesystem>
#include <string>
#include <string_view>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::io {

enum class ReducedDecode {
  automatic,     // per set: jpeg-reduced when the developed photos are JPEGs and the set is wider
                 // than the target, else raw-binned when every photo has a Bayer RAW file, else
                 // developed (raw-preview when the binned decode fails and a preview is there)
  raw_binned,
  jpeg_reduced,
  raw_preview,
  developed,
};
const char* reduced_decode_name(ReducedDecode);  // "auto" | "raw-binned" | "jpeg-reduced" | "raw-preview" | "developed"
Expected<ReducedDecode> parse_reduced_decode(const std::string&);

// The Bayer mosaic of RAW file bytes binned `factor` x `factor` (even, 2..32)
// into one linear pixel each: floor(width / factor) x floor(height / factor)
// of the full decode's visible size. Refuses files without a Bayer mosaic
// (linear DNGs, Foveon, X-Trans) naming the file.
Expected<cv::Mat> decode_raw_binned(std::string_view bytes, int factor, const std::string& name);
// The same with the largest even factor that keeps the result at least
// `min_width` wide (2 when even that is narrower); `factor_out` gets it.
Expected<cv::Mat> decode_raw_binned_to_width(std::string_view bytes, int min_width, const std::string& name,
                                             int* factor_out = nullptr);

// A JPEG decoded at 1/factor (1, 2, 4 or 8) in the DCT, linear.
Expected<cv::Mat> decode_jpeg_reduced(std::string_view bytes, int factor, const std::string& name);
// The largest factor of 1, 2, 4, 8 that keeps a `width` wide photo at least `min_width` wide.
int jpeg_reduction_for(int width, int min_width);

// The RAW file's embedded preview (JPEG or bitmap), linear. An error when
// the file has none.
Expected<cv::Mat> decode_raw_preview(std::string_view bytes, const std::string& name);

struct ReducedOptions {
  int width = 1280;  // the photos' width, px (64..8192): the live view's; a set no wider keeps its size
  ReducedDecode decode = ReducedDecode::automatic;
  bool load_truth = true;  // truth normals and mask (resized), for measuring quality
  Status check() const;
};

// Reads a set with its photos (and ambient frame) at min(options.width, the
// set's width) wide, aspect kept, through a reduced decode; the mask, truth
// and camera intrinsics are resized to match. photos_from names the decode
// ("raw-binned-4", "jpeg-reduced-2", "raw-preview", "developed"; the
// factor is the decode's, before the final area resize). DiLiGenT and thesis
// folders are read whole and area-resized ("developed"). Frames decode in
// parallel; `progress` hears the fraction of files done, and a cancel stops
// between files.
Expected<ImageSet> read_set_reduced(const std::filesystem::path& folder, const ReducedOptions& options = {},
                                    const Progress& progress = {});

}  // namespace veneer::io
