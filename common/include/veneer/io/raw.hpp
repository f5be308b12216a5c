#pragma once
// Camera RAW files (CR2, NEF, ARW, DNG, ...) decoded to linear photos with
// LibRaw, the way the thesis used dcraw: gamma 1, no auto-brightening, the
// camera's (as-shot) white balance, black level subtracted, demosaiced,
// converted to linear sRGB primaries. The result has the set's photo
// convention (imageset.hpp): CV_32FC3 BGR, 1.0 = the sensor's white level.
// LibRaw's types stay in raw_decode.cpp.
#include <filesystem>
#include <string>
#include <string_view>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"

namespace veneer::io {

// LibRaw's interpolations (user_qual 0, 1, 2, 3, 4, 11, 12), and mhc: Veneer's
// own (Malvar-He-Cutler's gradient-corrected linear filters, rows in
// parallel, on the mosaic LibRaw unpacks; LibRaw's develop skipped; a Bayer
// layout LibRaw's pipeline alone takes goes through its AHD instead).
enum class Demosaic { bilinear, vng, ppg, ahd, dcb, dht, aahd, mhc };
const char* demosaic_name(Demosaic);  // "bilinear" | "vng" | "ppg" | "ahd" | "dcb" | "dht" | "aahd" | "mhc"
Expected<Demosaic> parse_demosaic(const std::string&);

struct RawOptions {
  bool half_size = false;             // one pixel per 2x2 Bayer cell (half width and height, no
                                      // interpolation, ~4x faster); default off = full resolution
  Demosaic demosaic = Demosaic::mhc;  // interpolation at full resolution. MHC (ours): ~20x faster than
                                      // LibRaw's DCB at normals as good on the simulator's 5600x3750 pair
                                      // (issue 34: 4.18 vs 4.51 deg mean); the one default every reader,
                                      // the CLI and the viewer share (issue 42). Of LibRaw's own, DCB comes
                                      // nearest the linear render (bench_raw)
  bool camera_space = false;           // the camera's own linear RGB (black subtracted, white-balanced, 1.0 =
                                      // white) before its colour matrix: what photometric stereo solves in
                                      // (the matrix amplifies and correlates the sensor's noise: normals 1.2x
                                      // worse in mean on the Pi's DNGs, issue 42). decode_raw returns the
                                      // matrix that makes such a photo linear sRGB. Default off: linear sRGB
  bool half_floats = false;           // the photo as CV_16FC3 (half floats, as the result cache stores
                                      // photos): written so as it is demosaiced, never whole as float
                                      // (issue 42: a 5600x3750 frame is 126 MB instead of 252). Default off
  Status check() const;
};

// A RAW photo as decoded: CV_32FC3 BGR (CV_16FC3 with RawOptions::half_floats), 1.0 = white, in linear sRGB, or in
// the camera's space with RawOptions::camera_space; camera_to_srgb (on BGR
// pixels, as cv::transform takes it) makes the latter linear sRGB
// (apply_colour_matrix). Identity for a photo already in sRGB, and for
// files whose camera space is sRGB (no colour matrix, or ours: dng.hpp).
struct RawPhoto {
  cv::Mat image;
  cv::Matx33f camera_to_srgb = cv::Matx33f::eye();
};

// True for the file-name extensions of camera RAW formats (case-insensitive).
bool is_raw_file_name(const std::string& file_name);

// Decodes RAW file bytes; `name` names the file in errors. Refuses files
// LibRaw cannot open or unpack (damaged, unsupported, not RAW at all).
Expected<cv::Mat> decode_raw_linear(std::string_view bytes, const RawOptions& options, const std::string& name);
Expected<cv::Mat> read_raw_linear(const std::filesystem::path& file, const RawOptions& options = {});
Expected<RawPhoto> decode_raw(std::string_view bytes, const RawOptions& options, const std::string& name);

// True when `m` is the identity within 1e-4 per element (a DNG's matrix of an sRGB camera, through
// LibRaw's XYZ round trip, is off by ~1e-6; 1e-4 moves a pixel by less than a 14-bit count).
bool is_identity(const cv::Matx33f& m);
// photo = clip(m x photo, 0, 1) per pixel, in place, rows in parallel (CV_32FC3 or CV_16FC3 BGR);
// nothing when `m` is the identity. As LibRaw and our MHC clip after their matrix.
void apply_colour_matrix(cv::Mat& photo, const cv::Matx33f& m);

// A TIFF-based RAW (DNG, NEF, CR2, ARW...) is refused, with the reason, when
// its image directories or their values run past the end of the file: a file
// cut short in copying, or made to harm. LibRaw 0.20 (Debian 12) reads on
// past such ends and can crash (a 300-byte DNG found by fuzz_raw_decode).
// Every LibRaw open in veneer checks this first. Other containers pass.
Status check_raw_structure(std::string_view bytes, const std::string& name);

// The JPEG thumbnail/preview LibRaw finds in a RAW file (unpack_thumb, the
// mosaic left undecoded): its bytes as stored. An error when the file has
// none or it is not a JPEG.
Expected<std::string> raw_preview_jpeg(std::string_view bytes, const std::string& name);

// The LibRaw version this build decodes with, e.g. "0.20.2".
std::string raw_decoder_version();

}  // namespace veneer::io
