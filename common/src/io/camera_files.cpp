// A camera's files for a linear photo (camera_files.hpp).
#include "veneer/io/camera_files.hpp"

#include <array>
#include <cmath>
#include <vector>

#include <opencv2/core/utility.hpp>
#include "veneer/io/codecs.hpp"
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include "set_detail.hpp"

namespace veneer::io {

namespace {

// Linear [0, 1] quantised to 1/65535 -> sRGB 8-bit code value (IEC 61966-2-1).
const std::vector<uint8_t>& srgb_lut() {
  static const std::vector<uint8_t> lut = [] {
    std::vector<uint8_t> t(65536);
    for (int i = 0; i < 65536; ++i) {
      const double v = i / 65535.0;
      const double s = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
      t[static_cast<size_t>(i)] = static_cast<uint8_t>(std::lround(std::clamp(s, 0.0, 1.0) * 255.0));
    }
    return t;
  }();
  return lut;
}

}  // namespace

cv::Mat develop_srgb8(const cv::Mat& linear) {
  CV_Assert(linear.type() == CV_32FC3);
  const std::vector<uint8_t>& lut = srgb_lut();
  cv::Mat out(linear.size(), CV_8UC3);
  cv::parallel_for_(cv::Range(0, linear.rows), [&](const cv::Range& r) {
    for (int y = r.start; y < r.end; ++y) {
      const float* s = linear.ptr<float>(y);
      uint8_t* d = out.ptr<uint8_t>(y);
      for (int x = 0; x < linear.cols * 3; ++x) {
        const float v = s[x];
        const float c = v > 0.0f ? (v < 1.0f ? v : 1.0f) : 0.0f;  // NaN -> 0
        d[x] = lut[static_cast<size_t>(c * 65535.0f + 0.5f)];
      }
    }
  });
  return out;
}

Expected<std::string> encode_developed_jpeg(const cv::Mat& linear, int quality) {
  if (linear.type() != CV_32FC3 || linear.empty()) return make_error("JPEG: the photo must be a non-empty CV_32FC3");
  if (quality < 1 || quality > 100) return make_error("JPEG quality must be in 1..100");
  std::vector<uchar> bytes;
  try {
    if (!veneer::io::codecs::imencode(".jpg", develop_srgb8(linear), bytes, {cv::IMWRITE_JPEG_QUALITY, quality}))
      return make_error("JPEG: the encoder failed");
  } catch (const cv::Exception& e) {
    return make_error(std::string("JPEG: ") + e.what());
  }
  return std::string(bytes.begin(), bytes.end());
}

Status CameraFileOptions::check() const {
  if (jpeg_quality < 1 || jpeg_quality > 100) return make_error("JPEG quality must be in 1..100");
  return raw ? dng.check() : Status::success();
}

Expected<CameraFiles> encode_camera_files(const cv::Mat& linear, const CameraFileOptions& o) {
  if (Status s = o.check(); !s) return s.error();
  Expected<std::string> jpeg = make_error("not encoded"), dng = std::string();
  tbb::parallel_invoke([&] { jpeg = encode_developed_jpeg(linear, o.jpeg_quality); },
                       [&] {
                         if (o.raw) dng = encode_dng(linear, o.dng);
                       });
  if (!jpeg) return jpeg.error();
  if (!dng) return dng.error();
  CameraFiles files;
  files.developed = {"jpg", std::move(jpeg).value()};
  if (o.raw) files.raw = {"dng", std::move(dng).value()};
  return files;
}

Status add_camera_files(ImageSet& set, const CameraFileOptions& options) {
  if (Status s = options.check(); !s) return s;
  auto encoded = detail::encode_frames<CameraFiles>(
      set, [&](const cv::Mat& photo) { return encode_camera_files(photo, options); });
  if (!encoded) return encoded.error();
  set.developed.clear();
  set.raw.clear();
  for (size_t i = 0; i < set.images.size(); ++i) {
    set.developed.push_back(std::move((*encoded)[i].developed));
    set.raw.push_back(std::move((*encoded)[i].raw));
  }
  if (!set.ambient.empty()) {
    set.ambient_developed = std::move(encoded->back().developed);
    set.ambient_raw = std::move(encoded->back().raw);
  }
  return Status::success();
}

}  // namespace veneer::io
