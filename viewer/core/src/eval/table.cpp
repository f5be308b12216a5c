// The quality table of the thesis pairs (table.hpp).
#include <chrono>
#include <cstdio>
#include <map>
#include <memory>
#include <optional>
#include <sstream>

#include "veneer/eval/metrics.hpp"
#include "veneer/eval/table.hpp"
#include "veneer/match/fast.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/match/object.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::eval {

using namespace veneer::match;

std::vector<std::pair<std::string, std::string>> thesis_pairs() {
  return {{"bull", "orange"},          {"banana", "apple"},   {"cup-white", "cup-dots"},
          {"blocks", "two-spheres"},   {"blocks", "blocks"},  {"bull", "stone"},
          {"bull", "sphere-red-gloss"}, {"cup-white", "sphere-gray"}};
}

void second_capture(sim::RenderOptions& options) {
  options.offset_m = {0.035, -0.02, 0};
  options.scale = 0.85;
}

namespace {

struct RowSpec {
  Method method;
  Feature feature;
  int patch;
  int candidates = 10;
  double threshold = 0.05;
  bool fast = false;
};

std::vector<RowSpec> row_specs(const TableOptions& o) {
  std::vector<RowSpec> specs;
  if (o.full) {
    for (Method m : {Method::baseline, Method::linear, Method::flann, Method::candidates, Method::patchmatch,
                     Method::regiongrow})
      for (Feature f : {Feature::normals, Feature::intensities})
        for (int p : {1, 3, 5, 7}) {
          if (m == Method::baseline && (f != Feature::normals || p != 1)) continue;
          specs.push_back({m, f, p});
          if (m == Method::candidates) specs.push_back({m, f, p, 100});
        }
  } else {
    specs = {{Method::baseline, Feature::normals, 1},    {Method::linear, Feature::normals, 1},
             {Method::flann, Feature::normals, 1},       {Method::flann, Feature::normals, 3},
             {Method::flann, Feature::normals, 7},       {Method::flann, Feature::intensities, 1},
             {Method::flann, Feature::intensities, 3},   {Method::candidates, Feature::normals, 1, 10},
             {Method::patchmatch, Feature::normals, 3},  {Method::regiongrow, Feature::normals, 1}};
  }
  if (o.include_fast) {
    std::vector<RowSpec> fast;
    for (RowSpec s : specs) {
      if (s.method == Method::baseline) continue;
      s.fast = true;
      MatchOptions mo;
      mo.method = s.method, mo.feature = s.feature, mo.patch = s.patch, mo.candidates = s.candidates, mo.fast = true;
      if (fast::supports(mo)) fast.push_back(s);
    }
    MatchOptions coherent;
    coherent.method = Method::coherent;
    if (fast::supports(coherent)) {
      fast.push_back({Method::coherent, Feature::normals, 1, 10, 0.05, true});
      fast.push_back({Method::coherent, Feature::intensities, 1, 10, 0.05, true});
    }
    specs.insert(specs.end(), fast.begin(), fast.end());
  }
  return specs;
}

}  // namespace

Expected<TableObject> table_object(const std::string& scene, bool second, const TableOptions& options) {
  sim::RenderOptions ro;
  ro.size = options.size;
  ro.threads = options.threads;
  ro.noise_sigma = options.noise;
  if (second) second_capture(ro);
  auto set = sim::simulate_set(scene, ro, second ? io::Role::source : io::Role::destination);
  if (!set) return make_error("simulating " + scene + ": " + set.message());
  auto prepared = prepare_object(*set, options.truth_normals);
  if (!prepared) return make_error(scene + ": " + prepared.message());
  return TableObject{std::move(*set), std::move(prepared->view)};
}

Expected<std::vector<TableRow>> quality_table(const TableOptions& options, const Progress& progress) {
  const auto pairs = options.pairs.empty() ? thesis_pairs() : options.pairs;
  const auto specs = row_specs(options);
  std::map<std::string, TableObject> objects;
  auto object = [&](const std::string& scene, bool second) -> Expected<const TableObject*> {
    const std::string key = scene + (second ? "#2" : "");
    if (auto it = objects.find(key); it != objects.end()) return &it->second;
    auto made = table_object(scene, second, options);
    if (!made) return made.error();
    return &(objects[key] = std::move(*made));
  };
  std::vector<TableRow> rows;
  const double total = static_cast<double>(pairs.size() * specs.size());
  int done = 0;
  for (const auto& [dname, sname] : pairs) {
    const bool second = dname == sname;
    auto d = object(dname, false);
    if (!d) return d.error();
    auto s = object(sname, second);
    if (!s) return s.error();
    const io::ImageSet& dset = (*d)->set;
    const io::ImageSet& sset = (*s)->set;
    std::optional<Expected<RelightScenes>> relit_scenes;
    for (const RowSpec& spec : specs) {
      if (progress.cancelled()) return make_error("quality table cancelled");
      progress.report(done++ / total, dname + " <- " + sname + " " + method_name(spec.method));
      TableRow row;
      row.destination = dname;
      row.source = sname;
      row.method = method_name(spec.method);
      row.feature = feature_name(spec.feature);
      row.engine = spec.fast ? "fast" : "faithful";
      row.patch = spec.patch;
      row.candidates = spec.method == Method::candidates ? spec.candidates : 0;
      row.threshold = spec.method == Method::regiongrow ? spec.threshold : 0;
      row.destination_pixels = cv::countNonZero((*d)->view.mask);
      row.source_pixels = cv::countNonZero((*s)->view.mask);
      MatchOptions mo;
      mo.method = spec.method;
      mo.feature = spec.feature;
      mo.patch = spec.patch;
      mo.candidates = spec.candidates;
      mo.threshold = spec.threshold;
      mo.fast = spec.fast;
      mo.threads = options.threads;
      const auto t0 = std::chrono::steady_clock::now();
      auto map = compute_map((*d)->view, (*s)->view, mo);
      row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      if (!map) {
        row.error = map.message();
        rows.push_back(row);
        continue;
      }
      row.quality = evaluate(*map, dset.truth.mask, sset.truth.mask, dset.truth.normals, sset.truth.normals);
      if (relight_measurable(sname)) {
        // rendered once per pair: the lamp's scenes do not depend on the map
        if (!relit_scenes) relit_scenes = relight_scenes(dset, sset);
        auto relit = *relit_scenes ? relight(*map, **relit_scenes, sset.truth.mask, dset.truth.mask)
                                   : Expected<Relit>(relit_scenes->error());
        if (relit) {
          row.quality.psnr_db = relit->psnr_db;
          row.quality.psnr_lit_db = relit->psnr_lit_db;
        } else {
          row.error = relit.message();
        }
      }
      rows.push_back(row);
    }
  }
  progress.report(1.0, "done");
  return rows;
}

std::string format_table(const std::vector<TableRow>& rows, const TableOptions& options) {
  std::ostringstream out;
  char buf[1024];
  std::snprintf(buf, sizeof buf,
                "Quality of the correspondence methods on simulated pairs, rendered at %dx%d (reduced from 1024x680 so "
                "the faithful methods finish) with sensor noise %.3f, normals from %s; quality measured against the simulator's truth (masks, normals). blocks <- blocks compares two captures (the source moved and smaller). Coherence counts neighbours matched within 1.5 px, so one source pixel stamped over a region also counts as coherent: read it with reuse. PSNR: relighting under a lamp off the capture ring, where the source is of uniform material; PSNR lit leaves out the lamp's cast shadows on the destination, which no map can carry. Faithful flann rows on patches or intensities differ a little from run to run: FLANN shuffles its trees' points from std::random_device.\n\n",
                options.size.width, options.size.height, options.noise,
                options.truth_normals ? "the truth" : "photometric stereo");
  out << buf;
  out << "| destination <- source | px dst/src | method | engine | feature | patch | coverage | normal mean / p95 "
         "[deg] | coherence | reuse max | source used | PSNR [dB] | PSNR lit [dB] | time [s] |\n";
  out << "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& r : rows) {
    std::string method = r.method;
    if (r.candidates) method += " K=" + std::to_string(r.candidates);
    if (r.method == "regiongrow") {
      std::snprintf(buf, sizeof buf, " T=%.2f", r.threshold);
      method += buf;
    }
    if (!r.error.empty() && r.quality.destination_pixels == 0) {
      std::snprintf(buf, sizeof buf, "| %s <- %s | %d/%d | %s | %s | %s | %dx%d | failed: %s ||||||||\n",
                    r.destination.c_str(), r.source.c_str(), r.destination_pixels, r.source_pixels, method.c_str(),
                    r.engine.c_str(), r.feature.c_str(), r.patch, r.patch, r.error.c_str());
      out << buf;
      continue;
    }
    const auto& q = r.quality;
    std::string normals = "-", psnr_text = "-", lit_text = "-";
    if (q.normal_mean_deg) {
      std::snprintf(buf, sizeof buf, "%.2f / %.2f", *q.normal_mean_deg, *q.normal_p95_deg);
      normals = buf;
    }
    if (q.psnr_db) {
      std::snprintf(buf, sizeof buf, "%.2f", *q.psnr_db);
      psnr_text = buf;
    }
    if (q.psnr_lit_db) {
      std::snprintf(buf, sizeof buf, "%.2f", *q.psnr_lit_db);
      lit_text = buf;
    }
    std::snprintf(buf, sizeof buf, "| %s <- %s | %d/%d | %s | %s | %s | %dx%d | %.1f %% | %s | %.1f %% | %d | %.1f %% | %s | %s | %.3f |\n",
                  r.destination.c_str(), r.source.c_str(), r.destination_pixels, r.source_pixels, method.c_str(),
                  r.engine.c_str(), r.feature.c_str(), r.patch, r.patch, 100 * q.coverage, normals.c_str(),
                  100 * q.coherence, q.reuse_max, 100 * q.source_used, psnr_text.c_str(), lit_text.c_str(), r.seconds);
    out << buf;
  }
  return out.str();
}

}  // namespace veneer::eval
