#pragma once
// The look of a transfer, measured (issue 35; the C++ twin of
// shared/tools/look.py, which the checks run): how each lamp shades the
// repainted destination against a reference, and whether the texture comes
// from the source through the map the transfer reports.
//
// Shading, per lamp l: d_l = log(result_l / result median) - log(ref_l / ref
// median) over the mask where both are lit (above 5 % of the pixel's
// brightest sample over the lamps): texture and albedo cancel in each ratio,
// what is left is how the lamp shades the surface. The reference is the
// destination's own photos (a real matte pair) or the destination rendered in
// the source's material (the truth look, simulated pairs).
//
// Texture: the high-pass (log minus a 3 px Gaussian, normalised over the
// mapped pixels) of the result median correlated with that of the source's
// median photo warped through the map (nearest pixel), over the mapped mask
// eroded by 3 px. A destination merely tinted scores near 0, the source
// carried through the map near 1.
//
// Images are linear, any scale (the figures are ratios), 1 or 3 channels (3
// are averaged to grey), any depth.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"

namespace veneer::eval {

struct ShadingError {
  double mean = 0;    // mean |d_l| over lit pixels and lamps: the score
  double median = 0;  // its median (numpy's: halfway between the middle two)
  double p90 = 0;     // its 90th percentile (numpy's linear interpolation)
  long long samples = 0;  // lit pixel-lamp pairs compared
};

struct Look {
  ShadingError shading;
  std::optional<double> texture_corr;  // with a source (see look_folders)
};

// A photo as look.py sees it: CV_32FC1, the mean of its channels (a CV_32FC1
// image is returned as it is, sharing its pixels).
cv::Mat look_gray(const cv::Mat& image);
// The per-pixel median of equally sized CV_32FC1 images (numpy's median), or
// of CV_32FC3 photos' grey (the mean of their channels) without a grey copy.
cv::Mat median_image(const std::vector<cv::Mat>& gray);
// The same where `mask` (CV_8UC1 of their size) is non-zero, 0 elsewhere.
cv::Mat median_image(const std::vector<cv::Mat>& gray, const cv::Mat& mask);

// `result[l]` and `reference[l]` lit by lamp l (same count, same size);
// `mask`: CV_8UC1, non-zero = compared (empty = every pixel). Fails naming
// the mismatch, or when no pixel is lit in both.
Expected<ShadingError> shading_error(const std::vector<cv::Mat>& result, const std::vector<cv::Mat>& reference,
                                     const cv::Mat& mask = {});

// The same per lamp: element l holds lamp l's lit pixels only (medians and
// maxima still over all lamps, as above); a lamp with no lit pixel has
// samples = 0. What a live sequence is scored with frame by frame
// (eval/live_look.hpp), each frame a lamp.
Expected<std::vector<ShadingError>> shading_error_per_lamp(const std::vector<cv::Mat>& result,
                                                          const std::vector<cv::Mat>& reference,
                                                          const cv::Mat& mask = {});

// `result_median`: the transfer's median picture (result_median.png);
// `source_median`: the per-pixel median of the source's grey photos
// (median_image of look_gray of each); `map_xy`: the map (CV_32FC2 or
// CV_32FC3, channels source x, y; negative = unmapped) of result_median's
// size; `mask` as above. Fails on a size mismatch or when no pixel is left
// after the erosion.
Expected<double> texture_corr(const cv::Mat& result_median, const cv::Mat& source_median, const cv::Mat& map_xy,
                              const cv::Mat& mask = {});

// look.py on folders: `transfer_out` a `veneer transfer` folder
// (result_light_NN.png, result_median.png, map.pfm); `reference_set` the set
// whose photos are the reference (veneer-set/1 set.json or DiLiGenT
// filenames.txt; the developed photos, JPEGs through inverse sRGB, RAW files
// ignored; its mask.png, thresholded at 127, limits the comparison);
// `source_set` (empty = no texture figure) the transfer's source.
Expected<Look> look_folders(const std::filesystem::path& transfer_out, const std::filesystem::path& reference_set,
                            const std::filesystem::path& source_set = {});
// The photos of a set folder as look.py lists them (filenames.txt, else
// set.json's images[].file), each through look_gray.
Expected<std::vector<cv::Mat>> look_photos(const std::filesystem::path& set_folder);

// look.py's JSON: {"shading_mean":..,"shading_median":..,"shading_p90":..,"samples":..[,"texture_corr":..]}.
std::string look_json(const Look& look);

}  // namespace veneer::eval
