#pragma once
// What the set readers and the writer share (not part of the public API):
// limits, checks of directions and file names, the parallel photo decoder
// and the text-list parser of the DiLiGenT, thesis and RTI layouts.
#include <filesystem>
#include <functional>
#include <initializer_list>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>
#include <tbb/parallel_for.h>

#include "veneer/io/imageset.hpp"
#include "veneer/io/raw.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::io::detail {

inline constexpr int kMaxSide = 1 << 16;
inline constexpr size_t kMaxLights = 1024;
inline constexpr uintmax_t kMaxManifestBytes = 16u << 20;

std::string fmt_vec(const cv::Vec3d& v);
std::string size_text(cv::Size s);
bool finite3(const cv::Vec3d& v);
// A direction that is finite and of unit length within kUnitTolerance; else why not.
std::string direction_problem(const cv::Vec3d& d);
std::string intensity_problem(const cv::Vec3d& v);
// A file named by a manifest or list must stay inside the set folder.
std::string file_name_problem(const std::string& name);
std::string light_file_name(int index, const std::string& extension = "png");  // light_NN.<extension>
// The developed file of photo k when the set carries the camera's (else null).
const ImageSet::RawFile* developed_file(const ImageSet& set, size_t k);
std::string raw_file_name(int index, const std::string& extension);       // light_NN.<extension>
std::string folder_name(const std::filesystem::path& folder);             // "a/b/" -> "b"

// --- loading pixels ---

// job(i) for every i in [0, n) in parallel, reporting progress under `stage`
// and checking for cancellation before each; the first error in index order
// (or "cancelled") is the result.
Status for_each_parallel(size_t n, const Progress& progress, const std::string& stage,
                         const std::function<Status(size_t)>& job);

// One file to decode into a photo: through LibRaw when `raw`, else by its magic
// (PNG, JPEG, PFM, PNM).
struct Frame {
  std::filesystem::path file;
  bool raw = false;
  bool srgb8 = false;  // 8-bit PNG/TIFF samples are sRGB code values (linearised); JPEGs always are
};

// What a photo file was: "raw" | "raw-half" | "png" | "jpeg" | "tiff" | "pfm" |
// "pnm" (ImageSet::photos_from), and its bits per sample.
struct PhotoKind {
  std::string kind;
  int bits = 0;
  cv::Matx33f camera_to_srgb = cv::Matx33f::eye();  // RAW read in the camera's space (RawPhoto)
};

// Decodes one photo file's bytes into CV_32FC3 BGR, linear, 1.0 = full scale
// (CV_16FC3 with `half`: a RAW file's rows narrowed as they are demosaiced).
Expected<cv::Mat> decode_photo(std::string_view bytes, const Frame& frame, const RawOptions& raw_options, bool half,
                               PhotoKind& kind);
// 8-bit sRGB code values held as v / 255 in a float image -> linear, in place.
void srgb_to_linear_inplace(cv::Mat& image);
// How photos of this kind are read, for `veneer info` (ImageSet::photos_read).
std::string describe_photos(const PhotoKind& kind, bool srgb8, const RawOptions& raw_options);
// True when every photo is a RAW file by name, false when none is; an error names a mix.
Expected<bool> all_raw_by_name(const std::vector<std::filesystem::path>& files);

// Decodes `frames` in parallel (one task per file, each file read and decoded
// once) into CV_32FC3 (CV_16FC3 with `half`, ReadOptions::half_floats);
// `kinds` gets each file's kind ("raw", "png", ...). The first error wins by
// list order, so the message does not depend on thread timing. Progress is
// reported from the worker threads under a lock.
Status decode_frames(const std::vector<Frame>& frames, const RawOptions& raw_options, bool half,
                     const Progress& progress, const std::string& stage, std::vector<cv::Mat>& out,
                     std::vector<PhotoKind>* kinds = nullptr);
// The set's photos_from and photos_read from the kinds decode_frames found.
void note_photo_kinds(ImageSet& set, const std::vector<PhotoKind>& kinds, bool srgb8, const RawOptions& raw_options);
// The set's camera_to_srgb from its frames' (`kinds`: the images', then the
// ambient's when the set has one): the one matrix they share, or, when they
// differ (frames from two cameras), each frame made sRGB with its own.
void settle_camera_space(ImageSet& set, const std::vector<PhotoKind>& kinds);
Status check_size(const std::filesystem::path& file, const cv::Mat& image, cv::Size expected, const std::string& why);
Status check_same_sizes(const std::vector<std::filesystem::path>& files, const std::vector<cv::Mat>& images);
// The first existing file among folder/<stem>.<ext> for the given extensions.
std::filesystem::path find_with_ext(const std::filesystem::path& folder, const std::string& stem,
                                    std::initializer_list<const char*> exts);

// --- text lists (DiLiGenT, thesis) ---

struct Line {
  int number;  // 1-based
  std::string text;
};
// Non-empty lines with surrounding blanks and (unless `comments` is false)
// '#' comments removed; an error for an unreadable or binary file.
Expected<std::vector<Line>> read_lines(const std::filesystem::path& file, bool comments = true);
// Parses whitespace-separated numbers (strict: every token must be a number).
bool parse_numbers(const std::string& text, std::vector<double>& out);
// "x y z" (and optionally "r g b" when allow_rgb) per line.
Status parse_light_lines(const std::filesystem::path& file, const std::vector<Line>& lines, bool allow_rgb,
                         std::vector<Light>& lights);

// Decodes a list reader's photos into set.images (all RAW by name, or none),
// checks they have one size and sets set.size, photos_from and photos_read.
Status load_photos(const std::vector<std::filesystem::path>& files, bool srgb8, const ReadOptions& options,
                   const Progress& progress, ImageSet& set);

// --- the readers read_set dispatches to ---
Expected<ImageSet> read_veneer(const std::filesystem::path& folder, const ReadOptions& options, const Progress& progress);
Expected<ImageSet> read_diligent(const std::filesystem::path& folder, const ReadOptions& options, const Progress& progress);
Expected<ImageSet> read_thesis(const std::filesystem::path& folder, const ReadOptions& options, const Progress& progress);
Expected<ImageSet> read_rti(const std::filesystem::path& folder, const ReadOptions& options, const Progress& progress);
// The RTI light file (*.lp) of a folder: the one in it or in its
// assembly-files/ (RTIBuilder's project layout); empty when there is none, an
// error when there are several.
Expected<std::filesystem::path> find_lp_file(const std::filesystem::path& folder);

// --- camera files of a set (dng_writer.cpp, camera_files.cpp) ---

// encode(photo) for each of the set's photos, then its ambient frame if it has
// one, in parallel: the results in that order, or the first failure, named
// "image <i>" or "ambient".
template <class T, class Encode>
Expected<std::vector<T>> encode_frames(const ImageSet& set, Encode encode) {
  const size_t n = set.images.size() + (set.ambient.empty() ? 0 : 1);
  std::vector<Expected<T>> encoded(n, Expected<T>(T{}));
  tbb::parallel_for(size_t(0), n, [&](size_t i) {
    encoded[i] = encode(i < set.images.size() ? set.images[i] : set.ambient);
  });
  std::vector<T> out;
  for (size_t i = 0; i < n; ++i) {
    if (!encoded[i]) return make_error((i < set.images.size() ? "image " + std::to_string(i) : std::string("ambient")) +
                                       ": " + encoded[i].message());
    out.push_back(std::move(encoded[i]).value());
  }
  return out;
}

}  // namespace veneer::io::detail
