// bench_ps: photometric-stereo speed on a 1024x680 set of 7 lamps against a
// straightforward per-pixel cv::solve loop measured in the same run, set
// loading time, and the angular-error table of every simulated scene.
#include <algorithm>
#include <chrono>
#include <ctime>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <tbb/info.h>
#include <unistd.h>

#include "synth.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/ps/segmentation.hpp"
#include "veneer/sim/simulator.hpp"

namespace fs = std::filesystem;
using namespace veneer;
using Clock = std::chrono::steady_clock;

namespace {

double cpu_ms() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}

// Median wall-clock time of `runs` calls; *cpu gets the median process CPU
// time (all threads), which a loaded machine inflates much less.
template <class F>
double median_ms(int runs, F&& f, double* cpu = nullptr) {
  std::vector<double> t, c;
  for (int i = 0; i < runs; ++i) {
    const double c0 = cpu_ms();
    auto a = Clock::now();
    f();
    t.push_back(std::chrono::duration<double, std::milli>(Clock::now() - a).count());
    c.push_back(cpu_ms() - c0);
  }
  std::sort(t.begin(), t.end());
  std::sort(c.begin(), c.end());
  if (cpu) *cpu = c[c.size() / 2];
  return t[t.size() / 2];
}

std::string load_average() {
  std::FILE* f = std::fopen("/proc/loadavg", "r");
  if (!f) return "?";
  char buf[64] = {};
  const bool ok = std::fgets(buf, sizeof buf, f) != nullptr;
  std::fclose(f);
  if (!ok) return "?";
  std::string s(buf);
  return s.substr(0, s.find(' '));
}

// The straightforward way: for every object pixel, the n x 3 system solved by
// cv::solve (SVD), grey intensities, distant lights, no robustness.
cv::Mat solve_loop(const io::ImageSet& set, const cv::Mat& mask) {
  const int n = static_cast<int>(set.images.size());
  cv::Mat L(n, 3, CV_32F);
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) L.at<float>(i, c) = static_cast<float>(set.lights[i].direction[c]);
  cv::Mat normals(set.images[0].size(), CV_32FC3, cv::Scalar::all(0));
  cv::Mat b(n, 1, CV_32F), g;
  for (int y = 0; y < normals.rows; ++y)
    for (int x = 0; x < normals.cols; ++x) {
      if (!mask.at<uint8_t>(y, x)) continue;
      for (int i = 0; i < n; ++i) {
        const cv::Vec3f p = set.images[i].at<cv::Vec3f>(y, x);
        b.at<float>(i) = (p[0] + p[1] + p[2]) / 3.f;
      }
      cv::solve(L, b, g, cv::DECOMP_SVD);
      const float len = static_cast<float>(cv::norm(g));
      if (len > 0) normals.at<cv::Vec3f>(y, x) = cv::Vec3f(g.at<float>(0), g.at<float>(1), g.at<float>(2)) / len;
    }
  return normals;
}

}  // namespace

int main() {
  const cv::Size size(1024, 680);
  std::printf("# bench_ps — photometric stereo, %dx%d, 7 lamps, %d threads (load average %s)\n\n", size.width,
              size.height, tbb::info::default_concurrency(), load_average().c_str());

  // ---- speed ----
  sim::RenderOptions ro;
  ro.size = size;
  ro.noise_sigma = 0.005;
  auto sim_set = sim::simulate_set("sphere-gray", ro);
  if (!sim_set) {
    std::fprintf(stderr, "bench_ps: simulate sphere-gray: %s\n", sim_set.message().c_str());
    return 1;
  }
  io::ImageSet& set = *sim_set;
  const cv::Mat full(size, CV_8UC1, cv::Scalar(255));
  auto seg = ps::segment(set, {});
  const cv::Mat object = seg ? seg->mask : set.truth.mask;

  // A frame filled by the object: the analytic sphere, large, lamp positions known.
  ps::test::SynthOptions so;
  so.size = size;
  so.radius = 0.25;
  so.focal_scale = 1.0;
  io::ImageSet big = ps::test::synth_sphere(so);
  const cv::Mat big_mask = big.truth.mask;

  ps::PsOptions distant, distant_robust, near_robust;
  distant.light_model = ps::LightModel::distant;
  distant.robust = false;
  distant_robust.light_model = ps::LightModel::distant;
  near_robust.light_model = ps::LightModel::near;
  distant_robust.outlier_fraction = near_robust.outlier_fraction = 0;  // the default; the outlier pass has a column of its own

  struct Row {
    std::string what;
    const io::ImageSet* s;
    cv::Mat mask;
    int pixels;
  };
  std::vector<Row> rows = {
      {"sphere-gray, segmented object", &set, object, cv::countNonZero(object)},
      {"sphere filling the frame", &big, big_mask, cv::countNonZero(big_mask)},
      {"every pixel of the frame", &set, full, int(full.total())},
  };
  std::printf("## Speed (median of 15 runs; wall ms, with process CPU ms over all threads in brackets)\n\n");
  std::printf("Output buffers reused between runs; the \"fresh\" column allocates a new result each call.\n\n");
  std::printf("| input | pixels | distant | distant robust | robust + near | robust + near, fresh | cv::solve loop | loop / distant | loop / robust+near |\n");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const Row& r : rows) {
    ps::PsResult reused;  // output buffers reused between runs, as a live viewer would
    auto run = [&](const ps::PsOptions& o, double* cpu) {
      return median_ms(
          15,
          [&] {
            if (Status st = ps::photometric_stereo_into(*r.s, r.mask, o, {}, reused); !st)
              std::fprintf(stderr, "bench_ps: %s\n", st.message().c_str());
          },
          cpu);
    };
    double cd = 0, cdr = 0, cn = 0, cl = 0;
    const double td = run(distant, &cd), tdr = run(distant_robust, &cdr), tn = run(near_robust, &cn);
    const double tl = median_ms(1, [&] { solve_loop(*r.s, r.mask); }, &cl);
    double cfresh = 0;
    const double tfresh = median_ms(
        15, [&] { (void)ps::photometric_stereo(*r.s, r.mask, near_robust); }, &cfresh);
    std::printf("| %s | %d | %.2f (%.1f) | %.2f (%.1f) | %.2f (%.1f) | %.2f (%.1f) | %.0f (%.0f) | %.0fx | %.0fx |\n",
                r.what.c_str(), r.pixels, td, cd, tdr, cdr, tn, cn, tfresh, cfresh, tl, cl, tl / td, tl / tn);
    std::fflush(stdout);
  }
  const double tseg = median_ms(9, [&] {
    ps::SegmentOptions o;
    o.method = ps::SegmentMethod::otsu;
    (void)ps::segment(set, o);
  });
  std::printf("\nSegmentation (Otsu + cleaning), whole frame: %.2f ms\n", tseg);

  // ---- set loading ----
  const fs::path tmp = fs::temp_directory_path() / ("veneer-bench-ps-" + std::to_string(::getpid()));
  fs::remove_all(tmp);
  if (Status st = io::write_set(set, tmp / "set"); !st) {
    std::fprintf(stderr, "bench_ps: write_set: %s\n", st.message().c_str());
  } else {
    io::ReadOptions rd;
    rd.load_truth = false;
    const double tload = median_ms(5, [&] { (void)io::read_set(tmp / "set", rd); });
    std::printf("Loading the set (7 lamp PNGs + ambient, 16-bit, %dx%d): %.1f ms\n", size.width, size.height, tload);
  }
  fs::remove_all(tmp);

  // ---- quality per scene ----
  std::printf("\n## Angular error vs truth, %dx%d, noise 0.005 (degrees, mean / 95th percentile)\n\n", size.width,
              size.height);
  std::printf("| scene | pixels | distant LS | distant robust | robust + near | robust + near + outliers 0.1 | the same on "
              "grey only (diffuse chroma off) | near, unreliable %% |\n");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|\n");
  auto row_for = [&](const std::string& name, const sim::RenderOptions& o) {
    auto s = sim::simulate_set(name, o);
    if (!s) {
      std::printf("| %s | failed: %s | | | | | |\n", name.c_str(), s.message().c_str());
      return;
    }
    const cv::Mat m = s->truth.mask;
    auto err = [&](const ps::PsOptions& po, double* unreliable = nullptr) {
      auto r = ps::photometric_stereo(*s, m, po);
      if (!r) return std::string("error");
      if (unreliable) *unreliable = 100.0 * r->unreliable_pixels / std::max(1, r->solved_pixels);
      auto e = ps::angular_error(r->normals, s->truth.normals, m);
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.2f / %.2f", e.mean_deg, e.p95_deg);
      return std::string(buf);
    };
    double unrel = 0;
    ps::PsOptions near_outliers = near_robust;
    near_outliers.outlier_fraction = 0.1f;
    ps::PsOptions grey = near_outliers;  // the default before the off-grey solve (photometric_stereo.hpp)
    grey.diffuse_chroma = 0.f;
    const std::string a = err(distant), b = err(distant_robust), c = err(near_robust, &unrel), d = err(near_outliers),
                      g = err(grey);
    std::printf("| %s | %d | %s | %s | %s | %s | %s | %.1f |\n", name.c_str(), cv::countNonZero(m), a.c_str(),
                b.c_str(), c.c_str(), d.c_str(), g.c_str(), unrel);
    std::fflush(stdout);
  };
  for (const std::string& name : sim::scene_names()) row_for(name, ro);
  for (double off : {0.05, 0.10, 0.15}) {
    sim::RenderOptions o = ro;
    o.offset_m = cv::Vec3d(off, 0, 0);
    std::printf("| *sphere-gray %.0f cm off-centre* ", off * 100);
    auto s = sim::simulate_set("sphere-gray", o);
    if (!s) continue;
    const cv::Mat m = s->truth.mask;
    std::string cells[3];
    const ps::PsOptions* opts[3] = {&distant, &distant_robust, &near_robust};
    for (int k = 0; k < 3; ++k) {
      auto r = ps::photometric_stereo(*s, m, *opts[k]);
      auto e = r ? ps::angular_error(r->normals, s->truth.normals, m) : ps::AngularError{};
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.2f / %.2f", e.mean_deg, e.p95_deg);
      cells[k] = buf;
    }
    std::printf("| %d | %s | %s | %s | | | |\n", cv::countNonZero(m), cells[0].c_str(), cells[1].c_str(), cells[2].c_str());
  }
  return 0;
}
