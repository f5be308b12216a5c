#pragma once
// A test-only DNG writer that lays a file out as the Raspberry Pi camera's
// DNG library does (rpicam-apps image/dng.cpp, written from its description,
// no code taken): IFD 0 is a small 8-bit RGB thumbnail, the raw image is in a
// SubIFD as 16-bit samples holding a 10/12-bit sensor's counts, a 2x2
// BlackLevelRepeatDim with one black level per CFA cell, WhiteLevel
// 2^bits - 1, a CFA order of the sensor's (BGGR, GRBG, ...), AsShotNeutral =
// 1 / the white-balance gains and ColorMatrix1 = inverse(sRGB->XYZ x CCM x
// gains) -- the per-channel gains are inside the colour matrix too.
//
// The mosaic is what such a camera records of a linear sRGB photo:
// camera = gains^-1 x CCM^-1 x photo, in counts above black, clipped at white.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/core/mat.hpp>
#include <opencv2/imgproc.hpp>

namespace veneer::test {

struct PiDngOptions {
  int bits = 12;                          // sensor bit depth (10 or 12)
  int black_level = 256;                  // in sensor counts (12-bit: 4096 / 16)
  cv::Vec4i black_offsets{0, 0, 0, 0};    // added to black_level per CFA cell, in file order
  std::string cfa = "BGGR";               // the CFA order from the top-left cell
  cv::Vec2d gains{1.9, 1.6};              // red and blue white-balance gains (green 1)
  cv::Matx33d ccm{1.90255, -0.77478, -0.12777, -0.31338, 1.88197, -0.56858, -0.06001, -0.61785, 1.67786};
  double exposure = 1.0;                  // photo 1.0 -> this fraction of the white level (before the gains)
  uint16_t orientation = 1;               // TIFF Orientation of the main image: 1 (top-left) or 3 (the
                                          // sensor mounted upside down: the mosaic is stored rotated 180)
  std::string model = "imx477";
};

namespace pi_dng_detail {

struct Entry {
  uint16_t tag, type;
  uint32_t count;
  std::string data;
};
inline void put16(std::string& s, uint16_t v) {
  s.push_back(char(v & 0xff));
  s.push_back(char(v >> 8));
}
inline void put32(std::string& s, uint32_t v) {
  for (int i = 0; i < 4; ++i) s.push_back(char((v >> (8 * i)) & 0xff));
}
inline Entry shorts(uint16_t tag, std::vector<uint16_t> v) {
  Entry e{tag, 3, uint32_t(v.size()), {}};
  for (auto x : v) put16(e.data, x);
  return e;
}
inline Entry longs(uint16_t tag, std::vector<uint32_t> v) {
  Entry e{tag, 4, uint32_t(v.size()), {}};
  for (auto x : v) put32(e.data, x);
  return e;
}
inline Entry bytes(uint16_t tag, std::vector<uint8_t> v) {
  Entry e{tag, 1, uint32_t(v.size()), {}};
  for (auto x : v) e.data.push_back(char(x));
  return e;
}
inline Entry ascii(uint16_t tag, const std::string& t) {
  Entry e{tag, 2, uint32_t(t.size() + 1), t};
  e.data.push_back('\0');
  return e;
}
// libtiff writes FLOAT arrays as SRATIONAL for these tags; so do we.
inline Entry rationals(uint16_t tag, const std::vector<double>& v, bool is_signed) {
  Entry e{tag, uint16_t(is_signed ? 10 : 5), uint32_t(v.size()), {}};
  for (double x : v) {
    put32(e.data, uint32_t(int32_t(std::llround(x * 1e6))));
    put32(e.data, 1000000u);
  }
  return e;
}

// Appends one IFD (entries sorted by tag) and its out-of-line values at the
// end of `out`; `patch(tag)` gives values known only after layout. Returns the IFD's offset.
inline uint32_t append_ifd(std::string& out, std::vector<Entry> entries, uint32_t next_ifd = 0) {
  std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) { return a.tag < b.tag; });
  if (out.size() % 2) out.push_back('\0');
  const uint32_t at = uint32_t(out.size());
  const uint32_t size = 2 + 12 * uint32_t(entries.size()) + 4;
  uint32_t extra_at = at + size;
  std::string extra;
  std::vector<uint32_t> offsets(entries.size());
  for (size_t i = 0; i < entries.size(); ++i) {
    if (entries[i].data.size() <= 4) continue;
    if ((extra_at + extra.size()) % 2) extra.push_back('\0');
    offsets[i] = extra_at + uint32_t(extra.size());
    extra += entries[i].data;
  }
  put16(out, uint16_t(entries.size()));
  for (size_t i = 0; i < entries.size(); ++i) {
    put16(out, entries[i].tag);
    put16(out, entries[i].type);
    put32(out, entries[i].count);
    if (entries[i].data.size() <= 4) {
      std::string v = entries[i].data;
      v.resize(4, '\0');
      out += v;
    } else {
      put32(out, offsets[i]);
    }
  }
  put32(out, next_ifd);
  out += extra;
  return at;
}

inline void set_long(std::string& out, uint32_t at, uint32_t v) {
  for (int i = 0; i < 4; ++i) out[at + i] = char((v >> (8 * i)) & 0xff);
}

}  // namespace pi_dng_detail

// The DNG bytes for a linear photo (CV_32FC3 BGR, 1.0 = white); width and height even.
inline std::string encode_pi_dng(const cv::Mat& photo_in, const PiDngOptions& o = {}) {
  using namespace pi_dng_detail;
  CV_Assert(photo_in.type() == CV_32FC3 && photo_in.cols % 2 == 0 && photo_in.rows % 2 == 0);
  CV_Assert(o.orientation == 1 || o.orientation == 3);
  cv::Mat photo;  // a fresh Mat when rotated: never written into the caller's pixels
  if (o.orientation == 3) {
    cv::rotate(photo_in, photo, cv::ROTATE_180);
  } else {
    photo = photo_in;
  }
  const uint32_t w = uint32_t(photo.cols), h = uint32_t(photo.rows);
  const int white = (1 << o.bits) - 1;
  const cv::Matx33d wb(o.gains[0], 0, 0, 0, 1, 0, 0, 0, o.gains[1]);
  const cv::Matx33d rgb2xyz(0.4124564, 0.3575761, 0.1804375, 0.2126729, 0.7151522, 0.0721750, 0.0193339, 0.1191920,
                            0.9503041);
  const cv::Matx33d cam_xyz = (rgb2xyz * o.ccm * wb).inv();
  const cv::Matx33d photo_to_cam = (o.ccm * wb).inv();  // linear sRGB -> camera raw (r, g, b)
  std::vector<double> matrix;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) matrix.push_back(cam_xyz(r, c));
  auto colour_of = [&](char c) { return c == 'R' ? 0 : c == 'G' ? 1 : 2; };  // r, g, b index
  std::vector<uint8_t> cfa;
  for (char c : o.cfa) cfa.push_back(uint8_t(colour_of(c)));
  std::vector<uint32_t> blacks_rational;  // BlackLevel as RATIONAL (libtiff's type for it)
  std::string black_data;
  for (int i = 0; i < 4; ++i) {
    put32(black_data, uint32_t(o.black_level + o.black_offsets[i]));
    put32(black_data, 1u);
  }

  // The mosaic, 16-bit little-endian, `bits` of it used.
  std::string raw(size_t(w) * h * 2, '\0');
  for (uint32_t y = 0; y < h; ++y) {
    const cv::Vec3f* row = photo.ptr<cv::Vec3f>(int(y));
    for (uint32_t x = 0; x < w; ++x) {
      const int cell = int((y % 2) * 2 + (x % 2));
      const int colour = colour_of(o.cfa[size_t(cell)]);
      const cv::Vec3d rgb(row[x][2], row[x][1], row[x][0]);
      const cv::Vec3d cam = photo_to_cam * rgb;
      const int black = o.black_level + o.black_offsets[cell];
      const double counts = black + cam[colour] * o.exposure * (white - black);
      const uint16_t v = uint16_t(std::clamp<long>(std::lround(counts), 0, white));
      raw[(size_t(y) * w + x) * 2] = char(v & 0xff);
      raw[(size_t(y) * w + x) * 2 + 1] = char(v >> 8);
    }
  }
  // The thumbnail: 1/16 size, grey, 8-bit RGB.
  const uint32_t tw = std::max(1u, w >> 4), th = std::max(1u, h >> 4);
  std::string thumb(size_t(tw) * th * 3, '\0');
  for (uint32_t y = 0; y < th; ++y)
    for (uint32_t x = 0; x < tw; ++x) {
      const cv::Vec3f p = photo.at<cv::Vec3f>(int(std::min(h - 1, y * 16)), int(std::min(w - 1, x * 16)));
      const uint8_t g = uint8_t(std::clamp(255.0 * std::sqrt(std::max(0.0f, (p[0] + p[1] + p[2]) / 3)), 0.0, 255.0));
      for (int c = 0; c < 3; ++c) thumb[(size_t(y) * tw + x) * 3 + c] = char(g);
    }

  std::string out = "II";
  put16(out, 42);
  put32(out, 0);  // IFD 0 offset, patched
  const uint32_t thumb_at = uint32_t(out.size());
  out += thumb;
  if (out.size() % 2) out.push_back('\0');
  const uint32_t raw_at = uint32_t(out.size());
  out += raw;

  std::vector<Entry> main = {
      longs(254, {0}),          shorts(256, {uint16_t(w)}), shorts(257, {uint16_t(h)}), shorts(258, {16}),
      shorts(259, {1}),         shorts(262, {32803}),        longs(273, {raw_at}),       shorts(274, {o.orientation}),
      shorts(277, {1}),         longs(278, {h}),             longs(279, {uint32_t(raw.size())}), shorts(284, {1}),
      shorts(33421, {2, 2}),    bytes(33422, cfa),           shorts(50713, {2, 2}),
      Entry{50714, 5, 4, black_data},                        longs(50717, {uint32_t(white)}),
  };
  const uint32_t main_at = append_ifd(out, main);
  std::vector<Entry> ifd0 = {
      longs(254, {1}),
      shorts(256, {uint16_t(tw)}),
      shorts(257, {uint16_t(th)}),
      shorts(258, {8, 8, 8}),
      shorts(259, {1}),
      shorts(262, {2}),
      ascii(271, "Raspberry Pi"),
      ascii(272, o.model),
      longs(273, {thumb_at}),
      shorts(274, {1}),
      shorts(277, {3}),
      longs(278, {th}),
      longs(279, {uint32_t(thumb.size())}),
      shorts(284, {1}),
      ascii(305, "libcamera-still"),
      longs(330, {main_at}),
      bytes(50706, {1, 1, 0, 0}),
      bytes(50707, {1, 0, 0, 0}),
      ascii(50708, o.model),
      rationals(50721, matrix, true),
      rationals(50728, {1.0 / o.gains[0], 1.0, 1.0 / o.gains[1]}, false),
      shorts(50778, {21}),
  };
  const uint32_t ifd0_at = append_ifd(out, ifd0);
  set_long(out, 4, ifd0_at);
  return out;
}

}  // namespace veneer::test
