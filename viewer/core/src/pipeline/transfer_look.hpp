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

}  // namespace veneer::pipeline::detail
