#pragma once
// Single-image files: PFM (float), 16-bit linear PNG, pictures for people.
#include <filesystem>
#include <string>
#include <string_view>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"

namespace veneer::io {

// How a file is put in place. Always written to a temporary beside it and
// renamed over the name, so a reader never sees half a file; `each` also
// fsyncs the file and its folder before returning, `later` leaves the
// folder's fsync to one sync_folder() after a batch of files (results that a
// rerun remakes: a crash may lose them, never leave half of one).
enum class Sync { each, later };

// PFM: little-endian, bottom row first. 1 or 3 channels, CV_32F.
// `xyz_order`: the Mat's channel 0 goes to the file's R slot (for normals and
// maps, whose channels are x,y,z); otherwise the Mat is taken as BGR (a photo)
// and written so that the file's R slot holds the red channel.
Status write_pfm(const std::filesystem::path& file, const cv::Mat& image, bool xyz_order, Sync sync = Sync::each);
Expected<cv::Mat> read_pfm(const std::filesystem::path& file, bool xyz_order);
// The same from bytes in memory; `name` is used in error messages.
Expected<cv::Mat> read_pfm_bytes(std::string_view bytes, bool xyz_order, const std::string& name = "<memory>");
std::string encode_pfm(const cv::Mat& image, bool xyz_order);  // the file's bytes (image must be CV_32FC1/3)

// How a 16-bit PNG's image data is deflated. Linear photos are mostly sensor
// noise: libdeflate's fastest level shrinks them by ~20 % at ~4x the time of
// storing them (1024x680, measured in bench_io); stored PNGs are written at
// the speed of the disk and read by any PNG reader.
enum class PngDeflate {
  stored,  // deflate's stored blocks (level 0), rows unfiltered
  fast,    // libdeflate level 1, rows Sub-filtered
};
// 16-bit linear PNG from/to CV_32FC3 BGR in [0,1] (values clamped, NaN as 0).
// Writing defaults to stored: it is what results (result_*.png) are written as.
Status write_png16(const std::filesystem::path& file, const cv::Mat& image, Sync sync = Sync::each,
                   PngDeflate deflate = PngDeflate::stored);
// The PNG bytes of a 1- or 3-channel float image (sets' photos: fast by default).
Expected<std::string> encode_png16(const cv::Mat& image, PngDeflate deflate = PngDeflate::fast);
// An 8-bit image's PNG bytes (the sets' mask.png): grey and BGR deflated by libdeflate, others by OpenCV.
Expected<std::string> encode_png8(const cv::Mat& image);
// Reads an 8- or 16-bit PNG (or PPM/PGM, or a JPEG: see below) as CV_32FC3 BGR scaled to [0,1];
// grey images are expanded to 3 channels. A PFM photo is read as it is
// (file RGB -> Mat BGR). Truncated or corrupt files are refused.
Expected<cv::Mat> read_linear_image(const std::filesystem::path& file);
// The same from a file's bytes in memory (PNG, PPM/PGM, PFM or JPEG, told
// apart by their magic, not the name); `name` is used in error messages. A
// JPEG is a developed 8-bit sRGB photo: it goes through the inverse sRGB
// curve (the only non-linear input; RAW files are read by raw.hpp).
Expected<cv::Mat> decode_linear_image(std::string_view bytes, const std::string& name);
// "png" | "jpeg" | "pfm" | "pnm" by the bytes' magic, "" for anything else.
std::string image_file_kind(std::string_view bytes);
// A mask file (PNG/PGM/PPM, any depth) as CV_8UC1: 255 where the file is non-zero.
Expected<cv::Mat> read_mask(const std::filesystem::path& file);
// The whole file as bytes; the error names the file.
Expected<std::string> read_file_bytes(const std::filesystem::path& file);

// Pictures a person looks at (8-bit PNG):
cv::Mat normals_picture(const cv::Mat& normals);  // RGB = (n+1)/2, black outside
cv::Mat tonemap_picture(const cv::Mat& linear, double percentile = 99.5);  // sRGB gamma, auto exposure
Status write_picture(const std::filesystem::path& file, const cv::Mat& bgr8, Sync sync = Sync::each);

// Writes bytes to `file` via a temporary and rename (fsynced with Sync::each).
Status write_file_atomic(const std::filesystem::path& file, const std::string& bytes, Sync sync = Sync::each);
// Creates `file` with `bytes` and fsyncs it, in place (for a file inside a
// temporary folder that is renamed into place as a whole).
Status write_file_synced(const std::filesystem::path& file, std::string_view bytes);
// fsyncs a folder: the names written into it with Sync::later are durable.
Status sync_folder(const std::filesystem::path& folder);

}  // namespace veneer::io
