// A layout's photo file, whatever it is: a camera RAW file (by its name,
// through LibRaw), a TIFF (8- or 16-bit, through OpenCV), or what
// decode_linear_image reads (PNG, JPEG, PFM, PNM). 8-bit samples are taken
// as sRGB code values where the layout says so (set_detail.hpp, Frame).
#include <array>
#include <cmath>
#include <cstring>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "pixels.hpp"
#include "set_detail.hpp"
#include "veneer/io/image_io.hpp"

namespace veneer::io::detail {

namespace {

bool has_tiff_magic(std::string_view b) {
  return b.size() >= 8 && ((std::memcmp(b.data(), "II*\0", 4) == 0) || (std::memcmp(b.data(), "MM\0*", 4) == 0));
}

// A PNG's bit depth from its IHDR (the first chunk), 0 when not a PNG.
int png_bit_depth(std::string_view b) {
  static const unsigned char kMagic[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (b.size() < 8 + 8 + 13 || std::memcmp(b.data(), kMagic, 8) != 0) return 0;
  if (std::memcmp(b.data() + 12, "IHDR", 4) != 0) return 0;
  return static_cast<unsigned char>(b[24]);
}

// Most pixels a TIFF photo may declare (as the PNG path: a 100 Mpx sensor).
constexpr long long kMaxTiffPixels = 100'000'000;

// Reads the first IFD's width and height (tags 256, 257) before OpenCV
// allocates anything: a damaged header can claim anything.
Status check_tiff_size(std::string_view b, const std::string& name) {
  const bool le = b[0] == 'I';
  auto u16 = [&](size_t at) -> uint32_t {
    const auto* p = reinterpret_cast<const unsigned char*>(b.data()) + at;
    return le ? (p[0] | (p[1] << 8)) : ((p[0] << 8) | p[1]);
  };
  auto u32 = [&](size_t at) -> uint32_t {
    return le ? (u16(at) | (u16(at + 2) << 16)) : ((u16(at) << 16) | u16(at + 2));
  };
  const uint32_t ifd = u32(4);
  if (ifd < 8 || ifd > b.size() - 2) return make_error(name + ": damaged TIFF (first directory outside the file)");
  const uint32_t n = u16(ifd);
  if (n == 0 || size_t(ifd) + 2 + size_t(n) * 12 > b.size()) return make_error(name + ": damaged TIFF (truncated directory)");
  long long w = 0, h = 0;
  for (uint32_t i = 0; i < n; ++i) {
    const size_t e = ifd + 2 + size_t(i) * 12;
    const uint32_t tag = u16(e), type = u16(e + 2);
    const uint32_t value = type == 3 ? u16(e + 8) : u32(e + 8);
    if (tag == 256) w = value;
    if (tag == 257) h = value;
  }
  if (w <= 0 || h <= 0 || w > kMaxSide || h > kMaxSide || w * h > kMaxTiffPixels)
    return make_error(name + ": TIFF size " + std::to_string(w) + "x" + std::to_string(h) + " is missing or too large");
  return Status::success();
}

Expected<cv::Mat> decode_tiff(std::string_view bytes, const std::string& name, bool srgb8, PhotoKind& kind) {
  if (Status s = check_tiff_size(bytes, name); !s) return s.error();
  auto decoded = imdecode_bytes(bytes, cv::IMREAD_UNCHANGED, name, " TIFF");
  if (!decoded) return decoded.error();
  const cv::Mat& raw = *decoded;
  if (raw.empty()) return make_error(name + ": corrupt, truncated or unsupported TIFF (decoder failed)");
  const int depth = raw.depth(), channels = raw.channels();
  if (depth != CV_8U && depth != CV_16U && depth != CV_32F)
    return make_error(name + ": TIFF sample type not supported (8-, 16-bit or float only)");
  if (channels != 1 && channels != 3 && channels != 4)
    return make_error(name + ": TIFF with " + std::to_string(channels) + " channels is not a photo");
  auto out = to_linear_bgr(raw, name);
  if (!out) return out;
  const bool eight = depth == CV_8U;
  kind = {"tiff", eight ? 8 : 16};
  if (eight && srgb8) srgb_to_linear_inplace(*out);
  return out;
}

}  // namespace

void srgb_to_linear_inplace(cv::Mat& image) {
  const auto& lut = srgb_to_linear_lut();
  CV_Assert(image.depth() == CV_32F);
  for (int y = 0; y < image.rows; ++y) {
    float* p = image.ptr<float>(y);
    for (int x = 0; x < image.cols * image.channels(); ++x) {
      const long code = std::lround(std::min(1.0f, std::max(0.0f, p[x])) * 255.0f);
      p[x] = lut[static_cast<size_t>(code)];
    }
  }
}

namespace {
Expected<cv::Mat> decode_photo_float(std::string_view bytes, const Frame& frame, PhotoKind& kind) {
  const std::string name = frame.file.string();
  if (has_tiff_magic(bytes)) return decode_tiff(bytes, name, frame.srgb8, kind);
  auto image = decode_linear_image(bytes, name);
  if (!image) return image;
  kind = {image_file_kind(bytes), 8};
  if (kind.kind == "png") kind.bits = png_bit_depth(bytes);
  if (kind.kind == "pfm") kind.bits = 32;
  if (kind.kind == "png" && kind.bits <= 8 && frame.srgb8) srgb_to_linear_inplace(*image);
  return image;
}
}  // namespace

Expected<cv::Mat> decode_photo(std::string_view bytes, const Frame& frame, const RawOptions& raw_options, bool half,
                               PhotoKind& kind) {
  if (frame.raw) {
    kind = {raw_options.half_size ? "raw-half" : "raw", 16};
    RawOptions options = raw_options;
    options.half_floats = half;
    auto photo = decode_raw(bytes, options, frame.file.string());
    if (!photo) return photo.error();
    kind.camera_to_srgb = photo->camera_to_srgb;
    return std::move(photo->image);
  }
  auto image = decode_photo_float(bytes, frame, kind);
  if (image && half) image->convertTo(*image, CV_MAKETYPE(CV_16F, image->channels()));
  return image;
}

std::string describe_photos(const PhotoKind& photo, bool srgb8, const RawOptions& raw_options) {
  const std::string& kind = photo.kind;
  if (kind == "raw" || kind == "raw-half")
    return "camera RAW through LibRaw " + raw_decoder_version() + " (" + (raw_options.half_size ? "half size" : "full size, ") +
           (raw_options.half_size ? "" : demosaic_name(raw_options.demosaic) + std::string(" demosaic")) +
           "; black level subtracted, as-shot white balance, " +
           (raw_options.camera_space ? "the camera's primaries (its colour matrix kept aside)" : "linear sRGB primaries") +
           ", gamma 1)";
  if (kind == "jpeg") return "8-bit JPEG, sRGB: linearised through the inverse sRGB curve";
  if ((kind == "png" || kind == "tiff") && photo.bits <= 8) {
    const std::string what = kind == "png" ? "8-bit PNG" : "8-bit TIFF";
    return srgb8 ? what + ", sRGB: linearised through the inverse sRGB curve"
                 : what + ", taken as linear (the layout's convention; no curve applied)";
  }
  if (kind == "png") return "16-bit PNG, linear";
  if (kind == "tiff") return "16-bit or float TIFF, linear";
  if (kind == "pfm") return "PFM, linear float";
  if (kind == "pnm") return "PPM/PGM, taken as linear";
  if (kind == "mixed") return "mixed file kinds (each read by its own kind)";
  return kind;
}

}  // namespace veneer::io::detail
