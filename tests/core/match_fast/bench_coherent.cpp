// bench_coherent: how the `coherent` method's threshold trades coherence for
// normal agreement on the thesis pairs of issue 4 (orange -> bull, stone ->
// bull, cup-dots -> cup-white), matched on the simulator's truth normals at
// 512x340 and measured with match::evaluate against the same truth. Prints one
// markdown table; the per-pixel nearest (fast flann) is the reference row.
#include <cstdio>
#include <string>
#include <vector>

#include "veneer/match/fast.hpp"
#include "veneer/match/metrics.hpp"
#include "veneer/sim/simulator.hpp"

using namespace veneer;
using namespace veneer::match;

int main() {
  const std::vector<std::pair<std::string, std::string>> pairs = {
      {"bull", "orange"}, {"bull", "stone"}, {"cup-white", "cup-dots"}};
  const std::vector<double> thresholds = {0.03, 0.05, 0.08, 0.10, 0.15, 0.20, 0.30};
  std::printf("## bench_coherent — threshold vs coherence vs normal agreement (truth normals, 512x340)\n\n");
  std::printf("| destination <- source | method | threshold | coherence (%%) | normal mean (deg) | normal p95 (deg) | wall (ms) |\n");
  std::printf("|---|---|---|---|---|---|---|\n");
  for (const auto& [dname, sname] : pairs) {
    sim::RenderOptions ro;
    ro.size = cv::Size(512, 340);
    auto ds = sim::make_scene(dname, ro);
    auto ss = sim::make_scene(sname, ro);
    if (!ds || !ss) {
      std::printf("| %s <- %s | scene missing | | | | | |\n", dname.c_str(), sname.c_str());
      continue;
    }
    const Truth dt = sim::render_truth(**ds, ro), st = sim::render_truth(**ss, ro);
    ObjectView dv{dt.normals, dt.mask, {}, {}}, sv{st.normals, st.mask, {}, {}};
    auto run = [&](const char* label, MatchOptions o, double thr) {
      fast::Stats stats;
      auto m = fast::compute_map(dv, sv, o, {}, &stats);
      if (!m) {
        std::printf("| %s <- %s | %s | error: %s |\n", dname.c_str(), sname.c_str(), label, m.message().c_str());
        return;
      }
      const Quality q = evaluate(*m, dt.mask, st.mask, dt.normals, st.normals);
      std::printf("| %s <- %s | %s | %s | %.1f | %.2f | %.2f | %.1f |\n", dname.c_str(), sname.c_str(), label,
                  thr > 0 ? std::to_string(thr).substr(0, 4).c_str() : "—", 100 * q.coherence,
                  q.normal_mean_deg.value_or(-1), q.normal_p95_deg.value_or(-1), 1000 * stats.seconds);
    };
    MatchOptions nearest;
    nearest.method = Method::flann;
    nearest.feature = Feature::normals;
    nearest.fast = true;
    run("nearest 1x1", nearest, 0);
    for (double t : thresholds) {
      MatchOptions o = nearest;
      o.method = Method::coherent;
      o.coherent_threshold = t;
      run("coherent", o, t);
    }
  }
  return 0;
}
