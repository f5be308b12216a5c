// DNG writer (dng.hpp): one little-endian TIFF IFD holding a single
// uncompressed strip of 16-bit CFA samples and the DNG tags a reader needs.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include <tbb/parallel_for.h>

#include "veneer/io/dng.hpp"

namespace veneer {

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

}  // namespace

Status DngOptions::check() const {
  if (white_level < 1 || white_level > 65535) return make_error("DNG white level must be in 1..65535");
  if (black_level < 0 || black_level >= white_level) return make_error("DNG black level must be in 0..white level - 1");
  for (int c = 0; c < 3; ++c) {
    if (!(as_shot_neutral[c] > 0 && as_shot_neutral[c] <= 1)) return make_error("DNG as-shot neutral must be in (0, 1]");
  }
  return Status::success();
}

Expected<std::string> encode_dng(const cv::Mat& photo, const DngOptions& o) {
  if (Status s = o.check(); !s) return s.error();
  if (photo.type() != CV_32FC3) return make_error("DNG: the photo must be CV_32FC3 (linear BGR)");
  if (photo.empty() || photo.cols % 2 || photo.rows % 2)
    return make_error("DNG: width and height must be even and non-zero, got " + std::to_string(photo.cols) + "x" +
                      std::to_string(photo.rows));
  const uint32_t w = static_cast<uint32_t>(photo.cols), h = static_cast<uint32_t>(photo.rows);
  const uint32_t strip_bytes = w * h * 2;

  // XYZ (D65) -> linear sRGB; the camera's native space is sRGB scaled by the
  // neutral, so ColorMatrix1 (XYZ -> camera) = diag(neutral) * this.
  const double xyz_to_srgb[3][3] = {{3.2404542, -1.5371385, -0.4985314},
                                    {-0.9692660, 1.8760108, 0.0415560},
                                    {0.0556434, -0.2040259, 1.0572252}};
  std::vector<double> matrix;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) matrix.push_back(o.as_shot_neutral[r] * xyz_to_srgb[r][c]);

  std::vector<Entry> entries = {
      longs(254, {0}),                    // NewSubfileType: the main image
      longs(256, {w}),                    // ImageWidth
      longs(257, {h}),                    // ImageLength
      shorts(258, {16}),                  // BitsPerSample
      shorts(259, {1}),                   // Compression: none
      shorts(262, {32803}),               // PhotometricInterpretation: CFA
      ascii(271, "Veneer"),               // Make
      ascii(272, o.camera_model),         // Model
      longs(273, {0}),                    // StripOffsets (patched below)
      shorts(274, {1}),                   // Orientation: top-left
      shorts(277, {1}),                   // SamplesPerPixel
      longs(278, {h}),                    // RowsPerStrip
      longs(279, {strip_bytes}),          // StripByteCounts
      shorts(284, {1}),                   // PlanarConfiguration: chunky
      shorts(33421, {2, 2}),              // CFARepeatPatternDim
      bytes(33422, {0, 1, 1, 2}),         // CFAPattern: R G / G B
      bytes(50706, {1, 4, 0, 0}),         // DNGVersion
      bytes(50707, {1, 1, 0, 0}),         // DNGBackwardVersion
      ascii(50708, o.camera_model),       // UniqueCameraModel
      bytes(50710, {0, 1, 2}),            // CFAPlaneColor
      shorts(50711, {1}),                 // CFALayout: rectangular
      longs(50714, {static_cast<uint32_t>(o.black_level)}),  // BlackLevel
      longs(50717, {static_cast<uint32_t>(o.white_level)}),  // WhiteLevel
      rationals(50721, matrix, true),                        // ColorMatrix1
      rationals(50728, {o.as_shot_neutral[0], o.as_shot_neutral[1], o.as_shot_neutral[2]}, false),  // AsShotNeutral
      shorts(50778, {21}),                // CalibrationIlluminant1: D65
  };
  // Layout: header (8) | IFD | out-of-line values | strip.
  const uint32_t ifd_size = 2 + 12 * static_cast<uint32_t>(entries.size()) + 4;
  uint32_t extra_at = 8 + ifd_size;
  std::string extra;
  std::vector<uint32_t> offsets(entries.size(), 0);
  for (size_t i = 0; i < entries.size(); ++i) {
    if (entries[i].data.size() <= 4) continue;
    if ((extra_at + extra.size()) % 2) extra.push_back('\0');  // word alignment
    offsets[i] = extra_at + static_cast<uint32_t>(extra.size());
    extra += entries[i].data;
  }
  if ((extra_at + extra.size()) % 2) extra.push_back('\0');
  const uint32_t strip_at = extra_at + static_cast<uint32_t>(extra.size());
  for (auto& e : entries) {
    if (e.tag == 273) {
      e.data.clear();
      put32(e.data, strip_at);
    }
  }

  std::string out;
  out.reserve(strip_at + strip_bytes);
  out += "II";
  put16(out, 42);
  put32(out, 8);
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
  out += extra;

  // The mosaic: R at (even, even), G at (even, odd) and (odd, even), B at (odd, odd).
  const size_t pixels_at = out.size();
  out.resize(pixels_at + strip_bytes);
  const double range = o.white_level - o.black_level;
  const float gain[3] = {static_cast<float>(o.as_shot_neutral[2] * range), static_cast<float>(o.as_shot_neutral[1] * range),
                         static_cast<float>(o.as_shot_neutral[0] * range)};  // per BGR channel
  const float limit[3] = {static_cast<float>(o.as_shot_neutral[2]), static_cast<float>(o.as_shot_neutral[1]),
                          static_cast<float>(o.as_shot_neutral[0])};
  for (uint32_t y = 0; y < h; ++y) {
    const float* row = photo.ptr<float>(static_cast<int>(y));
    char* dst = out.data() + pixels_at + static_cast<size_t>(y) * w * 2;
    for (uint32_t x = 0; x < w; ++x) {
      const int channel = (y % 2 == 0) ? (x % 2 == 0 ? 2 : 1) : (x % 2 == 0 ? 1 : 0);  // BGR index
      float v = row[3 * x + static_cast<uint32_t>(channel)];
      if (!std::isfinite(v)) v = 0;
      // The sensor clips at its white level: photo * neutral <= 1.
      const float scaled = std::clamp(v * limit[channel], 0.0f, 1.0f) / limit[channel] * gain[channel];
      const uint16_t count = static_cast<uint16_t>(std::lround(o.black_level + scaled));
      dst[2 * x] = static_cast<char>(count & 0xff);
      dst[2 * x + 1] = static_cast<char>(count >> 8);
    }
  }
  return out;
}

Status add_dng_raw_files(ImageSet& set, const DngOptions& options) {
  const size_t n = set.images.size() + (set.ambient.empty() ? 0 : 1);
  std::vector<Expected<std::string>> encoded(n, Expected<std::string>(std::string()));
  tbb::parallel_for(size_t(0), n, [&](size_t i) {
    encoded[i] = encode_dng(i < set.images.size() ? set.images[i] : set.ambient, options);
  });
  for (size_t i = 0; i < n; ++i) {
    if (!encoded[i]) return make_error((i < set.images.size() ? "image " + std::to_string(i) : std::string("ambient")) +
                                       ": " + encoded[i].message());
  }
  set.raw.clear();
  for (size_t i = 0; i < set.images.size(); ++i) set.raw.push_back({"dng", std::move(encoded[i]).value()});
  if (!set.ambient.empty()) set.ambient_raw = {"dng", std::move(encoded.back()).value()};
  return Status::success();
}

}  // namespace veneer
