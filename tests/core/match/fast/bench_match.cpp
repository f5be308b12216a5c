// bench_match: the thesis's tables 5.1-5.3 re-measured for the fast engine,
// against the faithful FLANN peer (4 randomized kd-trees, 32 checks, one
// thread, as the thesis ran it) measured in the same run on the same features.
//
// Objects: a destination and a source at 1024x680, one thesis-sized (~21 000
// object pixels) and one full-frame (~150 000): the simulator's orange onto
// its bull (truth normals, photos under the thesis's 7-lamp ring), or, when
// the simulator cannot make them, synthetic shapes with known normals (a
// bumpy ellipsoid onto a bumpy sphere). At full frame the indices are also
// timed on a source of few orientations (boxes, normals with noise).
//
// Usage: bench_match [--quick] [--pictures DIR] [--only STEP [--runs N]]
//   --only: time one row (for profiling) and print its map's quality
//   --quick: 1 run per row, small object only; --pictures: PNGs of the maps
//   (thesis colouring) beside the destination repainted with the source's photo.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cctype>
#include <cstring>
#include <ctime>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/eval/metrics.hpp"
#include "veneer/match/fast.hpp"
#include "veneer/match/features.hpp"
#include "veneer/match/index.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/sim/simulator.hpp"

using namespace veneer::match;
using veneer::eval::evaluate;
using veneer::eval::Quality;

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }
// CPU time of this thread / of the process, in ms: unlike wall time it does
// not grow when other programs share the cores.
double thread_cpu_ms() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}
double process_cpu_ms() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

// An ellipsoid (semi-axes a, b px; depth c) with bumps of amplitude `bump`
// and wavelength ~ `wave` px, centred in a 1024x680 frame, plus its photos.
ObjectView shape(double a, double b, double bump, double wave, unsigned seed) {
  const cv::Size size(1024, 680);
  ObjectView v;
  v.normals = cv::Mat(size, CV_32FC3, cv::Scalar::all(0));
  v.mask = cv::Mat(size, CV_8UC1, cv::Scalar(0));
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> ph(0, 6.283);
  const double p1 = ph(rng), p2 = ph(rng);
  const double cx = 512, cy = 340, c = 0.8 * std::min(a, b);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) {
      const double u = (x - cx) / a, w = -(y - cy) / b;
      const double r2 = u * u + w * w;
      if (r2 >= 0.985) continue;
      const double z = std::sqrt(1 - r2);
      // gradient of the implicit ellipsoid, then a bump field
      double n[3] = {u / a, w / b, z / c};
      const double l0 = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      for (double& e : n) e /= l0;
      n[0] += bump * std::sin(x / wave + p1) * std::cos(y / (1.3 * wave) + p2);
      n[1] += bump * std::cos(x / (0.8 * wave) + p2) * std::sin(y / wave + p1);
      const double l = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
      v.normals.at<cv::Vec3f>(y, x) = cv::Vec3f(n[0] / l, n[1] / l, n[2] / l);
      v.mask.at<uchar>(y, x) = 255;
    }
  for (int lamp = 0; lamp < 7; ++lamp) {
    const double ang = 6.2832 * (lamp + (lamp >= 6 ? 1 : 0)) / 8 + 1.5708;
    cv::Vec3f L(static_cast<float>(0.47 * std::cos(ang)), static_cast<float>(0.47 * std::sin(ang)), 1.0f);
    L /= static_cast<float>(cv::norm(L));
    cv::Mat im(size, CV_32FC3, cv::Scalar::all(0));
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) {
        if (!v.mask.at<uchar>(y, x)) continue;
        const float s = std::max(0.0f, v.normals.at<cv::Vec3f>(y, x).dot(L));
        const float albedo = 0.55f + 0.3f * static_cast<float>(std::sin(0.05 * x) * std::cos(0.07 * y));
        im.at<cv::Vec3f>(y, x) = cv::Vec3f(0.7f, 0.9f, 1.0f) * (albedo * s);
      }
    v.images.push_back(im);
  }
  return v;
}

// A simulated scene's truth (normals, mask) and its photos under the thesis
// rig, scaled so the object covers about `target` pixels.
bool sim_object(const std::string& scene, int target, ObjectView& v, int& got) {
  namespace sim = veneer::sim;
  sim::RenderOptions ro;
  ro.size = cv::Size(1024, 680);
  // The scale that gives the target pixel count (within 2 %): the area does
  // not grow exactly with the square of the scale (perspective, the frame's
  // edge), so the first guess is corrected a few times.
  for (int pass = 0;; ++pass) {
    auto sc = sim::make_scene(scene, ro);
    if (!sc) return false;
    veneer::io::Truth t = sim::render_truth(**sc, ro);
    got = cv::countNonZero(t.mask);
    if (got == 0) return false;
    if (std::abs(got - target) <= target / 50 || pass == 5) {  // close enough, or the last try
      v.normals = t.normals;
      v.mask = t.mask;
      v.images.clear();
      for (const sim::Lamp& lamp : sim::thesis_rig()) v.images.push_back(sim::render(**sc, {lamp}, ro));
      return true;
    }
    ro.scale *= std::sqrt(static_cast<double>(target) / got);
  }
}

// The normals of an object's pixels, row by row.
std::vector<float> normals_of(const ObjectView& o) {
  std::vector<float> v;
  for (int y = 0; y < o.mask.rows; ++y)
    for (int x = 0; x < o.mask.cols; ++x)
      if (o.mask.at<uchar>(y, x)) {
        const cv::Vec3f n = o.normals.at<cv::Vec3f>(y, x);
        v.insert(v.end(), {n[0], n[1], n[2]});
      }
  return v;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// FLANN over the same feature vectors, single-threaded: build + all queries.
double flann_ms(const ObjectView& dst, const ObjectView& src, Feature f, int patch, int k) {
  const double t0 = thread_cpu_ms();
  auto d = make_features(dst, f, patch);
  auto s = make_features(src, f, patch);
  if (!d || !s) return -1;
  auto index = make_index("flann");
  if (!index) return -1;
  index->build(s->data.data(), s->rows(), s->dims);
  std::vector<int> ids(k);
  std::vector<float> sq(k);
  for (int i = 0; i < d->rows(); ++i) index->knn(d->row(i), k, ids.data(), sq.data());
  return thread_cpu_ms() - t0;
}

struct Row {
  std::string step;
  MatchOptions options;
  int flann_patch;
  Feature flann_feature;
  int flann_k;
  double thesis_s;  // the thesis's time at ~21k px (single core, i7-2600K), 0 = none
  double target_small_ms, target_large_ms;
};

std::string fmt(double v, int prec = 1) {
  if (v < 0) return "—";
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", prec, v);
  return b;
}

int count(const cv::Mat& m) { return cv::countNonZero(m); }

}  // namespace

// The destination repainted with the source's photo through the map (lamp
// `lamp`), beside the thesis's picture of the map (R = x / w, G = y / h, B = 1).
void write_pictures(const std::string& dir, const std::string& name, const Map& m, const ObjectView& dst,
                    const ObjectView& src) {
  cv::Mat repaint(dst.mask.size(), CV_8UC3, cv::Scalar::all(0)), picture(dst.mask.size(), CV_8UC3, cv::Scalar::all(0));
  const cv::Mat& photo = src.images.empty() ? cv::Mat() : src.images[0];
  double peak = 0;
  if (!photo.empty()) cv::minMaxLoc(photo.reshape(1), nullptr, &peak);
  for (int y = 0; y < dst.mask.rows; ++y)
    for (int x = 0; x < dst.mask.cols; ++x) {
      if (!dst.mask.at<uchar>(y, x) || !m.valid(x, y)) continue;
      const cv::Vec2f q = m.xy.at<cv::Vec2f>(y, x);
      picture.at<cv::Vec3b>(y, x) = cv::Vec3b(255, cv::saturate_cast<uchar>(255 * q[1] / src.mask.rows),
                                              cv::saturate_cast<uchar>(255 * q[0] / src.mask.cols));
      if (!photo.empty()) {
        const cv::Vec3f c = photo.at<cv::Vec3f>(static_cast<int>(q[1]), static_cast<int>(q[0]));
        for (int k = 0; k < 3; ++k)
          repaint.at<cv::Vec3b>(y, x)[k] = cv::saturate_cast<uchar>(255 * std::pow(c[k] / std::max(1e-6, peak), 1 / 2.2));
      }
    }
  // cropped to the destination object (with a margin), scaled up to be seen
  std::vector<cv::Point> pts;
  cv::findNonZero(dst.mask, pts);
  const cv::Rect box = (cv::boundingRect(pts) + cv::Size(20, 20) - cv::Point(10, 10)) & cv::Rect(cv::Point(0, 0), dst.mask.size());
  cv::Mat both;
  cv::hconcat(picture(box), repaint(box), both);
  if (both.rows < 400) cv::resize(both, both, cv::Size(), 2.0, 2.0, cv::INTER_NEAREST);
  cv::imwrite(dir + "/" + name + ".png", both);
}

// Build, all k = 1 queries and all lists of `list` of each index kind over
// the source normals sp for the destination normals dp, one thread, CPU
// time: the median of `runs` (FLANN's peer: one run), as a table row each.
void index_table(const char* what, const std::vector<float>& sp, const std::vector<float>& dp, int list, int runs) {
  std::printf("| %s, one thread, CPU time | build (ms) | all queries, k=1 (ms) | ns / query | all queries, k=%d (ms) "
              "|\n|---|---|---|---|---|\n",
              what, list);
  for (const char* kind : {"grid", "lookup", "kdtree", "flann"}) {
    std::vector<double> tb, tq, tk;
    for (int i = 0; i < (std::strcmp(kind, "flann") == 0 ? 1 : runs); ++i) {
      auto index = std::strcmp(kind, "flann") == 0 ? make_index("flann") : fast::make_index(kind);
      double t0 = thread_cpu_ms();
      index->build(sp.data(), static_cast<int>(sp.size() / 3), 3);
      tb.push_back(thread_cpu_ms() - t0);
      int id;
      float d;
      t0 = thread_cpu_ms();
      for (size_t q = 0; q < dp.size(); q += 3) index->knn(&dp[q], 1, &id, &d);
      tq.push_back(thread_cpu_ms() - t0);
      std::vector<int> ids(list);
      std::vector<float> ds(list);
      t0 = thread_cpu_ms();
      for (size_t q = 0; q < dp.size(); q += 3) index->knn(&dp[q], list, ids.data(), ds.data());
      tk.push_back(thread_cpu_ms() - t0);
    }
    std::printf("| %s | %s | %s | %s | %s |\n", kind, fmt(median(tb), 2).c_str(), fmt(median(tq), 2).c_str(),
                fmt(1e6 * median(tq) / (dp.size() / 3), 0).c_str(), fmt(median(tk), 1).c_str());
  }
  std::printf("\n");
}

// The indices on a source of few orientations: the simulator's blocks (the
// faces of boxes), their normals with photometric-stereo-like noise, against
// the bull's normals (most far from every cluster). One run each; lists of
// 16 are the longest the grid serves.
void box_source_table(const std::vector<float>& dp) {
  ObjectView blocks;
  int got = 0;
  if (!sim_object("blocks", 150000, blocks, got)) return;
  std::vector<float> sp = normals_of(blocks);
  std::mt19937 rng(5);
  std::normal_distribution<float> noise(0.0f, 0.005f);
  for (size_t i = 0; i < sp.size(); i += 3) {
    float* n = &sp[i];
    for (int c = 0; c < 3; ++c) n[c] += noise(rng);
    const float l = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int c = 0; c < 3; ++c) n[c] /= l;
  }
  std::printf("Source of few orientations: bull (%zu px) <- blocks (%d px), normals + noise sd 0.005.\n\n", dp.size() / 3, got);
  index_table("nearest-normal index, box-like source", sp, dp, 16, 1);
}

int main(int argc, char** argv) {
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  std::string pictures;  // --pictures DIR: also write what the maps look like
  for (int i = 1; i + 1 < argc; ++i)
    if (std::strcmp(argv[i], "--pictures") == 0) pictures = argv[i + 1];
  std::string only;  // --only STEP: time one row (for profiling), skip the other tables
  for (int i = 1; i + 1 < argc; ++i)
    if (std::strcmp(argv[i], "--only") == 0) only = argv[i + 1];
  int runs = quick ? 1 : 5;
  for (int i = 1; i + 1 < argc; ++i)  // --runs N: more runs per row (for profiling with --only)
    if (std::strcmp(argv[i], "--runs") == 0) runs = std::max(1, std::atoi(argv[i + 1]));
  struct Pair {
    std::string name;
    ObjectView dst, src;
    bool large;
  };
  std::vector<Pair> pairs;
  // ~21 000 px: the thesis's object size; ~150 000 px: most of the frame.
  // The simulator's orange -> bull (truth normals and masks, rendered photos);
  // synthetic shapes when the simulator cannot make them.
  std::string source_of_objects = "simulated orange (source) -> bull (destination), truth normals and masks";
  for (const int target : {21000, 150000}) {
    if (quick && target > 21000) break;
    const bool large = target > 21000;
    Pair pr{large ? "~150k px" : "~21k px", {}, {}, large};
    int nd = 0, ns = 0;
    if (!sim_object("bull", target, pr.dst, nd) || !sim_object("orange", target, pr.src, ns)) {
      source_of_objects = "synthetic bumpy ellipsoid -> bumpy sphere";
      pr.dst = large ? shape(245, 195, 0.10, 9, 3) : shape(92, 73, 0.10, 6, 1);
      pr.src = large ? shape(218, 218, 0.10, 8, 4) : shape(82, 82, 0.10, 5, 2);
    }
    pairs.push_back(std::move(pr));
  }

  auto opt = [](Method m, Feature f, int patch) {
    MatchOptions o;
    o.method = m;
    o.feature = f;
    o.patch = patch;
    o.fast = true;
    if (m == Method::candidates) o.candidates = 100;
    if (m == Method::patchmatch) o.iterations = 5;
    return o;
  };
  const std::vector<Row> rows = {
      {"normals 1x1", opt(Method::flann, Feature::normals, 1), 1, Feature::normals, 1, 0.68, 2, 10},
      {"normals 3x3", opt(Method::flann, Feature::normals, 3), 3, Feature::normals, 1, 0, 0, 0},
      {"normals 5x5", opt(Method::flann, Feature::normals, 5), 5, Feature::normals, 1, 0, 0, 0},
      {"normals 7x7", opt(Method::flann, Feature::normals, 7), 7, Feature::normals, 1, 2.4, 20, 100},
      {"intensities 1x1", opt(Method::flann, Feature::intensities, 1), 1, Feature::intensities, 1, 0, 0, 0},
      {"patchmatch 7x7, 5 it", opt(Method::patchmatch, Feature::normals, 7), 7, Feature::normals, 1, 0.98, 20, 150},
      {"regiongrow 3x3", opt(Method::regiongrow, Feature::normals, 3), 3, Feature::normals, 1, 16, 20, 150},
      {"candidates K=100", opt(Method::candidates, Feature::normals, 1), 1, Feature::normals, 100, 19, 20, 100},
      {"combined (the default: motion probe, then coherent)", opt(Method::combined, Feature::normals, 1), 1,
       Feature::normals, 1, 0, 0, 100},
      {"coherent (the previous default)", opt(Method::coherent, Feature::normals, 1), 1, Feature::normals, 1, 0, 10, 40},
      {"coherent, chunks only", [&] {
         auto o = opt(Method::coherent, Feature::normals, 1);
         o.coherent_smooth = 0;  // without the seam refinement
         return o;
       }(), 1, Feature::normals, 1, 0, 10, 40},
  };

  std::printf("## bench_match — correspondence, fast engine vs the faithful FLANN peer\n\n");
  std::printf("1024x680 frames, %s, 2 cores. fast = fast::compute_map on both cores, median of %d runs (3 for the large object) after a warm-up, whole call "
              "(features + index + search), as wall time and as CPU time summed over both cores (CPU time does "
              "not grow when other programs load the machine; wall time does). FLANN = 4 randomized kd-trees, "
              "32 checks, one thread, on the same feature vectors (make_features + build + all queries; K=100 "
              "for candidates), one run, CPU time. "
              "Thesis: one core of an i7-2600K at ~21k px.\n\n",
              source_of_objects.c_str(), runs);
  for (auto& pr : pairs) {
    const int nd = count(pr.dst.mask), ns = count(pr.src.mask);
    std::printf("### %s: destination %d px, source %d px\n\n", pr.name.c_str(), nd, ns);
    std::printf("| step | thesis (s) | fast wall (ms) | fast CPU, both cores (ms) | FLANN peer CPU (ms) | FLANN / fast wall | FLANN / fast CPU | target wall (ms) | nearest search |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|\n");
    for (const Row& r : rows) {
      if (!only.empty() && r.step != only) continue;
      fast::Stats st;
      std::vector<double> t;
      bool ok = true;
      std::vector<double> cpu;
      Quality q;  // of the last run's map, printed with --only
      const int reps = pr.large && only.empty() ? std::min(runs, 3) : runs;
      for (int i = 0; i <= reps; ++i) {  // run 0 warms caches and the thread pool
        const auto t0 = Clock::now();
        const double c0 = process_cpu_ms();
        auto m = fast::compute_map(pr.dst, pr.src, r.options, {}, &st);
        const double e = ms_since(t0);
        if (i > 0) cpu.push_back(process_cpu_ms() - c0);
        if (!m) {
          std::printf("| %s | error: %s |\n", r.step.c_str(), m.message().c_str());
          ok = false;
          break;
        }
        if (i > 0) t.push_back(e);
        if (!only.empty() && i == reps) q = evaluate(*m, pr.dst.mask, pr.src.mask, pr.dst.normals, pr.src.normals);
      }
      if (!ok) continue;
      const double fast_ms = median(t), fast_cpu = median(cpu);
      const double peer = flann_ms(pr.dst, pr.src, r.flann_feature, r.flann_patch, r.flann_k);
      const double target = pr.large ? r.target_large_ms : r.target_small_ms;
      std::printf("| %s | %s | %s | %s | %s | %sx | %sx | %s | %s |\n", r.step.c_str(),
                  r.thesis_s > 0 ? fmt(r.thesis_s, 2).c_str() : "—", fmt(fast_ms, 2).c_str(), fmt(fast_cpu, 2).c_str(),
                  fmt(peer, 0).c_str(), fmt(peer > 0 ? peer / fast_ms : -1, 0).c_str(),
                  fmt(peer > 0 ? peer / fast_cpu : -1, 0).c_str(),
                  target > 0 ? ("≤ " + fmt(target, 0)).c_str() : "—",
                  r.options.method == Method::patchmatch || r.options.method == Method::coherent ? "—"
                  : st.index == "lookup" ? "lookup (own cell)"
                  : !st.projected_dims ? "exact"
                  : st.certified > 0 ? (fmt(100 * st.certified, 1) + " %").c_str()
                                     : "approximate");
      if (!only.empty())  // a speed change shows here whether it moved the map
        std::printf("\nmap: mean normal error %s deg, coherence %s %%\n", fmt(q.normal_mean_deg.value_or(-1), 3).c_str(),
                    fmt(100 * q.coherence, 2).c_str());
      std::fflush(stdout);
    }
    std::printf("\n");
    if (!only.empty()) continue;

    // The nearest-normal index alone: build + all queries (1x1 normals).
    const std::vector<float> sp = normals_of(pr.src), dp = normals_of(pr.dst);
    index_table("nearest-normal index", sp, dp, 100, pr.large ? 1 : runs);
    if (pr.large) box_source_table(dp);

    // What the maps look like (synthetic shapes carry their true normals).
    std::printf("| method | mean normal error (deg) | coherence (%%) | max reuse |\n|---|---|---|---|\n");
    for (const auto& [name, o] : std::vector<std::pair<std::string, MatchOptions>>{
             {"normals 1x1 (nearest)", opt(Method::flann, Feature::normals, 1)},
             {"normals 7x7", opt(Method::flann, Feature::normals, 7)},
             {"patchmatch 7x7", opt(Method::patchmatch, Feature::normals, 7)},
             {"regiongrow 3x3", opt(Method::regiongrow, Feature::normals, 3)},
             {"coherent, threshold 0.05", [&] {
                auto o = opt(Method::coherent, Feature::normals, 1);
                o.coherent_threshold = 0.05;
                return o;
              }()},
             {"coherent (threshold 0.10, the default)", opt(Method::coherent, Feature::normals, 1)},
             {"coherent, chunks only (no seam refinement)", [&] {
                auto o = opt(Method::coherent, Feature::normals, 1);
                o.coherent_smooth = 0;
                return o;
              }()},
             {"coherent, threshold 0.20", [&] {
                auto o = opt(Method::coherent, Feature::normals, 1);
                o.coherent_threshold = 0.20;
                return o;
              }()},
             {"coherent, uniformity 0.5", [&] {
                auto o = opt(Method::coherent, Feature::normals, 1);
                o.uniformity = 0.5;
                return o;
              }()}}) {
      auto m = fast::compute_map(pr.dst, pr.src, o);
      if (!m) continue;
      if (!pictures.empty()) {
        std::string file = (pr.large ? "large_" : "small_") + name;
        for (char& ch : file)
          if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
        write_pictures(pictures, file, *m, pr.dst, pr.src);
      }
      const Quality q = evaluate(*m, pr.dst.mask, pr.src.mask, pr.dst.normals, pr.src.normals);
      std::printf("| %s | %s | %s | %d |\n", name.c_str(), fmt(q.normal_mean_deg.value_or(-1), 2).c_str(),
                  fmt(100 * q.coherence, 1).c_str(), q.reuse_max);
    }
    std::printf("\n");
  }
  return 0;
}
