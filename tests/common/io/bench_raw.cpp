// bench_raw: the RAW path on the rig twin's sets, per LibRaw interpolation:
// decode time per frame, how far the decoded photo is from the linear render
// (full RGB, over the object) and what photometric stereo makes of it (mean
// and p95 angle to the truth), next to photometric stereo on the render
// itself, measured in the same run. With the simulator's camera optics (the
// default) and with point sampling (the simulator before them).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/dng.hpp"
#include "veneer/io/raw.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/sim/simulator.hpp"

namespace {

using Clock = std::chrono::steady_clock;
using namespace veneer;

double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

struct AngleStats {
  double mean = 0, p95 = 0;
};

AngleStats angles_to_truth(const cv::Mat& normals, const io::Truth& truth) {
  std::vector<double> a;
  for (int y = 0; y < normals.rows; ++y)
    for (int x = 0; x < normals.cols; ++x) {
      if (!truth.mask.at<uchar>(y, x)) continue;
      const cv::Vec3f n = normals.at<cv::Vec3f>(y, x), t = truth.normals.at<cv::Vec3f>(y, x);
      const double d = std::clamp(static_cast<double>(n.dot(t)) / (cv::norm(n) * cv::norm(t) + 1e-12), -1.0, 1.0);
      a.push_back(std::acos(d) * 180.0 / CV_PI);
    }
  AngleStats s;
  if (a.empty()) return s;
  for (double v : a) s.mean += v;
  s.mean /= static_cast<double>(a.size());
  std::nth_element(a.begin(), a.begin() + static_cast<long>(0.95 * static_cast<double>(a.size() - 1)), a.end());
  s.p95 = a[static_cast<size_t>(0.95 * static_cast<double>(a.size() - 1))];
  return s;
}

AngleStats ps_error(const io::ImageSet& set) {
  auto ps = ps::photometric_stereo(set, set.truth.mask);
  if (!ps) {
    std::fprintf(stderr, "bench_raw: photometric stereo: %s\n", ps.message().c_str());
    return {180, 180};
  }
  return angles_to_truth(ps->normals, set.truth);
}

}  // namespace

int main() {
  std::printf("## RAW path on the rig twin's sets (1024x680, noise 0.002): decode, photo error, normals\n\n");
  std::printf("| optics | scene | photos from | decode ms/frame | full-RGB error vs render | PS mean deg | PS p95 deg |\n");
  std::printf("|---|---|---|---:|---:|---:|---:|\n");
  struct Optics {
    const char* name;
    int edge_samples;
    double olpf_spread_px;
  };
  const sim::RenderOptions camera = sim::RenderOptions().camera_optics();
  const Optics optics[] = {{"camera optics (the twin's)", camera.edge_samples, camera.olpf_spread_px},
                           {"point-sampled", 1, 0.0}};
  const std::vector<io::Demosaic> methods = {io::Demosaic::bilinear, io::Demosaic::vng, io::Demosaic::ppg, io::Demosaic::ahd,
                                         io::Demosaic::dcb,      io::Demosaic::dht, io::Demosaic::aahd, io::Demosaic::mhc};
  for (const auto& op : optics) {
    for (const std::string scene : {"orange", "bull"}) {
      sim::RenderOptions o;
      o.size = {1024, 680};
      o.noise_sigma = 0.002;  // the rig twin's
      o.seed = 1;
      o.edge_samples = op.edge_samples;
      o.olpf_spread_px = op.olpf_spread_px;
      auto t0 = Clock::now();
      auto set = sim::simulate_set(scene, o);
      const double render_ms = ms_since(t0);
      if (!set) {
        std::fprintf(stderr, "bench_raw: %s\n", set.message().c_str());
        return 1;
      }
      std::vector<std::string> dngs;
      for (const auto& img : set->images) {
        auto d = io::encode_dng(img);
        if (!d) {
          std::fprintf(stderr, "bench_raw: %s\n", d.message().c_str());
          return 1;
        }
        dngs.push_back(std::move(*d));
      }
      const AngleStats from_render = ps_error(*set);
      std::printf("| %s | %s | render (%.0f ms for the set) | - | - | %.2f | %.2f |\n", op.name, scene.c_str(), render_ms,
                  from_render.mean, from_render.p95);
      for (io::Demosaic m : methods) {
        io::RawOptions ro;
        ro.demosaic = m;
        io::ImageSet decoded = *set;
        double decode_ms = 0, worst_rgb = 0;
        for (size_t i = 0; i < dngs.size(); ++i) {
          auto t1 = Clock::now();
          auto img = io::decode_raw_linear(dngs[i], ro, "frame.dng");
          decode_ms += ms_since(t1);
          if (!img) {
            std::fprintf(stderr, "bench_raw: %s\n", img.message().c_str());
            return 1;
          }
          worst_rgb = std::max(worst_rgb, cv::norm(*img, set->images[i], cv::NORM_L1, set->truth.mask) /
                                              cv::norm(set->images[i], cv::NORM_L1, set->truth.mask));
          decoded.images[i] = std::move(*img);
        }
        const AngleStats s = ps_error(decoded);
        std::printf("| %s | %s | RAW, %s | %.1f | %.2f %% | %.2f | %.2f |\n", op.name, scene.c_str(), io::demosaic_name(m),
                    decode_ms / static_cast<double>(dngs.size()), 100 * worst_rgb, s.mean, s.p95);
        std::fflush(stdout);
      }
    }
  }
  std::printf("\nfull-RGB error: sum |decoded - render| / sum |render| over the object, the worst frame of the set.\n");
  return 0;
}
