#pragma once
// From set folders to objects ready for matching, through the per-set result
// cache (io/cache.hpp): on a miss the frames are decoded in parallel (RAW
// where the set has it), segmented and solved by photometric stereo (called
// as it is), and the results stored; on a hit the normals, mask and the
// photos the repaint needs come from a few cache files.
#include <filesystem>
#include <string>
#include <vector>

#include "veneer/io/cache.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::pipeline {

struct PrepareOptions {
  io::ReadOptions read;    // RAW or developed photos, half size, demosaic
  io::CacheOptions cache;  // where, how large, or off
  // An object mask drawn by hand (CV_8UC1 of the set's size as read, > 127 =
  // object) instead of the automatic segmentation; empty = segment. Keyed into
  // the cache by its content, so a re-run with the same mask hits.
  // prepare_set uses `mask`; prepare_pair `destination_mask` and `source_mask`.
  cv::Mat mask, destination_mask, source_mask;
  // The frames as half floats (CV_16FC3, the precision the cache stores
  // photos at) from their decoding on (io::ReadOptions::half_floats):
  // segmentation, photometric stereo and the median widen a row at a time,
  // and the photos and the median handed on are half floats; prepare_pair's
  // two sets are prepared one after the other. A 5600x3750 frame is 126 MB
  // instead of 252, and no set's frames are ever all float (issue 42: peak
  // memory). The normals differ from float frames' by a few hundredths of a
  // degree (tests/core/pipeline/test_camera_space.cpp), so the cache keys
  // them apart. Only for callers whose every stage reads such photos
  // (pipeline::transfer with the CLI's flow does); default off.
  bool half_photos = false;
  // The frames decoded to half floats as half_photos decodes them, the photos
  // and the median handed on widened to float once prepared: the normals and
  // the map of a caller that keeps float photos (the viewer) are those of
  // `veneer transfer`, and they share cache entries. default_prepare_options()
  // turns it on; half_photos implies it. Default off: float frames.
  bool half_frames = false;
  Status check() const;
};

// How the product reads and prepares sets by default -- what `veneer
// transfer` starts from before its flags, and what the viewer prepares its
// pairs with, so both give one answer: RAW where every photo has one,
// demosaiced by our MHC (io::Demosaic::mhc, io::RawOptions' default: ~20x
// faster than LibRaw's DCB at normals as good on the simulator's 5600x3750
// pair, issue 34: 4.18 vs 4.51 deg mean), full size, the result cache on.
// These are the options structs' own defaults (PrepareOptions{} is the same)
// but for half_frames, on here: the CLI and the viewer solve from half frames.
PrepareOptions default_prepare_options();

// What happened to one set, for metrics.json.
struct SetReport {
  std::string folder, id, checksum;
  bool cache_hit = false;
  std::string photos_from;  // "raw", "raw-half", "png", "jpeg", ... (io::ImageSet::photos_from)
  double read_s = 0;        // decoding the frames (miss) or reading the cache files (hit)
  double normals_s = 0;     // segmentation + photometric stereo (0 on a hit)
  double cache_write_s = 0;  // -1: written in the background (finish_cache_writes)
  double total_s = 0;
  std::string cache_error;  // a cache that could not be written is reported, not fatal
};

// One set prepared: the set's metadata (images = the photos with the ambient
// frame removed, the same pixels as object.view.images; of the truth only its
// normals and mask, all a transfer measures with), normals, mask, the
// photometric stereo's albedo and residual (empty on truth normals), median.
struct PreparedSet {
  io::ImageSet set;
  match::PreparedObject object;
  cv::Mat albedo, residual, median;
  SetReport report;
};

// `scale` and `truth_normals` as pipeline::TransferOptions.
Expected<PreparedSet> prepare_set(const std::filesystem::path& folder, double scale, bool truth_normals,
                                  const PrepareOptions& options, const Progress& progress = {});

// Both sets of a pair, as pipeline::prepare_pair makes them, via prepare_set.
Expected<pipeline::PreparedPair> prepare_pair(const std::filesystem::path& destination,
                                           const std::filesystem::path& source,
                                           const pipeline::TransferOptions& transfer, const PrepareOptions& options,
                                           std::vector<SetReport>* reports = nullptr, const Progress& progress = {});

// Waits for the cache entries prepare_set writes in the background (a
// program calls it before it exits); the first write's error, if any.
Status finish_cache_writes();

// The per-pixel, per-channel median of same-sized CV_32FC3 photos, equal to
// repaint::median_photo's (the mean of the two middle values for an even count);
// of CV_16FC3 photos (half_photos) it is CV_16FC3, the float median rounded.
cv::Mat median_of(const std::vector<cv::Mat>& photos);

// The reports as JSON ({"destination": {...}, "source": {...}} when two).
std::string reports_json(const std::vector<SetReport>& reports);

}  // namespace veneer::pipeline
