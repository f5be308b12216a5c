// bench_quality: the quality table of issue 3 (pairs x methods x feature x
// patch on simulated sets) and a summary per method against the FLANN peer.
#include <chrono>
#include <cstdio>
#include <map>
#include <set>

#include "veneer/match/metrics.hpp"

int main() {
  using namespace veneer::match;
  TableOptions options;  // 512x340, the chosen subset of rows, fast rows where the fast engine serves
  const auto t0 = std::chrono::steady_clock::now();
  auto rows = quality_table(options);
  if (!rows) {
    std::fprintf(stderr, "bench_quality: %s\n", rows.message().c_str());
    return 1;
  }
  std::fputs(format_table(*rows, options).c_str(), stdout);

  // Summary over the pairs: each configuration's mean figures; time relative
  // to faithful flann normals 1x1 on the same pairs (the thesis's default).
  struct Sum {
    double normal = 0, coherence = 0, seconds = 0;
    int n = 0, normal_n = 0;
  };
  std::map<std::string, Sum> sums;
  std::vector<std::string> order;
  for (const auto& r : *rows) {
    if (!r.error.empty() && r.quality.destination_pixels == 0) continue;
    const std::string key = r.method + (r.candidates ? " K=" + std::to_string(r.candidates) : "") + " | " + r.engine +
                            " | " + r.feature + " | " + std::to_string(r.patch) + "x" + std::to_string(r.patch);
    if (!sums.count(key)) order.push_back(key);
    Sum& s = sums[key];
    s.n++;
    s.seconds += r.seconds;
    s.coherence += r.quality.coherence;
    if (r.quality.normal_mean_deg) s.normal += *r.quality.normal_mean_deg, s.normal_n++;
  }
  const std::string peer = "flann | faithful | normals | 1x1";
  const double peer_s = sums.count(peer) ? sums[peer].seconds : 0;
  std::set<std::string> pairs;
  for (const auto& r : *rows) pairs.insert(r.destination + "<-" + r.source);
  std::printf("\nMean over the %zu pairs (time: total over the pairs; ratio = flann normals 1x1 time / this)\n\n",
              pairs.size());
  std::printf("| method | engine | feature | patch | normal mean [deg] | coherence | time [s] | speed vs flann 1x1 |\n");
  std::printf("|---|---|---|---|---|---|---|---|\n");
  for (const auto& key : order) {
    const Sum& s = sums[key];
    std::printf("| %s | %.2f | %.1f %% | %.3f | %.2fx |\n", key.c_str(), s.normal_n ? s.normal / s.normal_n : 0.0,
                100 * s.coherence / s.n, s.seconds, s.seconds > 0 ? peer_s / s.seconds : 0.0);
  }
  std::printf("\nbench_quality total %.1f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  return 0;
}
