// veneer figures: the thesis's result figures (5.2-5.13) re-made on the
// simulated pairs, each a labelled row of pictures, plus index.md.
#include <cstdio>
#include <fstream>
#include <iostream>
#include <map>

#include <opencv2/imgproc.hpp>

#include "command.hpp"
#include "output.hpp"
#include "veneer/eval/metrics.hpp"
#include "veneer/eval/table.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/repaint/repaint.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::cli {
namespace {

using namespace veneer::match;
using namespace veneer::eval;
using namespace veneer::pipeline;
using namespace veneer::repaint;

struct FiguresArgs {
  std::string out = "demo-out/figures";
  std::string size = "512x340";
  bool truth_normals = false;
};

::veneer::cli::Output report{"figures"};

struct Tile {
  std::string label;
  cv::Mat picture;  // 8-bit BGR
  cv::Rect crop;    // empty = the figure's crop (the destination object)
};

// One row of tiles, each cropped and scaled to the same height, its label above.
cv::Mat montage(const std::vector<Tile>& tiles, const cv::Rect& crop) {
  const int label_h = 22, gap = 4, height = 320;
  std::vector<cv::Mat> cols;
  for (const auto& t : tiles) {
    const cv::Rect r = (t.crop.area() > 0 ? t.crop : crop) & cv::Rect(0, 0, t.picture.cols, t.picture.rows);
    const double zoom = static_cast<double>(height) / std::max(1, r.height);
    cv::Mat view;
    cv::resize(t.picture(r), view, {}, zoom, zoom, zoom >= 1 ? cv::INTER_NEAREST : cv::INTER_AREA);
    cv::Mat cell(height + label_h, std::max(view.cols, 150), CV_8UC3, cv::Scalar(30, 30, 30));
    view.copyTo(cell(cv::Rect(0, label_h, view.cols, std::min(view.rows, height))));
    cv::putText(cell, t.label, {4, 15}, cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(235, 235, 235), 1, cv::LINE_AA);
    cols.push_back(cell);
    cols.emplace_back(cell.rows, gap, CV_8UC3, cv::Scalar(0, 0, 0));
  }
  if (!cols.empty()) cols.pop_back();
  cv::Mat out;
  cv::hconcat(cols, out);
  return out;
}

cv::Rect object_crop(const cv::Mat& mask, int margin) {
  std::vector<cv::Point> pts;
  cv::findNonZero(mask, pts);
  if (pts.empty()) return {0, 0, mask.cols, mask.rows};
  cv::Rect r = cv::boundingRect(pts);
  r.x -= margin, r.y -= margin, r.width += 2 * margin, r.height += 2 * margin;
  return r & cv::Rect(0, 0, mask.cols, mask.rows);
}

struct Figures {
  FiguresArgs args;
  cv::Size size;
  std::map<std::string, io::ImageSet> sets;
  std::map<std::string, PreparedObject> objects;
  std::map<std::string, cv::Mat> medians;
  std::ofstream index;

  // A scene paired with itself is taken from a second capture (metrics.hpp).
  static std::string key(const std::string& scene, bool second) { return second ? scene + "#2" : scene; }

  Status load(const std::string& scene, bool second = false) {
    const std::string k = key(scene, second);
    if (objects.count(k)) return {};
    sim::RenderOptions ro;
    ro.size = size;
    ro.noise_sigma = 0.005;  // `veneer simulate`'s default sensor noise
    if (second) second_capture(ro);
    auto set = sim::simulate_set(scene, ro);
    if (!set) return make_error("simulating " + scene + ": " + set.message());
    auto prepared = prepare_object(*set, args.truth_normals);
    if (!prepared) return make_error(scene + ": " + prepared.message());
    medians[k] = median_photo(prepared->view.images);
    sets[k] = std::move(*set);
    objects[k] = std::move(*prepared);
    return {};
  }

  Expected<Map> map(const std::string& d, const std::string& s, MatchOptions o) {
    const bool second = d == s;
    if (auto st = load(d); !st) return st.error();
    if (auto st = load(s, second); !st) return st.error();
    o.fast = false;  // the thesis's methods as they were
    return compute_map(objects[d].view, objects[key(s, second)].view, o);
  }

  // The source's photo, cropped to its own object, with the destination's crop's aspect.
  Tile source_tile(const std::string& s, bool second = false) {
    const std::string k = key(s, second);
    return Tile{"source " + s, io::tonemap_picture(medians[k]), object_crop(objects[k].view.mask, 12)};
  }

  // The destination repainted with the source's median photo.
  Expected<Tile> result(const std::string& d, const std::string& s, const MatchOptions& o, const std::string& label) {
    auto m = map(d, s, o);
    if (!m) return m.error();
    return Tile{label, io::tonemap_picture(repaint::repaint(*m, medians[key(s, d == s)], medians[d])), cv::Rect()};
  }

  Status write(const std::string& name, const std::string& caption, const std::vector<Tile>& tiles,
               const std::string& crop_scene) {
    const cv::Mat picture = montage(tiles, object_crop(objects[crop_scene].view.mask, 12));
    if (auto s = report.picture(name + ".png", picture); !s) return s;
    index << "- `" << name << ".png` — " << caption << "\n";
    report.line(report.path(name + ".png").string());
    return {};
  }
};

MatchOptions opts(Method m, Feature f = Feature::normals, int patch = 1) {
  MatchOptions o;
  o.method = m;
  o.feature = f;
  o.patch = patch;
  return o;
}

int run(const FiguresArgs& a) {
  Figures F;
  F.args = a;
  int w = 0, h = 0;
  if (std::sscanf(a.size.c_str(), "%dx%d", &w, &h) != 2 || w < 64 || h < 64 || w > 4096 || h > 4096)
    return report.usage("--size must be WxH (64..4096), got '" + a.size + "'");
  F.size = {w, h};
  if (auto s = report.folder(a.out); !s) return report.fail(s.message());
  F.index.open(report.path("index.md"));
  F.index << "# Thesis figures 5.2-5.13 re-made on the simulated rig (" << w << "x" << h << ", normals from "
          << (a.truth_normals ? "truth" : "photometric stereo") << ", faithful methods)\n\n";
  auto check = [](const Status& s) {
    if (!s) throw std::runtime_error(s.message());
  };
  auto tile = [&](Expected<Tile> t) {
    if (!t) throw std::runtime_error(t.message());
    return *t;
  };
  try {
    // 5.2 the objects: photo (median of the lamps) and normals
    {
      std::vector<Tile> tiles;
      for (const char* s : {"orange", "bull", "stone", "two-spheres", "blocks"}) {
        check(F.load(s));
        const cv::Rect crop = object_crop(F.objects[s].view.mask, 12);
        tiles.push_back({std::string(s) + " photo", io::tonemap_picture(F.medians[s]), crop});
        tiles.push_back({std::string(s) + " normals", io::normals_picture(F.objects[s].view.normals), crop});
      }
      check(F.write("fig5_02_objects", "objects of the simulated rig: median photo and photometric-stereo normals",
                    tiles, "bull"));
    }
    // 5.3 map pictures (R = x, G = y, B = 1) of orange -> bull per method
    {
      std::vector<Tile> tiles;
      for (Method m : {Method::baseline, Method::linear, Method::flann, Method::candidates, Method::patchmatch,
                       Method::regiongrow}) {
        auto mp = F.map("bull", "orange", opts(m));
        if (!mp) return report.fail(mp.message());
        tiles.push_back({method_name(m), map_picture(*mp, F.sets["orange"].size), cv::Rect()});
      }
      check(F.write("fig5_03_maps", "correspondence maps orange -> bull (R = source x, G = source y, B = 1)", tiles,
                    "bull"));
    }
    // 5.4 normals vs intensities, orange -> bull
    check(F.write("fig5_04_features", "orange -> bull: source, normals 1x1, intensities 1x1, normals 3x3, intensities 3x3",
                  {F.source_tile("orange"),
                   tile(F.result("bull", "orange", opts(Method::flann), "normals 1x1")),
                   tile(F.result("bull", "orange", opts(Method::flann, Feature::intensities), "intensities 1x1")),
                   tile(F.result("bull", "orange", opts(Method::flann, Feature::normals, 3), "normals 3x3")),
                   tile(F.result("bull", "orange", opts(Method::flann, Feature::intensities, 3), "intensities 3x3"))},
                  "bull"));
    // 5.5 patch sizes
    {
      std::vector<Tile> tiles;
      for (int p : {1, 3, 5, 7})
        tiles.push_back(tile(F.result("bull", "orange", opts(Method::flann, Feature::normals, p),
                                      "flann normals " + std::to_string(p) + "x" + std::to_string(p))));
      check(F.write("fig5_05_patches", "orange -> bull: patch sizes 1, 3, 5, 7 (larger patches, less speckle)",
                    tiles, "bull"));
    }
    // 5.6 / 5.7 candidates on two-spheres -> blocks and blocks -> blocks
    for (const auto& [fig, src] : {std::pair<std::string, std::string>{"fig5_06_candidates_spheres", "two-spheres"},
                                   {"fig5_07_candidates_blocks", "blocks"}}) {
      const bool second = src == "blocks";
      check(F.load(src, second));
      std::vector<Tile> tiles{F.source_tile(src, second)};
      for (int k : {1, 10, 100}) {
        auto o = opts(Method::candidates);
        o.candidates = k;
        tiles.push_back(tile(F.result("blocks", src, o, "candidates K=" + std::to_string(k))));
      }
      check(F.write(fig, src + " -> blocks: candidate lists K = 1, 10, 100 (eq. 4.2)", tiles, "blocks"));
    }
    // 5.8 region growing on stone -> bull
    {
      check(F.load("stone"));
      std::vector<Tile> tiles{F.source_tile("stone")};
      for (double t : {0.0, 0.02, 0.05, 0.1}) {
        auto o = opts(Method::regiongrow, Feature::normals, 3);
        o.threshold = t;
        char label[64];
        std::snprintf(label, sizeof label, "regiongrow 3x3 T=%.2f", t);
        tiles.push_back(tile(F.result("bull", "stone", o, label)));
      }
      check(F.write("fig5_08_regiongrow", "stone -> bull: region growing thresholds (0 = direct matching)", tiles,
                    "bull"));
    }
    // 5.9 patchmatch iterations
    {
      std::vector<Tile> tiles;
      for (int it : {1, 2, 5}) {
        auto o = opts(Method::patchmatch, Feature::normals, 7);
        o.iterations = it;
        tiles.push_back(tile(F.result("bull", "stone", o, "patchmatch 7x7, " + std::to_string(it) + " it.")));
      }
      tiles.push_back(tile(F.result("bull", "stone", opts(Method::linear, Feature::normals, 7), "linear 7x7")));
      check(F.write("fig5_09_patchmatch", "stone -> bull: PatchMatch 7x7 after 1, 2, 5 iterations vs exact", tiles,
                    "bull"));
    }
    // 5.10 baseline vs matching, apple -> banana
    check(F.load("apple"));
    check(F.write("fig5_10_baseline", "apple -> banana: source, bounding-box baseline, flann normals, regiongrow",
                  {F.source_tile("apple"),
                   tile(F.result("banana", "apple", opts(Method::baseline), "baseline")),
                   tile(F.result("banana", "apple", opts(Method::flann), "flann normals")),
                   tile(F.result("banana", "apple", opts(Method::regiongrow, Feature::normals, 3), "regiongrow 3x3"))},
                  "banana"));
    // 5.11 cup-dots -> cup-white per method
    {
      check(F.load("cup-dots"));
      std::vector<Tile> tiles{F.source_tile("cup-dots")};
      for (Method m : {Method::flann, Method::candidates, Method::patchmatch, Method::regiongrow})
        tiles.push_back(tile(F.result("cup-white", "cup-dots", opts(m, Feature::normals, 3),
                                      std::string(method_name(m)) + " 3x3")));
      check(F.write("fig5_11_cups", "cup-dots -> cup-white: the dots carried by each method", tiles, "cup-white"));
    }
    // 5.12 relighting: sphere-red-gloss -> bull under each lamp
    {
      auto mp = F.map("bull", "sphere-red-gloss", opts(Method::flann));
      if (!mp) return report.fail(mp.message());
      std::vector<Tile> tiles;
      const auto& src = F.objects["sphere-red-gloss"].view.images;
      const auto& dst = F.objects["bull"].view.images;
      for (size_t i = 0; i < src.size(); i += 2)
        tiles.push_back({"lamp " + std::to_string(i), io::tonemap_picture(repaint::repaint(*mp, src[i], dst[i])), cv::Rect()});
      check(F.write("fig5_12_relight", "sphere-red-gloss -> bull: the bull relit by the source's photos, lamp by lamp",
                    tiles, "bull"));
    }
    // 5.13 origin tool
    {
      auto mp = F.map("bull", "orange", opts(Method::flann, Feature::normals, 3));
      if (!mp) return report.fail(mp.message());
      const cv::Mat picture =
          origin_picture(*mp, F.medians["bull"], F.medians["orange"], spread_points(*mp, 16));
      if (auto s = report.picture("fig5_13_origins.png", picture); !s) return report.fail(s.message());
      F.index << "- `fig5_13_origins.png` — origin tool: where 16 bull pixels took their look from on the orange\n";
      report.line(report.path("fig5_13_origins.png").string());
    }
  } catch (const std::exception& e) {
    return report.fail(e.what());
  }
  return 0;
}

}  // namespace
}  // namespace veneer::cli

VENEER_ARGS_COMMAND(figures, veneer::cli::FiguresArgs, "re-make the thesis's figures 5.2-5.13 on the simulated pairs") {
  cmd->add_option("--out", args->out, "output folder (default demo-out/figures)");
  cmd->add_option("--size", args->size, "render size WxH (default 512x340)");
  cmd->add_flag("--truth-normals", args->truth_normals, "match on true normals instead of photometric stereo");
  return [args] { return veneer::cli::run(*args); };
}
