// bench_coherent: how the `coherent` method trades coherence for normal
// agreement on the thesis pairs of issue 4 (orange -> bull, stone -> bull,
// cup-dots -> cup-white), matched on the simulator's truth normals and
// measured with eval::evaluate against the same truth, at 512x340 (the
// quality table's size), 1024x680 (the frames) and 1024x680 with the
// objects 1.7x larger (the bull 130k px; bench_match's large one has 150k). Rows:
// the per-pixel nearest (fast flann), the chunks alone (coherent_smooth = 0)
// over thresholds, and the chunks refined over thresholds t and seam costs w
// (default t = 0.10, w = 2), and once with a 4 px guide (coherent_guide: the
// source's normals smoothed, its relief copied whole; its normal error is
// still against the fine truth, relief included). A second table gives, per pair and frame, the
// most coherent of those rows whose mean normal error stays within 3 degrees
// (issue 4 asks for at least 85 %).
// Usage: bench_coherent [--quick] [--pictures DIR]
//   --quick: 512x340 only; --pictures: per pair and size, the destination's
//   normals with every pixel whose match breaks with a neighbour's in red
//   (default options), cut to the object and enlarged up to 4x.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/eval/metrics.hpp"
#include "veneer/match/fast.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/sim/simulator.hpp"

using namespace veneer;
using namespace veneer::match;
using namespace veneer::eval;
using namespace veneer::pipeline;

namespace {

// the destination's normals, darkened, with the pixels whose match lies more
// than 1.5 px from a right or lower neighbour's in red
cv::Mat seam_picture(const Map& m, const io::Truth& t) {
  cv::Mat img(t.mask.size(), CV_8UC3, cv::Scalar(0, 0, 0));
  for (int y = 0; y < img.rows; ++y)
    for (int x = 0; x < img.cols; ++x) {
      if (!t.mask.at<uchar>(y, x)) continue;
      const cv::Vec3f n = t.normals.at<cv::Vec3f>(y, x);
      auto level = [](float v) { return static_cast<uchar>(50 + 60 * (v + 1)); };
      img.at<cv::Vec3b>(y, x) = cv::Vec3b(level(n[2]), level(n[1]), level(n[0]));
      const cv::Vec2f a = m.xy.at<cv::Vec2f>(y, x);
      for (const cv::Point off : {cv::Point(1, 0), cv::Point(0, 1)}) {
        const int nx = x + off.x, ny = y + off.y;
        if (nx >= img.cols || ny >= img.rows || !t.mask.at<uchar>(ny, nx)) continue;
        const cv::Vec2f b = m.xy.at<cv::Vec2f>(ny, nx);
        if (std::hypot(a[0] - b[0], a[1] - b[1]) > 1.5) img.at<cv::Vec3b>(y, x) = cv::Vec3b(0, 0, 255);
      }
    }
  const cv::Rect box = cv::boundingRect(t.mask);
  const int f = std::clamp(1400 / std::max(1, box.width), 1, 4);  // enlarged to about 1400 px wide, at most 4x
  cv::Mat big;
  cv::resize(img(box), big, {}, f, f, cv::INTER_NEAREST);
  return big;
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false;
  std::string pictures;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) quick = true;
    if (std::strcmp(argv[i], "--pictures") == 0 && i + 1 < argc) pictures = argv[++i];
  }
  const std::vector<std::pair<std::string, std::string>> pairs = {
      {"bull", "orange"}, {"bull", "stone"}, {"cup-white", "cup-dots"}};
  const std::vector<double> thresholds = {0.05, 0.10, 0.20, 0.30};
  const std::vector<double> seam_costs = {0.5, 1, 2, 4};          // at the default threshold
  const std::vector<double> refined_thresholds = {0.15, 0.18, 0.20};  // with w = 1 and 2
  struct Frame {
    cv::Size size;
    double scale;  // the simulator's object scale (1.7: the bull 130k px)
    std::string label;
  };
  std::vector<Frame> frames = {{{512, 340}, 1.0, "512x340"}};
  if (!quick) {
    frames.push_back({{1024, 680}, 1.0, "1024x680"});
    frames.push_back({{1024, 680}, 1.7, "1024x680 large"});
  }
  struct Best {
    std::string frame, pair, at;
    double coherence = -1, normal = 0;
  };
  std::vector<Best> best;
  std::printf("## bench_coherent — coherence vs normal agreement (truth normals)\n\n");
  std::printf("`coherent` at threshold t; w = seam cost of the refinement (0 = the chunks alone; default t = 0.10, "
              "w = 2). Time: one call, both cores.\n\n");
  std::printf("| frame | destination <- source | px | method | t | w | coherence (%%) | normal mean (deg) | normal p95 "
              "(deg) | wall (ms) | of which refinement (ms) |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Frame& frame : frames)
    for (const auto& [dname, sname] : pairs) {
      const cv::Size size = frame.size;
      const char* fl = frame.label.c_str();
      sim::RenderOptions ro;
      ro.size = size;
      ro.scale = frame.scale;
      auto ds = sim::make_scene(dname, ro);
      auto ss = sim::make_scene(sname, ro);
      if (!ds || !ss) {
        std::printf("| %s | %s <- %s | scene missing |\n", fl, dname.c_str(), sname.c_str());
        continue;
      }
      const io::Truth dt = sim::render_truth(**ds, ro), st = sim::render_truth(**ss, ro);
      ObjectView dv{dt.normals, dt.mask, {}, {}}, sv{st.normals, st.mask, {}, {}};
      const int px = cv::countNonZero(dt.mask);
      auto run = [&](const char* label, const MatchOptions& o, bool picture) {
        fast::Stats stats;
        auto m = fast::compute_map(dv, sv, o, {}, &stats);
        if (!m) {
          std::printf("| %s | %s <- %s | %d | %s | error: %s |\n", fl, dname.c_str(), sname.c_str(), px, label,
                      m.message().c_str());
          return;
        }
        const Quality q = evaluate(*m, dt.mask, st.mask, dt.normals, st.normals);
        const bool coherent = o.method == Method::coherent;
        const std::string t = coherent ? std::to_string(o.coherent_threshold).substr(0, 4) : "—";
        const std::string w = coherent ? std::to_string(o.coherent_smooth).substr(0, 3) : "—";
        std::printf("| %s | %s <- %s | %d | %s | %s | %s | %.1f | %.2f | %.2f | %.1f | %.1f |\n", fl, dname.c_str(),
                    sname.c_str(), px, label, t.c_str(), w.c_str(), 100 * q.coherence,
                    q.normal_mean_deg.value_or(-1), q.normal_p95_deg.value_or(-1), 1000 * stats.seconds,
                    1000 * stats.refine_seconds);
        const double normal = q.normal_mean_deg.value_or(180);
        Best& b = best.back();
        if (normal <= 3.0 && q.coherence > b.coherence)
          b.coherence = q.coherence, b.normal = normal, b.at = std::string(label) + ", t = " + t + ", w = " + w;
        if (picture && !pictures.empty()) {
          std::string name = frame.label;
          for (char& ch : name) ch = ch == ' ' ? '_' : ch;
          cv::imwrite(pictures + "/seams_" + dname + "_" + sname + "_" + name + ".png", seam_picture(*m, dt));
        }
      };
      best.push_back({frame.label, dname + " <- " + sname, "", -1, 0});
      MatchOptions nearest;
      nearest.method = Method::flann;
      nearest.feature = Feature::normals;
      nearest.fast = true;
      run("nearest 1x1", nearest, false);
      for (double t : thresholds) {
        MatchOptions o = nearest;
        o.method = Method::coherent;
        o.coherent_threshold = t;
        o.coherent_smooth = 0;
        run("coherent, chunks", o, false);
      }
      for (double w : seam_costs) {
        MatchOptions o = nearest;
        o.method = Method::coherent;
        o.coherent_smooth = w;
        run("coherent, refined", o, w == MatchOptions{}.coherent_smooth);
      }
      {  // the source's relief copied whole (a smoothed guide): normal error still against the fine truth
        MatchOptions o = nearest;
        o.method = Method::coherent;
        o.coherent_guide = 4;
        run("coherent, refined, guide 4 px", o, false);
      }
      for (double t : refined_thresholds)
        for (double w : {1.0, 2.0}) {
          MatchOptions o = nearest;
          o.method = Method::coherent;
          o.coherent_threshold = t;
          o.coherent_smooth = w;
          run("coherent, refined", o, false);
        }
    }
  std::printf("\n| frame | destination <- source | most coherent row with normal mean ≤ 3° | coherence (%%) | normal "
              "mean (deg) | ≥ 85 %% |\n|---|---|---|---|---|---|\n");
  for (const Best& b : best)
    std::printf("| %s | %s | %s | %.1f | %.2f | %s |\n", b.frame.c_str(), b.pair.c_str(),
                b.at.empty() ? "none" : b.at.c_str(), 100 * std::max(0.0, b.coherence), b.normal,
                b.coherence >= 0.85 ? "yes" : "no");
  return 0;
}
