// The scene simulator as the PTP/IP twin's shot and preview source: each shot
// renders the simulated camera's scene and encodes it as a camera's JPEG.
#include <algorithm>
#include <cmath>

#include <opencv2/imgcodecs.hpp>

#include "veneerd/sim/ptpip_twin.hpp"
#include "veneerd/sim/simulated_camera.hpp"

namespace veneerd {


PtpipShotSource simulated_shot_source(std::shared_ptr<SimulatedCamera> camera, int quality) {
  quality = std::clamp(quality, 1, 100);
  return [camera, quality](const PtpipExposure& e, uint64_t) -> veneer::Expected<std::vector<unsigned char>> {
    if (auto s = camera->set_exposure({e.shutter_s(), e.aperture(), e.iso}); !s) return s.error();
    auto still = camera->capture();
    if (!still) return still.error();
    // Linear float BGR -> 8-bit sRGB, as a camera's JPEG engine delivers it.
    static const std::vector<uint8_t> lut = [] {
      std::vector<uint8_t> t(4096);
      for (int i = 0; i < 4096; ++i) {
        double v = i / 4095.0;
        double s = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
        t[i] = uint8_t(std::lround(255.0 * s));
      }
      return t;
    }();
    cv::Mat linear = still->linear;
    if (linear.type() != CV_32FC3) linear.convertTo(linear, CV_32FC3);
    cv::Mat bgr8(linear.size(), CV_8UC3);
    for (int y = 0; y < linear.rows; ++y) {
      const auto* in = linear.ptr<cv::Vec3f>(y);
      auto* out = bgr8.ptr<cv::Vec3b>(y);
      for (int x = 0; x < linear.cols; ++x)
        for (int ch = 0; ch < 3; ++ch) out[x][ch] = lut[size_t(std::clamp(in[x][ch], 0.0f, 1.0f) * 4095.0f + 0.5f)];
    }
    std::vector<unsigned char> jpeg;
    if (!cv::imencode(".jpg", bgr8, jpeg, {cv::IMWRITE_JPEG_QUALITY, quality}))
      return veneer::make_error("PTP/IP twin: JPEG encoding of the simulated shot failed");
    return jpeg;
  };
}

PtpipPreviewSource simulated_preview_source(std::shared_ptr<SimulatedCamera> camera) {
  return [camera](const PtpipExposure&) { return camera->preview(); };
}

}  // namespace veneerd
