// PNG through libdeflate (png_codec.hpp). The chunk chain has been walked by
// image_io.cpp's check_png_chunks before decode_png_linear sees the bytes, so
// lengths stay inside the buffer; this file checks the CRCs of the chunks it
// uses, the IHDR fields, the image data's size and every row's filter.
#include "png_codec.hpp"

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <type_traits>
#include <vector>

#include <libdeflate.h>
#include <opencv2/core/utility.hpp>

#include "veneer/io/big_buffers.hpp"

namespace veneer::io::detail {

namespace {

constexpr unsigned char kMagic[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};

uint32_t be32(const unsigned char* p) {
  return (uint32_t(p[0]) << 24) | (uint32_t(p[1]) << 16) | (uint32_t(p[2]) << 8) | uint32_t(p[3]);
}

void put_be32(std::string& out, uint32_t v) {
  const char b[4] = {char(v >> 24), char(v >> 16), char(v >> 8), char(v)};
  out.append(b, 4);
}

struct DecompressorFree {
  void operator()(libdeflate_decompressor* d) const { libdeflate_free_decompressor(d); }
};
struct CompressorFree {
  void operator()(libdeflate_compressor* c) const { libdeflate_free_compressor(c); }
};

// The PNG row filters undone from `in` into `row` (distinct buffers); `prev`
// is the previous unfiltered row (zeros above the first). False for an
// unknown filter type.
bool unfilter(unsigned type, const unsigned char* in, unsigned char* row, const unsigned char* prev, size_t n,
              size_t bpp) {
  switch (type) {
    case 0: std::memcpy(row, in, n); return true;
    case 1:
      for (size_t i = 0; i < bpp; ++i) row[i] = in[i];
      for (size_t i = bpp; i < n; ++i) row[i] = static_cast<unsigned char>(in[i] + row[i - bpp]);
      return true;
    case 2:
      for (size_t i = 0; i < n; ++i) row[i] = static_cast<unsigned char>(in[i] + prev[i]);
      return true;
    case 3:
      for (size_t i = 0; i < bpp; ++i) row[i] = static_cast<unsigned char>(in[i] + (prev[i] >> 1));
      for (size_t i = bpp; i < n; ++i)
        row[i] = static_cast<unsigned char>(in[i] + ((unsigned(row[i - bpp]) + prev[i]) >> 1));
      return true;
    case 4:
      for (size_t i = 0; i < bpp; ++i) row[i] = static_cast<unsigned char>(in[i] + prev[i]);
      for (size_t i = bpp; i < n; ++i) {
        const int a = row[i - bpp], b = prev[i], c = prev[i - bpp];
        const int p = b - c, q = a - c;
        const int pa = std::abs(p), pb = std::abs(q), pc = std::abs(p + q);
        const int pred = (pa <= pb && pa <= pc) ? a : (pb <= pc ? b : c);
        row[i] = static_cast<unsigned char>(in[i] + pred);
      }
      return true;
    default: return false;
  }
}

// One unfiltered row (`channels` samples of `depth` bits per pixel, PNG's
// order R, G, B[, A] or grey[, alpha]) into `out` as float BGR in [0, 1].
void row_to_bgr(const unsigned char* in, float* out, int width, int channels, int depth) {
  const bool colour = channels >= 3;
  if (depth == 16) {
    constexpr float k = 1.0f / 65535.0f;
    const size_t step = size_t(channels) * 2;
    for (int x = 0; x < width; ++x, in += step, out += 3) {
      const float a = float((unsigned(in[0]) << 8) | in[1]) * k;
      if (colour) {
        out[2] = a;
        out[1] = float((unsigned(in[2]) << 8) | in[3]) * k;
        out[0] = float((unsigned(in[4]) << 8) | in[5]) * k;
      } else {
        out[0] = out[1] = out[2] = a;
      }
    }
  } else {
    constexpr float k = 1.0f / 255.0f;
    const size_t step = size_t(channels);
    for (int x = 0; x < width; ++x, in += step, out += 3) {
      if (colour) {
        out[2] = float(in[0]) * k;
        out[1] = float(in[1]) * k;
        out[0] = float(in[2]) * k;
      } else {
        out[0] = out[1] = out[2] = float(in[0]) * k;
      }
    }
  }
}

}  // namespace

std::optional<Expected<cv::Mat>> decode_png_linear(std::string_view bytes, const std::string& name) {
  if (bytes.size() < 8 + 25 || std::memcmp(bytes.data(), kMagic, 8) != 0) return std::nullopt;
  const auto* b = reinterpret_cast<const unsigned char*>(bytes.data());
  // The chunks this decoder uses; anything that changes the pixels (a
  // palette, a transparency key) sends the file to OpenCV.
  std::vector<std::pair<const unsigned char*, size_t>> idat;
  uint32_t width = 0, height = 0;
  int depth = 0, colour_type = 0, interlace = 0, compression = 0, filter_method = 0;
  size_t pos = 8, idat_bytes = 0;
  while (pos + 12 <= bytes.size()) {
    const uint32_t length = be32(b + pos);
    if (length > bytes.size() - pos - 12) break;  // check_png_chunks reports truncation
    const unsigned char* type = b + pos + 4;
    const unsigned char* data = b + pos + 8;
    const bool ihdr = std::memcmp(type, "IHDR", 4) == 0, is_idat = std::memcmp(type, "IDAT", 4) == 0;
    if (ihdr || is_idat) {
      const uint32_t crc = static_cast<uint32_t>(libdeflate_crc32(0, type, size_t(length) + 4));
      if (crc != be32(data + length))
        return Expected<cv::Mat>(make_error(name + ": corrupt PNG (CRC error in the " +
                                            std::string(reinterpret_cast<const char*>(type), 4) +
                                            " chunk at byte " + std::to_string(pos) + ")"));
    }
    if (ihdr) {
      if (length < 13) return Expected<cv::Mat>(make_error(name + ": corrupt PNG (short IHDR chunk)"));
      width = be32(data);
      height = be32(data + 4);
      depth = data[8];
      colour_type = data[9];
      compression = data[10];
      filter_method = data[11];
      interlace = data[12];
    } else if (is_idat) {
      idat.emplace_back(data, length);
      idat_bytes += length;
    } else if (std::memcmp(type, "PLTE", 4) == 0 || std::memcmp(type, "tRNS", 4) == 0) {
      return std::nullopt;
    } else if (std::memcmp(type, "IEND", 4) == 0) {
      break;
    }
    pos += size_t(length) + 12;
  }
  // DEFLATE expands at most ~1032:1: a file whose image data is too small
  // for the size its header declares is damaged (or hostile), and is named
  // so here, before this decoder or OpenCV's (interlaced, palette and
  // low-depth files) asks for a buffer of that size -- the fuzzer found a
  // 69-byte interlaced file declaring 8962x65280 (2.3 GB).
  {
    static constexpr int kSamples[7] = {1, 0, 3, 1, 2, 0, 4};  // per colour type; 0 = not a PNG type
    const int samples = colour_type >= 0 && colour_type < 7 ? kSamples[colour_type] : 0;
    const uint64_t row = (uint64_t(width) * uint64_t(samples) * uint64_t(depth) + 7) / 8 + 1;
    const uint64_t declared = uint64_t(height) * row;
    if (samples > 0 && declared / 1032 > idat_bytes + 64)
      return Expected<cv::Mat>(make_error(name + ": truncated PNG (" + std::to_string(idat_bytes) +
                                          " bytes of image data can't hold the " + std::to_string(width) + "x" +
                                          std::to_string(height) + " its header declares)"));
  }
  int channels = 0;
  switch (colour_type) {
    case 0: channels = 1; break;
    case 2: channels = 3; break;
    case 4: channels = 2; break;
    case 6: channels = 4; break;
    default: return std::nullopt;  // palette
  }
  if ((depth != 8 && depth != 16) || interlace != 0 || compression != 0 || filter_method != 0 || idat.empty() ||
      width == 0 || height == 0 || width > (1u << 16) || height > (1u << 16))
    return std::nullopt;

  // The zlib stream, in one piece (OpenCV writes it in 8 KiB chunks).
  std::string joined;
  const unsigned char* stream = idat.front().first;
  if (idat.size() > 1) {
    joined.reserve(idat_bytes);
    for (const auto& [p, n] : idat) joined.append(reinterpret_cast<const char*>(p), n);
    stream = reinterpret_cast<const unsigned char*>(joined.data());
  }
  const size_t bpp = size_t(channels) * size_t(depth) / 8;
  const size_t row_bytes = size_t(width) * bpp;
  const size_t expect = size_t(height) * (row_bytes + 1);
  // The inflated rows go straight into the tail of the float picture they
  // become (a float pixel takes more bytes than a filtered one): row y is
  // unfiltered into a small buffer, then written as floats over bytes whose
  // filtered rows (<= y) are already consumed -- row y's floats end at
  // 12*W*(y+1), row y+1's filtered bytes begin at 12*W*H - H*(r+1) + (y+1)*(r+1)
  // with r = W*bpp <= 8*W, never before. No intermediate buffer: the
  // picture's pages are the only fresh ones, faulted in at once.
  thread_local std::unique_ptr<libdeflate_decompressor, DecompressorFree> inflater;
  if (!inflater) inflater.reset(libdeflate_alloc_decompressor());
  if (!inflater) return Expected<cv::Mat>(make_error(name + ": out of memory for the PNG decoder"));
  cv::Mat out = big_mat(static_cast<int>(height), static_cast<int>(width), CV_32FC3);
  const size_t out_bytes = out.total() * out.elemSize();
  if (!out.isContinuous() || out_bytes < expect) return std::nullopt;  // not reached for 8/16-bit PNGs
  unsigned char* filtered = out.data + (out_bytes - expect);
  size_t got = 0;
  const auto r = libdeflate_zlib_decompress(inflater.get(), stream, idat_bytes, filtered, expect, &got);
  const std::string size_text = std::to_string(width) + "x" + std::to_string(height);
  if (r == LIBDEFLATE_INSUFFICIENT_SPACE)
    return Expected<cv::Mat>(make_error(name + ": corrupt PNG (more image data than " + size_text + " needs)"));
  if (r != LIBDEFLATE_SUCCESS)
    return Expected<cv::Mat>(make_error(name + ": corrupt PNG (its compressed image data does not inflate)"));
  if (got != expect)
    return Expected<cv::Mat>(make_error(name + ": truncated PNG (image data holds " + std::to_string(got) +
                                        " of the " + std::to_string(expect) + " bytes " + size_text + " needs)"));

  std::vector<unsigned char> rows(2 * row_bytes, 0);  // the row being unfiltered and the one above it
  unsigned char* cur = rows.data();
  unsigned char* prev = rows.data() + row_bytes;  // zeros above the first row
  for (uint32_t y = 0; y < height; ++y) {
    const unsigned char* in = filtered + size_t(y) * (row_bytes + 1);
    if (!unfilter(in[0], in + 1, cur, prev, row_bytes, bpp))
      return Expected<cv::Mat>(make_error(name + ": corrupt PNG (unknown row filter " + std::to_string(in[0]) +
                                          " in row " + std::to_string(y) + ")"));
    row_to_bgr(cur, out.ptr<float>(static_cast<int>(y)), static_cast<int>(width), channels, depth);
    std::swap(cur, prev);
  }
  return Expected<cv::Mat>(std::move(out));
}

namespace {

// One sample as the 16 bits a PNG stores: 8-bit and 16-bit values as they
// are, a float in [0, 1] scaled to 0..65535 (rounded, saturated, NaN -> 0,
// as cv::Mat::convertTo after cv::patchNaNs).
inline uint16_t sample16(uint16_t v) { return v; }
inline uint16_t sample16(float v) { return v == v ? cv::saturate_cast<uint16_t>(v * 65535.0f) : uint16_t(0); }

// One image row in PNG order (R, G, B; big-endian samples) into `p`.
template <class T>
void png_row(const T* s, int width, int channels, unsigned char* p) {
  const int swap = channels == 3 ? 2 : 0;  // BGR -> RGB
  if constexpr (!std::is_same_v<T, unsigned char>) {
    for (int x = 0; x < width; ++x, s += channels)
      for (int c = 0; c < channels; ++c) {
        const uint16_t v = sample16(s[swap ? swap - c : c]);
        *p++ = static_cast<unsigned char>(v >> 8);
        *p++ = static_cast<unsigned char>(v);
      }
  } else {
    for (int x = 0; x < width; ++x, s += channels)
      for (int c = 0; c < channels; ++c) *p++ = static_cast<unsigned char>(s[swap ? swap - c : c]);
  }
}

}  // namespace

std::string encode_png(const cv::Mat& image, int level) {
  const int channels = image.channels();
  const int depth = image.depth() == CV_8U ? 8 : 16;
  const int width = image.cols, height = image.rows;
  const size_t bpp = size_t(channels) * size_t(depth) / 8;
  const size_t row_bytes = size_t(width) * bpp;
  // Stored (level 0) rows go unfiltered: a filter only helps a compressor.
  const bool sub = level > 0;
  std::vector<unsigned char> filtered(size_t(height) * (row_bytes + 1));
  cv::parallel_for_(cv::Range(0, height), [&](const cv::Range& rows) {
    std::vector<unsigned char> plain(sub ? row_bytes : 0);
    for (int y = rows.start; y < rows.end; ++y) {
      unsigned char* row = filtered.data() + size_t(y) * (row_bytes + 1);
      row[0] = sub ? 1 : 0;
      unsigned char* p = sub ? plain.data() : row + 1;
      switch (image.depth()) {
        case CV_8U: png_row(image.ptr<unsigned char>(y), width, channels, p); break;
        case CV_16U: png_row(image.ptr<uint16_t>(y), width, channels, p); break;
        default: png_row(image.ptr<float>(y), width, channels, p); break;
      }
      if (!sub) continue;
      // Sub: each byte minus the same byte of the pixel to its left.
      for (size_t i = 0; i < bpp; ++i) row[1 + i] = plain[i];
      for (size_t i = bpp; i < row_bytes; ++i) row[1 + i] = static_cast<unsigned char>(plain[i] - plain[i - bpp]);
    }
  });
  std::unique_ptr<libdeflate_compressor, CompressorFree> deflater(libdeflate_alloc_compressor(level));

  std::string out(reinterpret_cast<const char*>(kMagic), 8);
  auto chunk = [&out](const char* type, const char* data, size_t n) {
    put_be32(out, static_cast<uint32_t>(n));
    const size_t start = out.size();
    out.append(type, 4);
    out.append(data, n);
    put_be32(out, static_cast<uint32_t>(libdeflate_crc32(0, out.data() + start, n + 4)));
  };
  std::string ihdr;
  put_be32(ihdr, static_cast<uint32_t>(width));
  put_be32(ihdr, static_cast<uint32_t>(height));
  const char colour_type = channels == 3 ? 2 : 0;
  const char tail[5] = {static_cast<char>(depth), colour_type, 0, 0, 0};
  ihdr.append(tail, 5);
  chunk("IHDR", ihdr.data(), ihdr.size());
  const size_t bound = libdeflate_zlib_compress_bound(deflater.get(), filtered.size());
  constexpr size_t kMaxChunk = size_t(1) << 30;
  if (bound <= kMaxChunk) {
    // One IDAT, compressed in place into the file's bytes (no second copy).
    const size_t at = out.size();
    out.resize(at + 8 + bound + 4 + 12);
    const size_t n = libdeflate_zlib_compress(deflater.get(), filtered.data(), filtered.size(), out.data() + at + 8,
                                              bound);
    const unsigned char head[8] = {static_cast<unsigned char>(n >> 24), static_cast<unsigned char>(n >> 16),
                                   static_cast<unsigned char>(n >> 8), static_cast<unsigned char>(n),
                                   'I', 'D', 'A', 'T'};
    std::memcpy(out.data() + at, head, 8);
    out.resize(at + 8 + n);  // shrinks: the compressed bytes stay
    put_be32(out, static_cast<uint32_t>(libdeflate_crc32(0, out.data() + at + 4, n + 4)));
  } else {
    std::string z(bound, '\0');
    z.resize(libdeflate_zlib_compress(deflater.get(), filtered.data(), filtered.size(), z.data(), z.size()));
    out.reserve(out.size() + z.size() + 128);
    for (size_t at = 0; at < z.size(); at += kMaxChunk) chunk("IDAT", z.data() + at, std::min(kMaxChunk, z.size() - at));
  }
  chunk("IEND", "", 0);
  return out;
}

}  // namespace veneer::io::detail
