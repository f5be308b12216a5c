#pragma once
// Lossless JPEG (ITU T.81 process 14: SOF3, Huffman, predictor 1, point
// transform 0) encoder for DNG's Compression = 7 raw tiles, written from the
// standard (Annex H for the prediction, Annex C and K.2 for the Huffman code).
// Not part of the public API: dng_writer.cpp is its one user.
#include <cstdint>
#include <string>

namespace veneer::io::detail {

// Encodes `rows` rows of `columns` 16-bit samples (row stride `stride`
// samples) as one lossless JPEG of `components` interleaved components:
// each JPEG line holds columns / components samples per component, sample x
// of a row belonging to component x % components (DNG's layout for a Bayer
// mosaic: two components, so that each is predicted from the sample of its
// own colour two to the left). Sample precision 16. One Huffman table,
// optimal for this tile (Annex K.2, code lengths limited to 16 bits).
// `columns` must be a multiple of `components` (1..4); appends to `out`.
void encode_lossless_jpeg(const uint16_t* samples, int columns, int rows, int stride, int components,
                          std::string& out);

}  // namespace veneer::io::detail
