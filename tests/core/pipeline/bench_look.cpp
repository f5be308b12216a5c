// bench_look: the coherence-shading frontier (issue 35). The default
// transfer (the shaded look over default_match_options()) and the pixel copy
// through each matching method's map, scored by metrics.json's look (eval/look.hpp): coverage
// and coherence of the map, the per-lamp shading error against the reference,
// that error over the `linear` map's (the floor of pixel copying, same run),
// and texture_corr (the result's fine detail against the source's warped
// through the map). Pairs: the demo pair (bull <- orange as `make demo`
// simulates them, 1024x680, photometric-stereo normals) against the truth
// look (bull rendered in orange's material), and a real pair
// (../shared/data/real: cat <- buddha) against cat's own photos.
// `ms`: match + repaint; `look ms`: the look's figures (and on the demo pair
// the truth look's render). Prints markdown tables; never fails on a number.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/sim/simulator.hpp"

namespace fs = std::filesystem;
using namespace veneer;

namespace {

struct Row {
  std::string name;
  double coverage = 0, coherence = 0, shading = 0, texture = 0, ms = 0, look_ms = 0;
  double object_shading = -1, object_texture = -1;  // over the object, when the reference has no mask
  bool ok = false;
  std::string reference;
};

Row run(const std::string& name, const io::ImageSet& dst, const io::ImageSet& src,
        const pipeline::TransferOptions& options) {
  Row r;
  r.name = name;
  auto t = pipeline::transfer(dst, src, options);
  if (!t) {
    std::fprintf(stderr, "%s: %s\n", name.c_str(), t.message().c_str());
    return r;
  }
  const nlohmann::json j = nlohmann::json::parse(t->metrics_json);
  if (!j.contains("look")) {
    std::fprintf(stderr, "%s: no look: %s\n", name.c_str(), j.value("look_error", std::string("?")).c_str());
    return r;
  }
  const nlohmann::json& look = j["look"];
  r.coverage = look.value("coverage", 0.0);
  r.coherence = look.value("coherence", 0.0);
  r.shading = look.value("shading_mean", 0.0);
  r.texture = look.value("texture_corr", 0.0);
  r.look_ms = 1000 * look.value("look_s", 0.0);
  if (look.contains("object")) {
    r.object_shading = look["object"].value("shading_mean", 0.0);
    r.object_texture = look["object"].value("texture_corr", 0.0);
  }
  const nlohmann::json& timings = j["timings"];
  r.ms = 1000 * (timings.value("match_s", 0.0) + timings.value("repaint_s", 0.0));
  r.ok = true;
  if (look.contains("truth_error")) std::fprintf(stderr, "%s: %s\n", name.c_str(), look["truth_error"].dump().c_str());
  r.reference = look.value("reference", std::string()) + "; mask: " + look.value("mask", std::string());
  return r;
}

void frontier(const std::string& title, const io::ImageSet& dst, const io::ImageSet& src) {
  std::printf("\n%s\n\n", title.c_str());
  struct Method {
    std::string name;
    pipeline::TransferOptions options;
  };
  std::vector<Method> methods;
  // The product's default: the shaded look over default_match_options()
  // (what the CLI, the viewer and `make demo` run); then pixel copies through
  // each map, `linear` the floor, `combined` the default before the look.
  pipeline::TransferOptions defaults;
  defaults.match = pipeline::default_match_options(repaint::Look::shaded);
  methods.push_back({std::string("default (shaded look, ") + match::method_name(defaults.match.method) + ")", defaults});
  for (match::Method m : {match::Method::linear, match::Method::coherent, match::Method::combined}) {
    pipeline::TransferOptions o;
    o.look = repaint::Look::copy;
    o.match = pipeline::default_match_options(repaint::Look::copy);
    o.match.method = m;
    methods.push_back({std::string(match::method_name(m)) + " (copy)", o});
  }
  std::vector<Row> rows;
  for (const Method& m : methods) rows.push_back(run(m.name, dst, src, m.options));
  double floor = 0, object_floor = 0;
  for (const Row& r : rows)
    if (r.ok && r.name == "linear (copy)") floor = r.shading, object_floor = r.object_shading;
  if (!rows.empty()) std::printf("reference: %s\n\n", rows.back().reference.c_str());
  // Where the reference has no mask (look.py then compares every pixel), the
  // figures over the object follow, their own columns.
  const bool object = object_floor > 0;
  std::printf("| transfer | coverage | coherence | shading error | shading vs linear | texture_corr |%s ms | look ms |\n",
              object ? " object: shading | vs linear | texture_corr |" : "");
  std::printf("|---|---|---|---|---|---|%s---|---|\n", object ? "---|---|---|" : "");
  for (const Row& r : rows) {
    if (!r.ok) {
      std::printf("| %s | failed |\n", r.name.c_str());
      continue;
    }
    std::printf("| %s | %.4f | %.3f | %.4f | %.2fx | %.3f |", r.name.c_str(), r.coverage, r.coherence, r.shading,
                floor > 0 ? r.shading / floor : 0.0, r.texture);
    if (object) std::printf(" %.4f | %.2fx | %.3f |", r.object_shading, r.object_shading / object_floor, r.object_texture);
    std::printf(" %.0f | %.0f |\n", r.ms, r.look_ms);
  }
  std::fflush(stdout);
}

}  // namespace

int main() {
  {
    sim::RenderOptions o;
    o.size = {1024, 680};
    o.noise_sigma = 0.005;  // veneer simulate's default
    auto dst = sim::simulate_set("bull", o, io::Role::destination);
    auto src = sim::simulate_set("orange", o, io::Role::source);
    if (dst && src)
      frontier("demo pair: bull <- orange 1024x680 (photometric-stereo normals), against the truth look", *dst, *src);
    else
      std::fprintf(stderr, "simulate: %s\n", (dst ? src.message() : dst.message()).c_str());
  }
  const fs::path real = fs::path(VENEER_SHARED_DATA) / "real";
  if (!fs::exists(real / "cat") || !fs::exists(real / "buddha")) {
    std::printf("\nreal pair: %s has no cat and buddha; skipped\n", real.c_str());
    return 0;
  }
  auto dst = io::read_set(real / "cat");
  auto src = io::read_set(real / "buddha");
  if (!dst || !src) {
    std::fprintf(stderr, "read_set: %s\n", (dst ? src.message() : dst.message()).c_str());
    return 0;
  }
  frontier("real pair: cat <- buddha (" + std::to_string(dst->size.width) + "x" + std::to_string(dst->size.height) +
               "), against cat's own photos",
           *dst, *src);
  return 0;
}
