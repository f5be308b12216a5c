// bench_camera_files: one frame of the rig's camera twin at a 24 Mpx body's
// sizes (5600x3750, 6000x4000; VENEER_BENCH_SIZES="WxH,..." to change),
// rendered as the twin renders it (bull, camera optics, sensor noise 0.002,
// one lamp), stored as the twin stores it now -- the developed JPEG (q95)
// and the lossless DNG with its 1/4 preview -- next to what it stored before
// (a 16-bit PNG and an uncompressed DNG), measured in the same run: bytes,
// encode time, and LibRaw's decode of both DNGs (equal values checked).
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/camera_files.hpp"
#include "veneer/io/dng.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/raw.hpp"
#include "veneer/sim/simulator.hpp"

namespace {

using Clock = std::chrono::steady_clock;
using namespace veneer;

double s_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
double mb(size_t bytes) { return static_cast<double>(bytes) / 1e6; }

}  // namespace

int main() {
  std::vector<cv::Size> sizes = {{5600, 3750}, {6000, 4000}};
  if (const char* env = std::getenv("VENEER_BENCH_SIZES"); env && *env) {
    sizes.clear();
    std::string list = env;
    for (size_t at = 0; at < list.size();) {
      const size_t comma = std::min(list.find(',', at), list.size());
      int w = 0, h = 0;
      if (std::sscanf(list.substr(at, comma - at).c_str(), "%dx%d", &w, &h) == 2 && w > 0 && h > 0) sizes.push_back({w, h});
      at = comma + 1;
    }
  }
  std::printf("\n### One frame of the camera twin: files now (JPEG + lossless DNG) against before (16-bit PNG + "
              "uncompressed DNG)\n\n");
  std::printf("| size | file | MB | encode s | LibRaw decode s (DCB) |\n|---|---|---|---|---|\n");
  for (cv::Size size : sizes) {
    sim::RenderOptions o;
    o.size = size;
    o.noise_sigma = 0.002;
    o.seed = 1;
    o.camera_optics();
    auto scene = sim::make_scene("bull", o);
    if (!scene) {
      std::fprintf(stderr, "bench_camera_files: %s\n", scene.message().c_str());
      return 1;
    }
    const sim::Lamp lamp = sim::thesis_rig()[2];
    auto t0 = Clock::now();
    const cv::Mat photo = sim::render(**scene, {lamp}, o);
    const double render_s = s_since(t0);
    const std::string name = std::to_string(size.width) + "x" + std::to_string(size.height);

    t0 = Clock::now();
    auto png = io::encode_png16(photo);
    const double png_s = s_since(t0);
    io::DngOptions before;
    before.compress = false;
    before.preview_divisor = 0;
    t0 = Clock::now();
    auto plain = io::encode_dng(photo, before);
    const double plain_s = s_since(t0);
    t0 = Clock::now();
    auto jpeg = io::encode_developed_jpeg(photo, io::CameraFileOptions{}.jpeg_quality);
    const double jpeg_s = s_since(t0);
    t0 = Clock::now();
    auto dng = io::encode_dng(photo, io::CameraFileOptions{}.dng);
    const double dng_s = s_since(t0);
    if (!png || !plain || !jpeg || !dng) {
      std::fprintf(stderr, "bench_camera_files: an encoder failed\n");
      return 1;
    }
    auto preview = io::find_dng_preview(*dng, dng->size(), "frame.dng");
    t0 = Clock::now();
    auto a = io::decode_raw_linear(*plain, {}, "plain.dng");
    const double plain_decode_s = s_since(t0);
    t0 = Clock::now();
    auto b = io::decode_raw_linear(*dng, {}, "lj92.dng");
    const double dng_decode_s = s_since(t0);
    const bool same = a && b && cv::norm(*a, *b, cv::NORM_INF) == 0;

    std::printf("| %s | before: 16-bit PNG | %.1f | %.2f | |\n", name.c_str(), mb(png->size()), png_s);
    std::printf("| %s | before: uncompressed DNG | %.1f | %.2f | %.2f |\n", name.c_str(), mb(plain->size()), plain_s,
                plain_decode_s);
    std::printf("| %s | **now: developed JPEG (q95)** | **%.1f** | %.2f | |\n", name.c_str(), mb(jpeg->size()), jpeg_s);
    std::printf("| %s | **now: lossless DNG + %dx%d preview (%.2f MB)** | **%.1f** | %.2f | %.2f (%s) |\n", name.c_str(),
                preview ? preview->size.width : 0, preview ? preview->size.height : 0,
                preview ? mb(preview->length) : 0.0, mb(dng->size()), dng_s, dng_decode_s,
                same ? "the same values" : "DIFFERENT VALUES");
    std::printf("| %s | per frame before -> now | %.1f -> %.1f | | (render %.1f s) |\n", name.c_str(),
                mb(png->size() + plain->size()), mb(jpeg->size() + dng->size()), render_s);
  }
  return 0;
}
