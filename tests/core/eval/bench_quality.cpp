// bench_quality: the quality table of issue 3 (pairs x methods x feature x
// patch on simulated sets) and a summary per method against the FLANN peer.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>
#include <set>

#include "veneer/eval/metrics.hpp"
#include "veneer/eval/table.hpp"
#include "veneer/pipeline/transfer.hpp"

namespace {

using namespace veneer;
using namespace veneer::match;
using namespace veneer::eval;
using namespace veneer::pipeline;

const TableRow* find_row(const std::vector<TableRow>& rows, const std::string& dst, const std::string& src,
                         const std::string& method, const std::string& engine) {
  for (const auto& r : rows)
    if (r.destination == dst && r.source == src && r.method == method && r.engine == engine &&
        r.feature == "normals" && r.patch == 1 && r.error.empty())
      return &r;
  return nullptr;
}

// Issue 4 asks, on this table, for `coherent` to reach coherence >= 85 % with
// mean normal agreement within 3 deg on three pairs, and the best relighting
// PSNR on bull <- sphere-red-gloss. "Within 3 deg" is read both ways: as a
// bound on the mean error, and as at most 3 deg more than the exact nearest
// (linear, which the fast engine's "within 0.5 deg" is measured against).
// Besides the default, coherent is swept over its threshold t and seam cost w
// on the table's own sets, so the best it can do on this table is shown too.
Status issue4_targets(const std::vector<TableRow>& rows, const TableOptions& options) {
  std::printf("\n## Issue 4's quality targets on this table\n\n");
  std::printf("coherent swept over t in {0.05 ... 0.40} x w in {1, 2, 4} on the table's sets (normals, fast engine); "
              "exact = linear, the per-pixel nearest normal.\n\n");
  std::printf("| destination <- source | exact: normal mean | coherent default (t = 0.10, w = 2): coherence / normal "
              "mean | most coherent with normal mean <= 3 deg | >= 85 %% | most coherent with normal mean <= exact + 3 "
              "deg | >= 85 %% |\n|---|---|---|---|---|---|---|\n");
  const std::vector<std::pair<std::string, std::string>> pairs = {
      {"bull", "orange"}, {"bull", "stone"}, {"cup-white", "cup-dots"}};
  for (const auto& [dname, sname] : pairs) {
    const TableRow* exact = find_row(rows, dname, sname, "linear", "faithful");
    const TableRow* coherent = find_row(rows, dname, sname, "coherent", "fast");
    if (!exact || !coherent || !exact->quality.normal_mean_deg || !coherent->quality.normal_mean_deg) {
      std::printf("| %s <- %s | not in the table |||||\n", dname.c_str(), sname.c_str());
      continue;
    }
    auto d = table_object(dname, false, options);
    if (!d) return d.error();
    auto s = table_object(sname, false, options);
    if (!s) return s.error();
    const double e0 = *exact->quality.normal_mean_deg;
    struct Best {
      double coherence = -1, normal = 0, t = 0, w = 0;
    } absolute, relative;
    for (double t : {0.05, 0.10, 0.15, 0.20, 0.25, 0.30, 0.40})
      for (double w : {1.0, 2.0, 4.0}) {
        MatchOptions mo;
        mo.method = Method::coherent;
        mo.fast = true;
        mo.threads = options.threads;
        mo.coherent_threshold = t;
        mo.coherent_smooth = w;
        auto map = compute_map(d->view, s->view, mo);
        if (!map) return make_error("coherent on " + dname + " <- " + sname + ": " + map.message());
        const Quality q = evaluate(*map, d->set.truth.mask, s->set.truth.mask, d->set.truth.normals,
                                   s->set.truth.normals);
        const double e = q.normal_mean_deg.value_or(180);
        if (e <= 3.0 && q.coherence > absolute.coherence) absolute = {q.coherence, e, t, w};
        if (e <= e0 + 3.0 && q.coherence > relative.coherence) relative = {q.coherence, e, t, w};
      }
    auto cell = [](const Best& b) {
      char buf[128];
      if (b.coherence < 0) return std::string("none | no");
      std::snprintf(buf, sizeof buf, "%.1f %% at %.2f deg (t = %.2f, w = %.0f) | %s", 100 * b.coherence, b.normal,
                    b.t, b.w, b.coherence >= 0.85 ? "yes" : "no");
      return std::string(buf);
    };
    std::printf("| %s <- %s | %.2f deg | %.1f %% / %.2f deg | %s | %s |\n", dname.c_str(), sname.c_str(), e0,
                100 * coherent->quality.coherence, *coherent->quality.normal_mean_deg, cell(absolute).c_str(),
                cell(relative).c_str());
  }
  // relighting: the table's rows on bull <- sphere-red-gloss by PSNR, best first
  std::vector<const TableRow*> lit;
  for (const auto& r : rows)
    if (r.destination == "bull" && r.source == "sphere-red-gloss" && r.quality.psnr_db) lit.push_back(&r);
  std::stable_sort(lit.begin(), lit.end(),
                   [](const TableRow* a, const TableRow* b) { return *a->quality.psnr_db > *b->quality.psnr_db; });
  std::printf("\nRelighting on bull <- sphere-red-gloss (issue 4: coherent the best PSNR of all methods): the "
              "three best rows and coherent's, of %zu.\n\n| rank | method | engine | feature | patch | PSNR [dB] | "
              "PSNR lit [dB] |\n|---|---|---|---|---|---|---|\n",
              lit.size());
  for (size_t i = 0; i < lit.size(); ++i) {
    const TableRow& r = *lit[i];
    if (i >= 3 && r.method != "coherent") continue;
    const std::string method = r.method + (r.candidates ? " K=" + std::to_string(r.candidates) : "");
    std::printf("| %zu | %s | %s | %s | %dx%d | %.2f | %.2f |\n", i + 1, method.c_str(), r.engine.c_str(),
                r.feature.c_str(), r.patch, r.patch, *r.quality.psnr_db, r.quality.psnr_lit_db.value_or(0));
  }
  return {};
}

}  // namespace

int main() {
  using namespace veneer::match;
  using namespace veneer::eval;
  using namespace veneer::pipeline;
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
  if (auto st = issue4_targets(*rows, options); !st) {
    std::fprintf(stderr, "bench_quality: %s\n", st.message().c_str());
    return 1;
  }
  std::printf("\nbench_quality total %.1f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  return 0;
}
