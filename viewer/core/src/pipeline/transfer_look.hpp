#pragma once
// metrics.json's "look" block of a transfer (transfer.cpp), built here so the
// transfer's own code stays about matching and painting.
#include <functional>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "veneer/pipeline/transfer.hpp"

namespace veneer::pipeline::detail {

// How the transfer paints a photo onto a backdrop through its map.
using Paint = std::function<Expected<cv::Mat>(const cv::Mat& photo, const cv::Mat& backdrop)>;

// The look of `result` (its pictures, or painted again with `paint` when not
// kept) against the destination's own photos, and against the truth look when
// both sets are simulated; `coverage` and `coherence` (the quality block's)
// stand beside it; with options.look_floor the `linear` map's pixel copy too.
Expected<nlohmann::json> look_block(const PreparedPair& pair, const TransferOptions& options,
                                    const TransferResult& result, const Paint& paint, double coverage,
                                    double coherence, const Progress& progress);

// The same in two halves, for write_transfer with the pair, which paints each
// picture once (and lets each photo go once painted): look_begin takes what
// the figures need besides the pictures (the truth look, the masks, the
// source's median where the map reads it) while the pair's photos are all
// there; look_end scores the pictures (grey, one per lamp) against the
// destination's own photos (`own`, grey or colour) and the truth look.
struct LookBegun {
  nlohmann::json json;             // reference, mask, truth_noise / truth_error
  std::vector<cv::Mat> truth;      // the truth look, grey; empty when not rendered
  cv::Mat mask;                    // look.py's mask, empty = every pixel
  cv::Mat object;                  // the object the figures are repeated over when there is no mask
  std::string object_name;
  cv::Mat source_median;           // grey, where the map reads it
  double seconds = 0;
};
Expected<LookBegun> look_begin(const PreparedPair& pair, const TransferResult& result, bool floor,
                               const Progress& progress);
Expected<nlohmann::json> look_end(const LookBegun& begun, const std::vector<cv::Mat>& pictures,
                                  const std::vector<cv::Mat>& own, const cv::Mat& repainted_median,
                                  const cv::Mat& map_xy, double coverage, double coherence);

}  // namespace veneer::pipeline::detail
