#include "veneer/io/image_io.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "veneer/io/codecs.hpp"
#include <opencv2/imgproc.hpp>

#include "file_util.hpp"
#include "pixels.hpp"
#include "png_codec.hpp"

namespace veneer::io {
namespace fs = std::filesystem;

// --- pixel conversions (pixels.hpp) --------------------------------------

namespace detail {

Expected<cv::Mat> to_linear_bgr(const cv::Mat& raw, const std::string& name) {
  double scale;
  switch (raw.depth()) {
    case CV_8U: scale = 1.0 / 255.0; break;
    case CV_16U: scale = 1.0 / 65535.0; break;
    case CV_32F: scale = 1.0; break;
    default: return make_error(name + ": unsupported sample type (only 8- and 16-bit images are read)");
  }
  cv::Mat bgr;
  switch (raw.channels()) {
    case 1: cv::cvtColor(raw, bgr, cv::COLOR_GRAY2BGR); break;
    case 2: {
      cv::Mat grey;
      cv::extractChannel(raw, grey, 0);
      cv::cvtColor(grey, bgr, cv::COLOR_GRAY2BGR);
      break;
    }
    case 3: bgr = raw; break;
    case 4: cv::cvtColor(raw, bgr, cv::COLOR_BGRA2BGR); break;
    default: return make_error(name + ": unsupported channel count " + std::to_string(raw.channels()));
  }
  cv::Mat out;
  bgr.convertTo(out, CV_32FC3, scale);
  return out;
}

bool has_jpeg_magic(std::string_view b) {
  return b.size() >= 3 && static_cast<unsigned char>(b[0]) == 0xFF && static_cast<unsigned char>(b[1]) == 0xD8 &&
         static_cast<unsigned char>(b[2]) == 0xFF;
}

const std::array<float, 256>& srgb_to_linear_lut() {
  static const std::array<float, 256> lut = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) {
      const double c = i / 255.0;
      t[static_cast<size_t>(i)] = static_cast<float>(c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4));
    }
    return t;
  }();
  return lut;
}

Expected<cv::Mat> imdecode_bytes(std::string_view bytes, int flags, const std::string& name, const char* kind) {
  try {
    cv::Mat buffer(1, static_cast<int>(bytes.size()), CV_8UC1, const_cast<char*>(bytes.data()));
    return veneer::io::codecs::imdecode(buffer, flags);
  } catch (const cv::Exception& e) {
    return make_error(name + ": cannot decode" + kind + ": " + e.what());
  }
}

cv::Mat srgb8_to_linear(const cv::Mat& bgr8) {
  const auto& lut = srgb_to_linear_lut();
  cv::Mat out(bgr8.size(), CV_32FC3);
  for (int y = 0; y < bgr8.rows; ++y) {
    const uchar* s = bgr8.ptr<uchar>(y);
    float* o = out.ptr<float>(y);
    for (int x = 0; x < bgr8.cols * 3; ++x) o[x] = lut[s[x]];
  }
  return out;
}

}  // namespace detail

using namespace detail;

namespace {

// Largest side we accept from a file header (guards allocations on bad input).
constexpr long kMaxSide = 1 << 16;

uint32_t byteswap32(uint32_t v) {
  return (v >> 24) | ((v >> 8) & 0xff00u) | ((v << 8) & 0xff0000u) | (v << 24);
}

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f'; }

// --- PNG structure check -------------------------------------------------
// libpng (through OpenCV) decodes some damaged files without complaint, e.g.
// one cut after its last IDAT chunk, so the chunk chain is walked first.
constexpr std::array<unsigned char, 8> kPngMagic{0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

bool has_png_magic(std::string_view b) {
  return b.size() >= 8 && std::memcmp(b.data(), kPngMagic.data(), 8) == 0;
}

uint32_t be32(const char* p) {
  auto u = [&](int i) { return static_cast<uint32_t>(static_cast<unsigned char>(p[i])); };
  return (u(0) << 24) | (u(1) << 16) | (u(2) << 8) | u(3);
}

Status check_png_chunks(std::string_view b, const std::string& name) {
  size_t pos = 8;
  bool first = true, idat = false;
  while (true) {
    if (pos + 8 > b.size())
      return make_error(name + ": truncated PNG (file ends at byte " + std::to_string(b.size()) +
                        " before the IEND chunk)");
    uint32_t length = be32(b.data() + pos);
    std::string type(b.data() + pos + 4, 4);
    if (length > 0x7fffffffu) return make_error(name + ": corrupt PNG (chunk length out of range at byte " +
                                                std::to_string(pos) + ")");
    if (first && type != "IHDR") return make_error(name + ": corrupt PNG (first chunk is not IHDR)");
    first = false;
    if (b.size() - pos - 8 < static_cast<size_t>(length) + 4)
      return make_error(name + ": truncated PNG (file ends inside its " + type + " chunk at byte " +
                        std::to_string(b.size()) + ")");
    if (type == "IHDR") {
      if (length < 8) return make_error(name + ": corrupt PNG (short IHDR chunk)");
      const uint32_t w = be32(b.data() + pos + 8), h = be32(b.data() + pos + 12);
      if (w == 0 || h == 0 || w > static_cast<uint32_t>(kMaxSide) || h > static_cast<uint32_t>(kMaxSide))
        return make_error(name + ": PNG size " + std::to_string(w) + "x" + std::to_string(h) + " is out of range");
    }
    if (type == "IDAT") idat = true;
    pos += 12 + static_cast<size_t>(length);
    if (type == "IEND") break;
  }
  if (!idat) return make_error(name + ": corrupt PNG (no image data)");
  return Status::success();
}

// --- PNM (PPM/PGM) structure check ----------------------------------------
bool has_pnm_magic(std::string_view b) {
  return b.size() >= 2 && b[0] == 'P' && (b[1] >= '1' && b[1] <= '6') && (b.size() == 2 || is_space(b[2]) || b[2] == '#');
}

// The header's size against the bytes that follow, before OpenCV allocates
// the picture: binary variants (P4-P6) need every sample's bytes, ASCII ones
// (P1-P3) at least a digit per sample (and a separator for P2/P3), so an
// 18-byte file declaring 266666x3534 is refused, not a 2.8 GB buffer asked for.
Status check_pnm(std::string_view b, const std::string& name) {
  const char kind = b[1];
  const bool bitmap = kind == '1' || kind == '4';
  size_t pos = 2;
  long fields[3] = {0, 0, 0};
  for (int f = 0; f < (bitmap ? 2 : 3); ++f) {
    long& field = fields[f];
    while (pos < b.size() && (is_space(b[pos]) || b[pos] == '#')) {
      if (b[pos] == '#') {
        while (pos < b.size() && b[pos] != '\n') ++pos;
      } else {
        ++pos;
      }
    }
    size_t start = pos;
    while (pos < b.size() && b[pos] >= '0' && b[pos] <= '9' && pos - start < 9) field = field * 10 + (b[pos++] - '0');
    if (pos == start)
      return make_error(name + (bitmap ? ": corrupt PBM header (expected width and height)"
                                       : ": corrupt PNM header (expected width, height and maxval)"));
  }
  if (pos >= b.size() || !is_space(b[pos])) return make_error(name + ": corrupt PNM header");
  ++pos;
  long w = fields[0], h = fields[1], maxval = bitmap ? 1 : fields[2];
  if (w <= 0 || h <= 0 || w > kMaxSide || h > kMaxSide)
    return make_error(name + ": bad PNM size " + std::to_string(w) + "x" + std::to_string(h));
  if (maxval <= 0 || maxval > 65535) return make_error(name + ": bad PNM maxval " + std::to_string(maxval));
  const size_t samples = static_cast<size_t>(w) * h * (kind == '3' || kind == '6' ? 3 : 1);
  size_t need = 0;
  switch (kind) {
    case '4': need = static_cast<size_t>((w + 7) / 8) * h; break;
    case '5':
    case '6': need = samples * (maxval > 255 ? 2 : 1); break;
    case '1': need = samples; break;      // a digit per pixel, separators optional
    default: need = 2 * samples - 1; break;  // P2/P3: a digit and a separator per sample
  }
  if (b.size() - pos < need)
    return make_error(name + ": truncated PNM (" + std::to_string(b.size() - pos) + " bytes of pixels, expected " +
                      (kind >= '1' && kind <= '3' ? "at least " : "") + std::to_string(need) + ")");
  return Status::success();
}

// A JPEG (a camera's developed photo: 8-bit sRGB) as linear CV_32FC3 BGR.
Expected<cv::Mat> decode_jpeg_linear(std::string_view bytes, const std::string& name) {
  auto bgr8 = imdecode_bytes(bytes, cv::IMREAD_COLOR, name, " JPEG");
  if (!bgr8) return bgr8.error();
  if (bgr8->empty() || bgr8->type() != CV_8UC3) return make_error(name + ": corrupt or truncated JPEG (decoder failed)");
  return srgb8_to_linear(*bgr8);
}

Expected<cv::Mat> decode_raw(std::string_view bytes, const std::string& name) {
  if (has_png_magic(bytes)) {
    if (Status s = check_png_chunks(bytes, name); !s) return s.error();
  } else if (has_pnm_magic(bytes)) {
    if (Status s = check_pnm(bytes, name); !s) return s.error();
  } else if (bytes.empty()) {
    return make_error(name + ": empty file");
  } else {
    return make_error(name + ": not a PNG, PPM, PGM or PFM file (unrecognised first bytes)");
  }
  auto raw = imdecode_bytes(bytes, cv::IMREAD_UNCHANGED, name);
  if (raw && raw->empty()) return make_error(name + ": corrupt or truncated image (decoder failed)");
  return raw;
}

}  // namespace

// --- files ---------------------------------------------------------------

Expected<std::string> read_file_bytes(const fs::path& file) {
  int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    int err = errno;
    if (err == ENOENT) return make_error(file.string() + ": file not found");
    return make_error(file.string() + ": cannot open: " + std::strerror(err));
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || S_ISDIR(st.st_mode)) {
    ::close(fd);
    return make_error(file.string() + (S_ISDIR(st.st_mode) ? ": is a folder, expected a file" : ": cannot stat"));
  }
  std::string bytes;
  // One spare byte, so end of file is seen without growing the buffer.
  bytes.resize(S_ISREG(st.st_mode) ? static_cast<size_t>(st.st_size) + 1 : 0);
  size_t done = 0;
  while (true) {
    if (done == bytes.size()) bytes.resize(std::max<size_t>(4096, bytes.size() * 2));  // grew, or not a regular file
    ssize_t n = ::read(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      int err = errno;
      ::close(fd);
      return make_error(file.string() + ": read error: " + std::strerror(err));
    }
    if (n == 0) break;
    done += static_cast<size_t>(n);
  }
  ::close(fd);
  bytes.resize(done);
  return bytes;
}

Status write_file_atomic(const fs::path& file, const std::string& bytes, Sync sync) {
  fs::path tmp = detail::temp_sibling(file);
  if (Status s = detail::write_file_synced(tmp, bytes, sync == Sync::each); !s) {
    ::unlink(tmp.c_str());
    return make_error(file.string() + ": " + s.message());
  }
  if (::rename(tmp.c_str(), file.c_str()) != 0) {
    int err = errno;
    ::unlink(tmp.c_str());
    return make_error(file.string() + ": cannot rename temporary file into place: " + std::strerror(err));
  }
  if (sync == Sync::later) return Status::success();
  return detail::fsync_dir(file.parent_path());
}

Status sync_folder(const fs::path& folder) { return detail::fsync_dir(folder); }

Status write_file_synced(const fs::path& file, std::string_view bytes) {
  return detail::write_file_synced(file, bytes);
}

Expected<std::string> encode_png8(const cv::Mat& image) {
  // grey and BGR through libdeflate (png_codec.hpp), the rest through OpenCV
  if (image.depth() == CV_8U && (image.channels() == 1 || image.channels() == 3)) return detail::encode_png(image, 1);
  std::vector<uchar> buffer;
  try {
    if (!veneer::io::codecs::imencode(".png", image, buffer)) return make_error("PNG encoder failed");
  } catch (const cv::Exception& e) {
    return make_error(std::string("PNG encoder failed: ") + e.what());
  }
  return std::string(buffer.begin(), buffer.end());
}

// --- PFM -----------------------------------------------------------------

std::string encode_pfm(const cv::Mat& image, bool xyz_order) {
  const int channels = image.channels();
  std::string out = (channels == 3 ? "PF\n" : "Pf\n") + std::to_string(image.cols) + " " +
                    std::to_string(image.rows) + "\n-1.0\n";
  const size_t header = out.size();
  out.resize(header + static_cast<size_t>(image.total()) * channels * 4);
  char* dst = out.data() + header;
  for (int row = image.rows - 1; row >= 0; --row) {
    const float* src = image.ptr<float>(row);
    for (int x = 0; x < image.cols; ++x) {
      for (int c = 0; c < channels; ++c) {
        // File slots are R, G, B. xyz: slot c <- Mat channel c; photo (BGR): slot c <- Mat channel 2-c.
        int from = (channels == 3 && !xyz_order) ? 2 - c : c;
        uint32_t bits = std::bit_cast<uint32_t>(src[x * channels + from]);
        if constexpr (std::endian::native == std::endian::big) bits = byteswap32(bits);
        std::memcpy(dst, &bits, 4);
        dst += 4;
      }
    }
  }
  return out;
}

Status write_pfm(const fs::path& file, const cv::Mat& image, bool xyz_order, Sync sync) {
  if (image.empty()) return make_error(file.string() + ": cannot write an empty image");
  if (image.depth() != CV_32F || (image.channels() != 1 && image.channels() != 3))
    return make_error(file.string() + ": PFM needs a CV_32FC1 or CV_32FC3 image");
  return write_file_atomic(file, encode_pfm(image, xyz_order), sync);
}

Expected<cv::Mat> read_pfm_bytes(std::string_view b, bool xyz_order, const std::string& name) {
  if (b.size() < 2 || b[0] != 'P' || (b[1] != 'F' && b[1] != 'f'))
    return make_error(name + ": not a PFM file (expected \"PF\" or \"Pf\" at the start)");
  const int channels = b[1] == 'F' ? 3 : 1;
  size_t pos = 2;
  auto next_token = [&](size_t max_len) -> std::string_view {
    while (pos < b.size() && is_space(b[pos])) ++pos;
    size_t start = pos;
    while (pos < b.size() && !is_space(b[pos]) && pos - start <= max_len) ++pos;
    return b.substr(start, pos - start);
  };
  std::string_view wtok = next_token(10), htok = next_token(10), stok = next_token(40);
  long w = 0, h = 0;
  auto [wp, wec] = std::from_chars(wtok.data(), wtok.data() + wtok.size(), w);
  auto [hp, hec] = std::from_chars(htok.data(), htok.data() + htok.size(), h);
  if (wec != std::errc() || hec != std::errc() || wp != wtok.data() + wtok.size() || hp != htok.data() + htok.size())
    return make_error(name + ": corrupt PFM header (width and height must be integers)");
  if (w <= 0 || h <= 0 || w > kMaxSide || h > kMaxSide)
    return make_error(name + ": bad PFM size " + std::to_string(w) + "x" + std::to_string(h));
  double scale = 0;
  auto [sp, sec] = std::from_chars(stok.data(), stok.data() + stok.size(), scale);
  if (sec != std::errc() || sp != stok.data() + stok.size() || !std::isfinite(scale) || scale == 0)
    return make_error(name + ": corrupt PFM header (scale must be a non-zero number, got \"" +
                      std::string(stok.substr(0, 20)) + "\")");
  // Exactly one whitespace character separates the header from the pixels.
  if (pos >= b.size() || !is_space(b[pos])) return make_error(name + ": truncated PFM (no pixel data)");
  ++pos;
  const bool little = scale < 0;
  const size_t need = static_cast<size_t>(w) * static_cast<size_t>(h) * channels * 4;
  if (b.size() - pos < need)
    return make_error(name + ": truncated PFM (" + std::to_string(b.size() - pos) + " bytes of pixels, expected " +
                      std::to_string(need) + " for " + std::to_string(w) + "x" + std::to_string(h) + ")");
  const bool swap = little != (std::endian::native == std::endian::little);
  cv::Mat image(static_cast<int>(h), static_cast<int>(w), CV_MAKETYPE(CV_32F, channels));
  const char* src = b.data() + pos;
  for (int row = image.rows - 1; row >= 0; --row) {
    float* dst = image.ptr<float>(row);
    for (int x = 0; x < image.cols; ++x) {
      for (int c = 0; c < channels; ++c) {
        uint32_t bits;
        std::memcpy(&bits, src, 4);
        src += 4;
        if (swap) bits = byteswap32(bits);
        int to = (channels == 3 && !xyz_order) ? 2 - c : c;
        dst[x * channels + to] = std::bit_cast<float>(bits);
      }
    }
  }
  return image;
}

Expected<cv::Mat> read_pfm(const fs::path& file, bool xyz_order) {
  auto bytes = read_file_bytes(file);
  if (!bytes) return bytes.error();
  return read_pfm_bytes(*bytes, xyz_order, file.string());
}

// --- PNG / PNM -------------------------------------------------------------

Expected<std::string> encode_png16(const cv::Mat& image, PngDeflate deflate) {
  if (image.empty()) return make_error("cannot encode an empty image");
  if (image.depth() != CV_32F || (image.channels() != 1 && image.channels() != 3))
    return make_error("16-bit PNG needs a CV_32FC1 or CV_32FC3 image");
  // libdeflate, rows Sub-filtered (png_codec.hpp) at its fastest level:
  // faster than OpenCV's zlib level 1 with the RLE strategy, and smaller; or
  // stored. The float -> 16-bit conversion is part of the row pass.
  return detail::encode_png(image, deflate == PngDeflate::stored ? 0 : 1);
}

Status write_png16(const fs::path& file, const cv::Mat& image, Sync sync, PngDeflate deflate) {
  auto bytes = encode_png16(image, deflate);
  if (!bytes) return make_error(file.string() + ": " + bytes.message());
  return write_file_atomic(file, *bytes, sync);
}

Expected<cv::Mat> decode_linear_image(std::string_view bytes, const std::string& name) {
  if (bytes.size() >= 2 && bytes[0] == 'P' && (bytes[1] == 'F' || bytes[1] == 'f')) {
    auto pfm = read_pfm_bytes(bytes, false, name);
    if (!pfm) return pfm.error();
    if (pfm->channels() == 3) return pfm;
    cv::Mat bgr;
    cv::cvtColor(*pfm, bgr, cv::COLOR_GRAY2BGR);
    return bgr;
  }
  if (has_jpeg_magic(bytes)) return decode_jpeg_linear(bytes, name);
  if (has_png_magic(bytes)) {
    if (Status s = check_png_chunks(bytes, name); !s) return s.error();
    if (auto fast = detail::decode_png_linear(bytes, name)) return std::move(*fast);
  }
  auto raw = decode_raw(bytes, name);
  if (!raw) return raw.error();
  return to_linear_bgr(*raw, name);
}

std::string image_file_kind(std::string_view bytes) {
  if (has_png_magic(bytes)) return "png";
  if (has_jpeg_magic(bytes)) return "jpeg";
  if (bytes.size() >= 2 && bytes[0] == 'P' && (bytes[1] == 'F' || bytes[1] == 'f')) return "pfm";
  if (has_pnm_magic(bytes)) return "pnm";
  return {};
}

Expected<cv::Mat> read_linear_image(const fs::path& file) {
  auto bytes = read_file_bytes(file);
  if (!bytes) return bytes.error();
  return decode_linear_image(*bytes, file.string());
}

Expected<cv::Mat> read_mask(const fs::path& file) {
  auto bytes = read_file_bytes(file);
  if (!bytes) return bytes.error();
  auto raw = decode_raw(*bytes, file.string());
  if (!raw) return raw.error();
  cv::Mat grey;
  if (raw->channels() == 1) {
    grey = *raw;
  } else {
    // Any non-zero colour channel counts as object.
    std::vector<cv::Mat> planes;
    cv::split(*raw, planes);
    grey = planes[0].clone();
    for (size_t i = 1; i < planes.size() && i < 3; ++i) cv::max(grey, planes[i], grey);
  }
  cv::Mat mask = grey > 0;
  return mask;
}

// --- pictures --------------------------------------------------------------

cv::Mat normals_picture(const cv::Mat& normals) {
  cv::Mat out(normals.size(), CV_8UC3, cv::Scalar::all(0));
  if (normals.empty() || normals.type() != CV_32FC3) return out;
  for (int y = 0; y < normals.rows; ++y) {
    const cv::Vec3f* n = normals.ptr<cv::Vec3f>(y);
    cv::Vec3b* o = out.ptr<cv::Vec3b>(y);
    for (int x = 0; x < normals.cols; ++x) {
      const cv::Vec3f v = n[x];
      if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2])) continue;
      if (v[0] == 0 && v[1] == 0 && v[2] == 0) continue;
      auto to8 = [](float c) { return cv::saturate_cast<uchar>((c + 1.0f) * 0.5f * 255.0f + 0.5f); };
      o[x] = cv::Vec3b(to8(v[2]), to8(v[1]), to8(v[0]));  // B = z, G = y, R = x
    }
  }
  return out;
}

cv::Mat tonemap_picture(const cv::Mat& linear, double percentile) {
  if (linear.empty()) return {};
  cv::Mat f;
  linear.convertTo(f, CV_MAKETYPE(CV_32F, linear.channels()));
  if (f.channels() == 1) cv::cvtColor(f, f, cv::COLOR_GRAY2BGR);
  if (f.channels() == 4) cv::cvtColor(f, f, cv::COLOR_BGRA2BGR);
  // Brightest channel per pixel, sampled, to find the exposure that puts the
  // chosen percentile at white.
  std::vector<float> samples;
  const size_t total = f.total();
  const size_t stride = std::max<size_t>(1, total / 500000);
  samples.reserve(total / stride + 1);
  for (size_t i = 0; i < total; i += stride) {
    const cv::Vec3f v = f.at<cv::Vec3f>(static_cast<int>(i / f.cols), static_cast<int>(i % f.cols));
    float m = std::max({v[0], v[1], v[2]});
    if (std::isfinite(m)) samples.push_back(m);
  }
  float white = 1.0f;
  if (!samples.empty()) {
    double p = std::clamp(percentile, 0.0, 100.0) / 100.0;
    size_t k = std::min(samples.size() - 1, static_cast<size_t>(p * (samples.size() - 1) + 0.5));
    std::nth_element(samples.begin(), samples.begin() + static_cast<long>(k), samples.end());
    if (samples[k] > 1e-12f) white = samples[k];
  }
  std::array<uchar, 4097> lut{};
  for (int i = 0; i <= 4096; ++i) {
    double v = i / 4096.0;
    double s = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
    lut[i] = cv::saturate_cast<uchar>(s * 255.0 + 0.5);
  }
  cv::Mat out(f.size(), CV_8UC3);
  const float k = 4096.0f / white;
  for (int y = 0; y < f.rows; ++y) {
    const float* src = f.ptr<float>(y);
    uchar* dst = out.ptr<uchar>(y);
    for (int x = 0; x < f.cols * 3; ++x) {
      float v = src[x] * k;
      int idx = std::isfinite(v) ? static_cast<int>(std::clamp(v, 0.0f, 4096.0f) + 0.5f) : 0;
      dst[x] = lut[static_cast<size_t>(idx)];
    }
  }
  return out;
}

Status write_picture(const fs::path& file, const cv::Mat& bgr8, Sync sync) {
  if (bgr8.empty()) return make_error(file.string() + ": cannot write an empty picture");
  if (bgr8.depth() != CV_8U) return make_error(file.string() + ": a picture must be 8-bit");
  // grey and BGR through libdeflate at its fastest level (png_codec.hpp): no
  // image codec library opened for a transfer's pictures (issue 48)
  if (bgr8.channels() == 1 || bgr8.channels() == 3)
    return write_file_atomic(file, detail::encode_png(bgr8, 1), sync);
  std::vector<uchar> buffer;
  try {
    if (!veneer::io::codecs::imencode(".png", bgr8, buffer)) return make_error(file.string() + ": PNG encoder failed");
  } catch (const cv::Exception& e) {
    return make_error(file.string() + ": PNG encoder failed: " + e.what());
  }
  return write_file_atomic(file, std::string(buffer.begin(), buffer.end()), sync);
}

}  // namespace veneer::io
