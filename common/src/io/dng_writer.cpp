// DNG writer (dng.hpp): a little-endian TIFF whose IFD0 holds the Bayer
// mosaic (16-bit CFA samples, lossless JPEG tiles or one uncompressed strip)
// and the DNG tags a reader needs, and whose one SubIFD holds a reduced
// developed JPEG (NewSubFileType 1), as cameras' DNGs carry a preview.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "lj92.hpp"
#include "set_detail.hpp"
#include "veneer/io/camera_files.hpp"
#include "veneer/io/dng.hpp"

namespace veneer::io {

namespace {

enum Type : uint16_t { kByte = 1, kAscii = 2, kShort = 3, kLong = 4, kRational = 5, kSRational = 10 };
struct Entry {
  uint16_t tag;
  uint16_t type;
  uint32_t count;
  std::string data;  // the value's bytes, little-endian
};

void put16(std::string& s, uint16_t v) {
  s.push_back(static_cast<char>(v & 0xff));
  s.push_back(static_cast<char>(v >> 8));
}
void put32(std::string& s, uint32_t v) {
  for (int i = 0; i < 4; ++i) s.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}

Entry shorts(uint16_t tag, std::initializer_list<uint16_t> v) {
  Entry e{tag, kShort, static_cast<uint32_t>(v.size()), {}};
  for (uint16_t x : v) put16(e.data, x);
  return e;
}
Entry longs(uint16_t tag, std::initializer_list<uint32_t> v) {
  Entry e{tag, kLong, static_cast<uint32_t>(v.size()), {}};
  for (uint32_t x : v) put32(e.data, x);
  return e;
}
Entry bytes(uint16_t tag, std::initializer_list<uint8_t> v) {
  Entry e{tag, kByte, static_cast<uint32_t>(v.size()), {}};
  for (uint8_t x : v) e.data.push_back(static_cast<char>(x));
  return e;
}
Entry ascii(uint16_t tag, const std::string& text) {
  Entry e{tag, kAscii, static_cast<uint32_t>(text.size() + 1), text};
  e.data.push_back('\0');
  return e;
}
// Rationals with a fixed denominator of 10^6: enough for matrices and neutrals.
Entry rationals(uint16_t tag, const std::vector<double>& v, bool is_signed) {
  Entry e{tag, static_cast<uint16_t>(is_signed ? kSRational : kRational), static_cast<uint32_t>(v.size()), {}};
  for (double x : v) {
    const int64_t n = std::llround(x * 1e6);
    put32(e.data, static_cast<uint32_t>(static_cast<int32_t>(n)));
    put32(e.data, 1000000u);
  }
  return e;
}

Entry long_array(uint16_t tag, const std::vector<uint32_t>& v) {
  Entry e{tag, kLong, static_cast<uint32_t>(v.size()), {}};
  for (uint32_t x : v) put32(e.data, x);
  return e;
}

// One IFD at file offset `at`: the entry table, then the values that do not
// fit in an entry. Its length does not depend on the values, so a layout can
// be measured with zero offsets first and written again with the real ones.
std::string serialize_ifd(const std::vector<Entry>& entries, uint32_t at) {
  const uint32_t table = 2 + 12 * static_cast<uint32_t>(entries.size()) + 4;
  std::string extra;
  std::vector<uint32_t> offsets(entries.size(), 0);
  for (size_t i = 0; i < entries.size(); ++i) {
    if (entries[i].data.size() <= 4) continue;
    if ((at + table + extra.size()) % 2) extra.push_back('\0');  // word alignment
    offsets[i] = at + table + static_cast<uint32_t>(extra.size());
    extra += entries[i].data;
  }
  if ((at + table + extra.size()) % 2) extra.push_back('\0');
  std::string out;
  put16(out, static_cast<uint16_t>(entries.size()));
  for (size_t i = 0; i < entries.size(); ++i) {
    const Entry& e = entries[i];
    put16(out, e.tag);
    put16(out, e.type);
    put32(out, e.count);
    if (e.data.size() <= 4) {
      std::string v = e.data;
      v.resize(4, '\0');
      out += v;
    } else {
      put32(out, offsets[i]);
    }
  }
  put32(out, 0);  // no next IFD
  return out + extra;
}

void set_values(std::vector<Entry>& entries, uint16_t tag, const std::vector<uint32_t>& v) {
  for (auto& e : entries) {
    if (e.tag == tag) e = long_array(tag, v);
  }
}

constexpr int kTile = 256;  // tile side (Adobe's DNG converter's)

}  // namespace

Status DngOptions::check() const {
  if (white_level < 1 || white_level > 65535) return make_error("DNG white level must be in 1..65535");
  if (black_level < 0 || black_level >= white_level) return make_error("DNG black level must be in 0..white level - 1");
  for (int c = 0; c < 3; ++c) {
    if (!(as_shot_neutral[c] > 0 && as_shot_neutral[c] <= 1)) return make_error("DNG as-shot neutral must be in (0, 1]");
  }
  if (preview_divisor < 0 || preview_divisor > 16) return make_error("DNG preview divisor must be 0 (none) or 1..16");
  if (preview_quality < 1 || preview_quality > 100) return make_error("DNG preview quality must be in 1..100");
  return Status::success();
}

Expected<std::string> encode_dng(const cv::Mat& photo, const DngOptions& o) {
  if (Status s = o.check(); !s) return s.error();
  if (photo.type() != CV_32FC3) return make_error("DNG: the photo must be CV_32FC3 (linear BGR)");
  if (photo.empty() || photo.cols % 2 || photo.rows % 2)
    return make_error("DNG: width and height must be even and non-zero, got " + std::to_string(photo.cols) + "x" +
                      std::to_string(photo.rows));
  const int w = photo.cols, h = photo.rows;

  // The sensor counts of rows [y0, y0 + n) x columns [x0, x0 + tw) (edge
  // replicated past the image: the padding of edge tiles). R at (even, even),
  // G at (even, odd) and (odd, even), B at (odd, odd); the sensor clips at
  // its white level: photo * neutral <= 1.
  const double range = o.white_level - o.black_level;
  const float gain[3] = {static_cast<float>(o.as_shot_neutral[2] * range), static_cast<float>(o.as_shot_neutral[1] * range),
                         static_cast<float>(o.as_shot_neutral[0] * range)};  // per BGR channel
  const float limit[3] = {static_cast<float>(o.as_shot_neutral[2]), static_cast<float>(o.as_shot_neutral[1]),
                          static_cast<float>(o.as_shot_neutral[0])};
  auto counts = [&](int x0, int y0, int tw, int th, uint16_t* dst) {
    for (int ty = 0; ty < th; ++ty) {
      const int y = y0 + ty < h ? y0 + ty : h - 2 + (y0 + ty) % 2;  // past the edge: the last cell, same colour
      const float* row = photo.ptr<float>(y);
      for (int tx = 0; tx < tw; ++tx) {
        const int x = x0 + tx < w ? x0 + tx : w - 2 + (x0 + tx) % 2;
        const int channel = (y % 2 == 0) ? (x % 2 == 0 ? 2 : 1) : (x % 2 == 0 ? 1 : 0);  // BGR index
        float v = row[3 * x + channel];
        if (!std::isfinite(v)) v = 0;
        const float scaled = std::clamp(v * limit[channel], 0.0f, 1.0f) / limit[channel] * gain[channel];
        dst[static_cast<size_t>(ty) * tw + tx] = static_cast<uint16_t>(std::lround(o.black_level + scaled));
      }
    }
  };

  // The mosaic's data blocks: tiles of lossless JPEG (a single strip when the
  // image is one tile), or one uncompressed strip.
  int tile_w = kTile, tile_h = kTile;
  // LibRaw (0.20, lossless_dng_load_raw) reads a two-component tile whose
  // image is exactly twice as wide as the tile as another layout: such a
  // width gets one tile column.
  if (w == 2 * tile_w) tile_w = w;
  const bool tiled = o.compress && (w > tile_w || h > tile_h);
  if (!tiled) {
    tile_w = w;
    tile_h = h;
  }
  const int across = (w + tile_w - 1) / tile_w, down = (h + tile_h - 1) / tile_h;
  std::vector<std::string> blocks(static_cast<size_t>(across) * down);
  tbb::parallel_for(size_t(0), blocks.size(), [&](size_t i) {
    const int x0 = static_cast<int>(i % across) * tile_w, y0 = static_cast<int>(i / across) * tile_h;
    std::vector<uint16_t> tile(static_cast<size_t>(tile_w) * tile_h);
    counts(x0, y0, tile_w, tile_h, tile.data());
    if (o.compress) {
      blocks[i].reserve(tile.size() * 2);
      detail::encode_lossless_jpeg(tile.data(), tile_w, tile_h, tile_w, 2, blocks[i]);
    } else {
      blocks[i].resize(tile.size() * 2);
      for (size_t k = 0; k < tile.size(); ++k) {
        blocks[i][2 * k] = static_cast<char>(tile[k] & 0xff);
        blocks[i][2 * k + 1] = static_cast<char>(tile[k] >> 8);
      }
    }
  });

  // The preview: the developed photo (as the camera's JPEG) at 1/divisor.
  std::string preview;
  cv::Size preview_size;
  if (o.preview_divisor > 0) {
    preview_size = cv::Size(std::max(1, (w + o.preview_divisor / 2) / o.preview_divisor),
                            std::max(1, (h + o.preview_divisor / 2) / o.preview_divisor));
    cv::Mat small;
    if (preview_size == photo.size())
      small = photo;
    else
      cv::resize(photo, small, preview_size, 0, 0, cv::INTER_AREA);
    auto jpeg = encode_developed_jpeg(small, o.preview_quality);
    if (!jpeg) return make_error("DNG preview: " + jpeg.message());
    preview = std::move(jpeg).value();
  }

  // XYZ (D65) -> linear sRGB; the camera's native space is sRGB scaled by the
  // neutral, so ColorMatrix1 (XYZ -> camera) = diag(neutral) * this.
  const double xyz_to_srgb[3][3] = {{3.2404542, -1.5371385, -0.4985314},
                                    {-0.9692660, 1.8760108, 0.0415560},
                                    {0.0556434, -0.2040259, 1.0572252}};
  std::vector<double> matrix;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) matrix.push_back(o.as_shot_neutral[r] * xyz_to_srgb[r][c]);

  const uint32_t uw = static_cast<uint32_t>(w), uh = static_cast<uint32_t>(h);
  const std::vector<uint32_t> offsets_to_come(blocks.size(), 0);  // known once the IFD is laid out
  std::vector<Entry> ifd0 = {
      longs(254, {0}),                    // NewSubfileType: the main image
      longs(256, {uw}),                   // ImageWidth
      longs(257, {uh}),                   // ImageLength
      shorts(258, {16}),                  // BitsPerSample
      shorts(259, {static_cast<uint16_t>(o.compress ? 7 : 1)}),  // Compression: lossless JPEG | none
      shorts(262, {32803}),               // PhotometricInterpretation: CFA
      ascii(271, "Veneer"),               // Make
      ascii(272, o.camera_model),         // Model
  };
  if (!tiled) ifd0.push_back(longs(273, {0}));  // StripOffsets (set below)
  ifd0.push_back(shorts(274, {1}));             // Orientation: top-left
  ifd0.push_back(shorts(277, {1}));             // SamplesPerPixel
  if (!tiled) {
    ifd0.push_back(longs(278, {uh}));                                            // RowsPerStrip
    ifd0.push_back(longs(279, {static_cast<uint32_t>(blocks.front().size())}));  // StripByteCounts
  }
  ifd0.push_back(shorts(284, {1}));  // PlanarConfiguration: chunky
  if (tiled) {
    ifd0.push_back(longs(322, {static_cast<uint32_t>(tile_w)}));  // TileWidth
    ifd0.push_back(longs(323, {static_cast<uint32_t>(tile_h)}));  // TileLength
    ifd0.push_back(long_array(324, offsets_to_come));                  // TileOffsets (set below)
    std::vector<uint32_t> sizes;
    for (const auto& b : blocks) sizes.push_back(static_cast<uint32_t>(b.size()));
    ifd0.push_back(long_array(325, sizes));                        // TileByteCounts
  }
  if (!preview.empty()) ifd0.push_back(longs(330, {0}));  // SubIFDs: the preview (set below)
  for (Entry e : {shorts(33421, {2, 2}),          // CFARepeatPatternDim
                  bytes(33422, {0, 1, 1, 2}),     // CFAPattern: R G / G B
                  bytes(50706, {1, 4, 0, 0}),     // DNGVersion
                  bytes(50707, {1, 1, 0, 0}),     // DNGBackwardVersion
                  ascii(50708, o.camera_model),   // UniqueCameraModel
                  bytes(50710, {0, 1, 2}),        // CFAPlaneColor
                  shorts(50711, {1}),             // CFALayout: rectangular
                  longs(50714, {static_cast<uint32_t>(o.black_level)}),  // BlackLevel
                  longs(50717, {static_cast<uint32_t>(o.white_level)}),  // WhiteLevel
                  rationals(50721, matrix, true),                        // ColorMatrix1
                  rationals(50728, {o.as_shot_neutral[0], o.as_shot_neutral[1], o.as_shot_neutral[2]}, false),  // AsShotNeutral
                  shorts(50778, {21})})           // CalibrationIlluminant1: D65
    ifd0.push_back(std::move(e));
  std::vector<Entry> sub = {
      longs(254, {1}),                                                    // NewSubfileType: a reduced image
      longs(256, {static_cast<uint32_t>(preview_size.width)}),           // ImageWidth
      longs(257, {static_cast<uint32_t>(preview_size.height)}),          // ImageLength
      shorts(258, {8, 8, 8}),                                             // BitsPerSample
      shorts(259, {7}),                                                   // Compression: JPEG
      shorts(262, {6}),                                                   // PhotometricInterpretation: YCbCr
      longs(273, {0}),                                                    // StripOffsets (set below)
      shorts(277, {3}),                                                   // SamplesPerPixel
      longs(278, {static_cast<uint32_t>(preview_size.height)}),          // RowsPerStrip
      longs(279, {static_cast<uint32_t>(preview.size())}),               // StripByteCounts
      shorts(284, {1}),                                                   // PlanarConfiguration
  };

  // Layout: header (8) | IFD0 | the preview's IFD | preview JPEG | mosaic blocks.
  const uint32_t ifd0_at = 8;
  const uint32_t sub_at = ifd0_at + static_cast<uint32_t>(serialize_ifd(ifd0, ifd0_at).size());
  const uint32_t preview_at = sub_at + (preview.empty() ? 0 : static_cast<uint32_t>(serialize_ifd(sub, sub_at).size()));
  uint32_t at = preview_at + static_cast<uint32_t>(preview.size());
  at += at % 2;
  std::vector<uint32_t> block_at;
  uint64_t end = at;
  for (const auto& b : blocks) {
    block_at.push_back(static_cast<uint32_t>(end));
    end += b.size() + b.size() % 2;
  }
  if (end > 0xffffffffull) return make_error("DNG: " + std::to_string(end) + " bytes do not fit a TIFF file");
  if (tiled)
    set_values(ifd0, 324, block_at);
  else
    set_values(ifd0, 273, {block_at.front()});
  if (!preview.empty()) {
    set_values(ifd0, 330, {sub_at});
    set_values(sub, 273, {preview_at});
  }

  std::string out;
  out.reserve(static_cast<size_t>(end));
  out += "II";
  put16(out, 42);
  put32(out, ifd0_at);
  out += serialize_ifd(ifd0, ifd0_at);
  if (!preview.empty()) out += serialize_ifd(sub, sub_at);
  out += preview;
  if (out.size() % 2) out.push_back('\0');
  for (auto& b : blocks) {
    out += b;
    if (out.size() % 2) out.push_back('\0');
    std::string().swap(b);
  }
  return out;
}

Status add_dng_raw_files(ImageSet& set, const DngOptions& options) {
  auto encoded = detail::encode_frames<std::string>(set, [&](const cv::Mat& photo) { return encode_dng(photo, options); });
  if (!encoded) return encoded.error();
  set.raw.clear();
  for (size_t i = 0; i < set.images.size(); ++i) set.raw.push_back({"dng", std::move((*encoded)[i])});
  if (!set.ambient.empty()) set.ambient_raw = {"dng", std::move(encoded->back())};
  return Status::success();
}

}  // namespace veneer::io
