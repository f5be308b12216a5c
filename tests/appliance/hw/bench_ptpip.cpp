// bench_ptpip: what the gphoto2 back-end costs per shot when it drives the real
// libgphoto2 over PTP/IP (loopback) against the PTP/IP camera twin. The twin
// serves a prepared 1024x680 JPEG (a simulator render), so the time of a
// capture() is libgphoto2 + PTP/IP + our JPEG decoding, nothing of a camera.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "veneer/sim/simulator.hpp"
#include "veneer/util/log.hpp"
#include "veneerd/sim/ptpip_twin.hpp"
#include "veneerd/hw/gphoto2.hpp"

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

static double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

static double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

static double mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0 : s / v.size();
}

int main() {
  veneer::log::set_levels("warn");
  const char* iolibs = std::getenv("IOLIBS");
  fs::path driver = fs::path(iolibs && *iolibs ? iolibs : VENEER_GPHOTO2_IOLIBS) / "ptpip.so";
  if (!fs::exists(driver)) {
    std::printf("bench_ptpip: skipped, libgphoto2's PTP/IP port driver is not installed (%s)\n", driver.c_str());
    return 0;
  }
  // libgphoto2 writes its PTP/IP GUID under $HOME/.gphoto: keep it out of the user's.
  fs::path home = fs::temp_directory_path() / ("veneer-bench-ptpip-" + std::to_string(::getpid()));
  fs::create_directories(home);
  ::setenv("HOME", home.c_str(), 1);

  // One simulator render, sRGB-encoded, as the body's JPEG.
  const cv::Size size(1024, 680);
  veneer::sim::RenderOptions ro;
  ro.size = size;
  ro.focal_px = 2.0 * size.width;
  ro.noise_sigma = 0.002;
  auto scene = veneer::sim::make_scene("bull", ro);
  if (!scene) {
    std::fprintf(stderr, "bench_ptpip: %s\n", scene.message().c_str());
    return 1;
  }
  cv::Mat linear = veneer::sim::render(**scene, {veneer::sim::thesis_rig()[0]}, ro);
  cv::Mat bgr8(linear.size(), CV_8UC3);
  for (int y = 0; y < linear.rows; ++y)
    for (int x = 0; x < linear.cols; ++x)
      for (int c = 0; c < 3; ++c) {
        double v = std::clamp(double(linear.at<cv::Vec3f>(y, x)[c]), 0.0, 1.0);
        double s = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
        bgr8.at<cv::Vec3b>(y, x)[c] = uint8_t(std::lround(255 * s));
      }
  std::vector<unsigned char> jpeg;
  cv::imencode(".jpg", bgr8, jpeg, {cv::IMWRITE_JPEG_QUALITY, 95});

  veneerd::PtpipTwinOptions to;
  to.shot = [&](const veneerd::PtpipExposure&, uint64_t) -> veneer::Expected<std::vector<unsigned char>> { return jpeg; };
  to.preview = [&](const veneerd::PtpipExposure&) -> veneer::Expected<std::vector<unsigned char>> { return jpeg; };
  auto twin = veneerd::PtpipTwin::start(to);
  if (!twin) {
    std::fprintf(stderr, "bench_ptpip: %s\n", twin.message().c_str());
    return 1;
  }
  const int reopen_delay_ms = 100;
  auto opt = veneerd::hw::parse_gphoto2_options(
      {{"port", (*twin)->gphoto2_port()}, {"still_size", {size.width, size.height}}, {"reopen_delay_ms", reopen_delay_ms}},
      "camera");
  if (!opt) {
    std::fprintf(stderr, "bench_ptpip: %s\n", opt.message().c_str());
    return 1;
  }
  veneerd::hw::Gphoto2Camera camera(veneerd::hw::make_libgphoto2_api(), nullptr, *opt);

  auto t = Clock::now();
  if (auto s = camera.open(); !s) {
    std::fprintf(stderr, "bench_ptpip: %s\n", s.message().c_str());
    return 1;
  }
  double open_ms = ms_since(t);

  std::vector<double> exposure_ms;
  const veneerd::Exposure settings[] = {{1.0 / 60, 5.6, 200}, {1.0 / 30, 8, 100}};
  for (int i = 0; i < 6; ++i) {
    t = Clock::now();
    if (auto s = camera.set_exposure(settings[i % 2]); !s) {
      std::fprintf(stderr, "bench_ptpip: %s\n", s.message().c_str());
      return 1;
    }
    exposure_ms.push_back(ms_since(t));
  }

  const int warmup = 2, shots = 20;
  std::vector<double> capture_ms;
  for (int i = 0; i < warmup + shots; ++i) {
    t = Clock::now();
    auto still = camera.capture();
    double ms = ms_since(t);
    if (!still) {
      std::fprintf(stderr, "bench_ptpip: %s\n", still.message().c_str());
      return 1;
    }
    if (i >= warmup) capture_ms.push_back(ms);
  }
  std::vector<double> decode_ms;
  for (int i = 0; i < 10; ++i) {
    t = Clock::now();
    auto m = veneerd::hw::decode_jpeg_linear(jpeg, size);
    decode_ms.push_back(ms_since(t));
  }

  int frames = 0;
  t = Clock::now();
  while (ms_since(t) < 3000) {
    if (!camera.preview()) break;
    ++frames;
  }
  double fps = frames / (ms_since(t) / 1000);

  std::vector<double> reconnect_ms;
  for (int i = 0; i < 3; ++i) {
    (*twin)->drop_now();
    t = Clock::now();
    auto s = camera.set_exposure(settings[i % 2]);
    if (!s) {
      std::fprintf(stderr, "bench_ptpip: %s\n", s.message().c_str());
      return 1;
    }
    reconnect_ms.push_back(ms_since(t) - reopen_delay_ms);
  }

  std::printf("\n### gphoto2 back-end over PTP/IP (real libgphoto2 2.5.30, loopback, PTP/IP twin), %dx%d JPEG of %.0f KiB\n\n",
              size.width, size.height, jpeg.size() / 1024.0);
  std::printf("| measure | value |\n|---|---|\n");
  std::printf("| open: connect + session + device info + card listing (ms) | %.1f |\n", open_ms);
  std::printf("| set exposure, 3 properties (ms, median of %zu) | %.1f |\n", exposure_ms.size(), median(exposure_ms));
  std::printf("| **capture(): trigger + events + download + delete + decode, per shot (ms, median of %d)** | **%.1f** |\n",
              shots, median(capture_ms));
  std::printf("| capture() mean / worst (ms) | %.1f / %.1f |\n", mean(capture_ms),
              *std::max_element(capture_ms.begin(), capture_ms.end()));
  std::printf("| of which JPEG decode + linearise (ms, median) | %.1f |\n", median(decode_ms));
  std::printf("| **libgphoto2 + PTP/IP per shot, beyond decoding (ms)** | **%.1f** |\n",
              median(capture_ms) - median(decode_ms));
  std::printf("| live view through GetStream (frames/s, 3 s) | %.1f |\n", fps);
  std::printf("| reconnect after a dropped connection, beyond the %d ms wait (ms, median of 3) | %.1f |\n",
              reopen_delay_ms, median(reconnect_ms));
  twin->reset();
  fs::remove_all(home);
  return 0;
}
