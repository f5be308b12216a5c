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
  Demosaic demosaic = Demosaic::dcb;  // interpolation at full resolution. DCB: of LibRaw's methods the one
                                      // whose photometric stereo comes nearest the linear render's on the
                                      // simulator's sets (bench_raw); ~1.7x AHD's time, ppg ~4x faster
  Status check() const;
};

// True for the file-name extensions of camera RAW formats (case-insensitive).
bool is_raw_file_name(const std::string& file_name);

// Decodes RAW file bytes; `name` names the file in errors. Refuses files
// LibRaw cannot open or unpack (damaged, unsupported, not RAW at all).
Expected<cv::Mat> decode_raw_linear(std::string_view bytes, const RawOptions& options, const std::string& name);
Expected<cv::Mat> read_raw_linear(const std::filesystem::path& file, const RawOptions& options = {});

// The JPEG thumbnail/preview LibRaw finds in a RAW file (unpack_thumb, the
// mosaic left undecoded): its bytes as stored. An error when the file has
// none or it is not a JPEG.
Expected<std::string> raw_preview_jpeg(std::string_view bytes, const std::string& name);

// The LibRaw version this build decodes with, e.g. "0.20.2".
std::string raw_decoder_version();

}  // namespace veneer::io
