#pragma once
// Live first: both sets of a pair read at the live view's size through a
// reduced decode (io/reduced.hpp: RAW mosaics binned, JPEGs decoded small in
// the DCT, RAW previews), then segmented and solved by photometric stereo at
// that size. The live repaint starts on the map of this pair while the
// full-resolution pair (prepare.hpp) is made behind it. No result cache: at
// the live size reading is cheaper than a cache entry would be.
#include <filesystem>
#include <vector>

#include "veneer/io/reduced.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/pipeline/prepare.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::pipeline {

struct LiveOptions {
  io::ReducedOptions read;  // live width (default 1280 px), which reduced decode (default auto)
  // Hand-drawn object masks (CV_8UC1 at any size, > 127 = object), resized to
  // the live size and used instead of the segmentation; empty = segment.
  cv::Mat destination_mask, source_mask;
  Status check() const;
};

// The pair at the live size, as pipeline::prepare_pair makes it from sets read
// with read_set_reduced (transfer.scale applies on top, normally 1).
// `reports` gets one SetReport per set (photos_from names the decode,
// checksum empty: no cache). Progress: reading 0-60 %, normals 60-100 %.
Expected<pipeline::PreparedPair> prepare_live_pair(const std::filesystem::path& destination,
                                                const std::filesystem::path& source,
                                                const pipeline::TransferOptions& transfer, const LiveOptions& options,
                                                std::vector<SetReport>* reports = nullptr,
                                                const Progress& progress = {});
// The same from the two sets already read by io::read_set_reduced with
// options.read (the viewer's flow reads them so to show them): not read
// again. Progress: normals 60-100 %.
Expected<pipeline::PreparedPair> prepare_live_pair(io::ImageSet destination, io::ImageSet source,
                                                const pipeline::TransferOptions& transfer, const LiveOptions& options,
                                                std::vector<SetReport>* reports = nullptr,
                                                const Progress& progress = {});

}  // namespace veneer::pipeline
