// Turning what a camera delivers into a set image: JPEG → linear float,
// the JPEG inside a RAW file, file-name kinds.
#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "veneerd/hw/gphoto2.hpp"

namespace veneerd::hw {

namespace {

const std::array<float, 256>& srgb_to_linear_lut() {
  static const std::array<float, 256> lut = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) {
      double c = i / 255.0;
      t[i] = float(c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4));
    }
    return t;
  }();
  return lut;
}

// End (one past EOI) of a JPEG stream starting with SOI at `start`, or 0.
size_t jpeg_end(const std::vector<unsigned char>& d, size_t start) {
  size_t n = d.size();
  size_t i = start + 2;
  // Marker segments up to the first scan.
  for (;;) {
    if (i + 4 > n || d[i] != 0xFF) return 0;
    unsigned char m = d[i + 1];
    if (m == 0xFF) {  // fill byte
      ++i;
      continue;
    }
    if (m == 0xD8 || m == 0x01 || (m >= 0xD0 && m <= 0xD7)) {  // no length
      i += 2;
      continue;
    }
    if (m == 0xD9) return i + 2;
    size_t len = (size_t(d[i + 2]) << 8) | d[i + 3];
    if (len < 2 || i + 2 + len > n) return 0;
    i += 2 + len;
    if (m == 0xDA) break;
  }
  // Entropy-coded data (and further scans of progressive files) up to EOI.
  while (i + 1 < n) {
    if (d[i] != 0xFF) {
      ++i;
      continue;
    }
    unsigned char m = d[i + 1];
    if (m == 0x00 || m == 0xFF || (m >= 0xD0 && m <= 0xD7)) {
      i += (m == 0xFF) ? 1 : 2;
      continue;
    }
    if (m == 0xD9) return i + 2;
    // Another marker segment between scans (DHT, SOS, ...): skip its body.
    if (i + 4 > n) return 0;
    size_t len = (size_t(d[i + 2]) << 8) | d[i + 3];
    if (len < 2 || i + 2 + len > n) return 0;
    i += 2 + len;
  }
  return 0;
}

// Width and height the first frame header (SOFn) of a JPEG declares; empty
// when there is none before the first scan. Bytes between segments are
// skipped the way libjpeg resynchronises, so it finds what the decoder finds.
cv::Size jpeg_declared_size(const std::vector<unsigned char>& d) {
  const size_t n = d.size();
  size_t i = 2;
  while (i + 4 <= n) {
    if (d[i] != 0xFF || d[i + 1] == 0xFF || d[i + 1] == 0x00) {
      ++i;
      continue;
    }
    unsigned char m = d[i + 1];
    if (m == 0xD8 || m == 0x01 || (m >= 0xD0 && m <= 0xD7)) {  // no length
      i += 2;
      continue;
    }
    if (m == 0xD9 || m == 0xDA) break;
    size_t len = (size_t(d[i + 2]) << 8) | d[i + 3];
    if (len < 2 || i + 2 + len > n) break;
    bool sof = m >= 0xC0 && m <= 0xCF && m != 0xC4 && m != 0xC8 && m != 0xCC;
    if (sof && len >= 8) return cv::Size(int((d[i + 7] << 8) | d[i + 8]), int((d[i + 5] << 8) | d[i + 6]));
    i += 2 + len;
  }
  return {};
}

// Most pixels decoded at once (~1 GB as 8-bit plus float). A JPEG may declare
// up to 65535x65535 in a few hundred bytes; larger ones are decoded at 1/2,
// 1/4 or 1/8 scale (65535^2 / 64 still fits).
constexpr long long kMaxDecodePixels = 1LL << 26;

}  // namespace

veneer::Expected<cv::Mat> decode_jpeg_linear(const std::vector<unsigned char>& jpeg, cv::Size size) {
  if (jpeg.empty()) return veneer::make_error("empty image file");
  const cv::Size declared = jpeg_declared_size(jpeg);
  const long long pixels = (long long)declared.width * declared.height;
  int flags = cv::IMREAD_COLOR;
  if (pixels > kMaxDecodePixels) {
    if (pixels / 4 <= kMaxDecodePixels) flags = cv::IMREAD_REDUCED_COLOR_2;
    else if (pixels / 16 <= kMaxDecodePixels) flags = cv::IMREAD_REDUCED_COLOR_4;
    else flags = cv::IMREAD_REDUCED_COLOR_8;
  }
  cv::Mat img = cv::imdecode(jpeg, flags);
  if (img.empty() || img.depth() != CV_8U) return veneer::make_error("not a JPEG the decoder can read");
  return linearize_srgb8(img, size);
}

cv::Mat linearize_srgb8(const cv::Mat& img, cv::Size size) {
  CV_Assert(img.type() == CV_8UC3);
  const auto& lut = srgb_to_linear_lut();
  cv::Mat linear(img.size(), CV_32FC3);
  for (int y = 0; y < img.rows; ++y) {
    const unsigned char* s = img.ptr<unsigned char>(y);
    float* o = linear.ptr<float>(y);
    for (int x = 0; x < img.cols * 3; ++x) o[x] = lut[s[x]];
  }
  if (size.area() > 0 && size != linear.size()) {
    // Keep the aspect ratio of the still: fit inside `size`.
    double scale = std::min(double(size.width) / linear.cols, double(size.height) / linear.rows);
    cv::Size target(std::max(1, int(std::lround(linear.cols * scale))), std::max(1, int(std::lround(linear.rows * scale))));
    cv::Mat small;
    cv::resize(linear, small, target, 0, 0, scale < 1 ? cv::INTER_AREA : cv::INTER_LINEAR);
    linear = small;
  }
  return linear;
}

std::vector<unsigned char> embedded_jpeg(const std::vector<unsigned char>& raw) {
  size_t best_start = 0, best_len = 0;
  int candidates = 0;
  for (size_t i = 0; i + 3 < raw.size() && candidates < 64;) {
    if (raw[i] == 0xFF && raw[i + 1] == 0xD8 && raw[i + 2] == 0xFF) {
      ++candidates;
      size_t end = jpeg_end(raw, i);
      if (end > i) {
        if (end - i > best_len) {
          best_start = i;
          best_len = end - i;
        }
        i = end;
        continue;
      }
    }
    ++i;
  }
  if (best_len == 0) return {};
  return std::vector<unsigned char>(raw.begin() + long(best_start), raw.begin() + long(best_start + best_len));
}

bool is_raw_name(const std::string& file_name) {
  size_t dot = file_name.rfind('.');
  if (dot == std::string::npos) return false;
  std::string ext = file_name.substr(dot + 1);
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  static const char* raws[] = {"cr2", "cr3", "crw", "nef", "nrw", "arw", "srf", "sr2", "dng", "orf", "rw2", "raf", "pef", "raw"};
  return std::any_of(std::begin(raws), std::end(raws), [&](const char* r) { return ext == r; });
}

}  // namespace veneerd::hw
