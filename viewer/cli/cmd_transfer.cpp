// veneer transfer: two image sets in, the correspondence map and the
// destination repainted with the source's appearance out.
#include <chrono>
#include <cstdio>
#include <iostream>
#include <optional>

#include <nlohmann/json.hpp>
#include "veneer/io/codecs.hpp"

#include "command.hpp"
#include "inputs.hpp"
#include "output.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/pipeline/live.hpp"
#include "veneer/pipeline/prepare.hpp"
#include "veneer/pipeline/transfer.hpp"
#include "veneer/repaint/hsh.hpp"
#include "veneer/repaint/rti_export.hpp"
#include "veneer/repaint/web_export.hpp"

namespace veneer::cli {
namespace {

struct TransferArgs {
  std::string dst, src, out, method = "combined", feature = "normals";
  std::string look = repaint::look_name(pipeline::TransferOptions{}.look);
  std::string dst_mask, src_mask;  // object masks drawn elsewhere (e.g. the viewer's hand segmentation)
  // the matching defaults are the library's (MatchOptions)
  int patch = 1, candidates = match::MatchOptions{}.candidates, iterations = match::MatchOptions{}.iterations,
      threads = 0, blend = pipeline::TransferOptions{}.blend;
  double threshold = match::MatchOptions{}.threshold, scale = 1.0,
         uniformity = match::MatchOptions{}.uniformity, coherent_smooth = match::MatchOptions{}.coherent_smooth,
         coherent_guide = match::MatchOptions{}.coherent_guide, blend_guide = pipeline::TransferOptions{}.blend_guide;
  double look_smoothing = repaint::LookOptions{}.normal_smoothing, look_headroom = repaint::LookOptions{}.ratio_headroom,
         look_feather = repaint::LookOptions{}.seam_feather;
  std::optional<double> coherent_threshold;  // unset: pipeline::default_match_options(look)'s
  bool no_grow = false;
  unsigned seed = match::MatchOptions{}.seed;
  bool faithful = false, truth_normals = false, look_floor = false, figures = false;
  // reading the sets (pipeline::PrepareOptions)
  // the reading the viewer does too (pipeline::default_prepare_options: RAW
  // where present, our MHC demosaic)
  std::string photos = io::photo_source_name(pipeline::default_prepare_options().read.photos),
              demosaic = io::demosaic_name(pipeline::default_prepare_options().read.raw.demosaic), cache_dir;
  bool raw_half = false, no_cache = false;
  double cache_size_gb = 4.0;
  // the repainted destination as a relightable file (repaint/rti_export.hpp)
  std::string rti, rti_format = "lrgb";
  int hsh_order = 0;  // --rti-format hsh: 0 = automatic (HshExportOptions)
  // the repainted destination as a web page (repaint/web_export.hpp)
  std::string web;
  int web_size = repaint::WebExportOptions{}.max_side;
  // live first (pipeline/live.hpp): only the map at the live view's size
  bool live = false, live_no_truth = false;
  int live_width = io::ReducedOptions{}.width;
  std::string live_decode = io::reduced_decode_name(io::ReducedOptions{}.decode);
};

::veneer::cli::Output report{"transfer"};

// The repainted photos a transfer folder holds (result_light_NN.png, linear
// 16-bit) fitted into a PTM or HSH under the destination's lamp directions.
Expected<repaint::RtiFit> export_rti(const std::vector<cv::Mat>& photos, const std::vector<cv::Vec3d>& directions,
                                     const std::string& file, const repaint::RtiExportOptions& options,
                                     const std::optional<repaint::HshExportOptions>& hsh) {
  if (hsh) return repaint::export_hsh(photos, directions, file, *hsh);
  return repaint::export_ptm(photos, directions, file, options);
}

// A mask PNG for a set: pixels above 127 are the object. One clear error
// for a file that does not read, has another size than the set, or marks nothing.
Status read_mask(const std::string& option, const std::string& file, const std::string& folder,
                 const io::ReadOptions& read, cv::Mat& mask) {
  mask = veneer::io::codecs::imread(file, cv::IMREAD_GRAYSCALE);
  if (mask.empty()) return make_error(option + " " + file + ": cannot read it as an image");
  io::ReadOptions manifest = read;
  manifest.load_photos = false;
  manifest.load_truth = false;
  auto set = io::read_set(folder, manifest);
  if (!set) return set.error();
  if (mask.size() != set->size)
    return make_error(option + " " + file + " is " + std::to_string(mask.cols) + "x" + std::to_string(mask.rows) +
                      ", the set is " + std::to_string(set->size.width) + "x" + std::to_string(set->size.height));
  if (cv::countNonZero(mask > 127) == 0) return make_error(option + " " + file + " marks no object pixel (all dark)");
  return {};
}

int run(const TransferArgs& a) {
  auto look = repaint::parse_look(a.look);
  if (!look) return report.usage("--look: " + look.message());
  // the default transfer the viewer runs too, then the flags
  pipeline::TransferOptions options = pipeline::default_transfer_options(*look);
  auto method = match::parse_method(a.method);
  if (!method) return report.usage(method.message());
  if (*method == match::Method::combined && (a.feature != "normals" || a.patch != 1))
    return report.usage("--method combined compares normals, shading and colour over its own patches: drop --feature and "
                "--patch, or pick a method that takes them (coherent, flann, patchmatch ...)");
  auto feature = match::parse_feature(a.feature);
  if (!feature) return report.usage(feature.message());
  options.look_options.normal_smoothing = a.look_smoothing;
  options.look_options.ratio_headroom = a.look_headroom;
  options.look_options.seam_feather = a.look_feather;
  options.match.method = *method;
  options.match.feature = *feature;
  options.match.patch = a.patch;
  options.match.candidates = a.candidates;
  options.match.threshold = a.threshold;
  options.match.iterations = a.iterations;
  options.match.coherent_threshold =
      a.coherent_threshold ? *a.coherent_threshold : pipeline::default_match_options(*look).coherent_threshold;
  options.match.uniformity = a.uniformity;
  options.match.coherent_smooth = a.coherent_smooth;
  options.match.coherent_guide = a.coherent_guide;
  options.match.coherent_grow = !a.no_grow;
  options.match.seed = a.seed;
  options.match.threads = a.threads;
  options.match.fast = !a.faithful;
  options.truth_normals = a.truth_normals;
  options.blend = a.blend;
  options.blend_guide = a.blend_guide;
  options.scale = a.scale;
  options.look_floor = a.look_floor;
  // metrics.json's look only when asked (issue 48: at 5600x3750 it was 12 s of 59)
  options.look_figures = a.figures || a.look_floor;
  options.keep_pictures = false;  // painted and written one at a time (write_transfer with the pair)
  options.look_when_written = true;  // and the look measured from them then, each painted once
  // the full-resolution map refined from one made at the live view's width
  // (issue 42: refine, don't recompute); a set no wider is matched as it is
  options.refine_from_width = io::ReducedOptions{}.width;
  if (auto s = options.check(); !s) return report.usage(s.message());
  repaint::RtiExportOptions rti_options;
  std::optional<repaint::HshExportOptions> hsh_options;
  if (a.rti_format == "rgb") {
    rti_options.format = repaint::PtmFormat::rgb;
  } else if (a.rti_format == "hsh") {
    hsh_options = repaint::HshExportOptions{.order = a.hsh_order};
    if (auto s = hsh_options->check(); !s) return report.usage("--hsh-order: " + s.message());
  } else if (a.rti_format != "lrgb" && a.rti_format != "ptm") {
    return report.usage("--rti-format must be lrgb (or ptm), rgb or hsh, got \"" + a.rti_format + "\"");
  }
  if (a.hsh_order != 0 && !hsh_options && a.web.empty())
    return report.usage("--hsh-order goes with --rti-format hsh or --web");
  repaint::WebExportOptions web_options;
  web_options.max_side = a.web_size;
  web_options.order = a.hsh_order;
  if (auto s = web_options.check(); !s) return report.usage("--web-size: " + s.message());
  if (!a.web.empty())
    if (auto s = repaint::check_web_folder(a.web); !s) return report.usage("--web: " + s.message());

  const auto t_wall = std::chrono::steady_clock::now();
  pipeline::PrepareOptions prep = pipeline::default_prepare_options();
  auto photos = io::parse_photo_source(a.photos);
  if (!photos) return report.usage(photos.message());
  auto demosaic = io::parse_demosaic(a.demosaic);
  if (!demosaic) return report.usage(demosaic.message());
  prep.read.photos = *photos;
  prep.read.raw.demosaic = *demosaic;
  prep.read.raw.half_size = a.raw_half;
  prep.cache.enabled = !a.no_cache;
  prep.half_photos = true;  // photos in half floats, one set's float frames at a time (issue 42: memory)
  prep.cache.dir = a.cache_dir;
  if (!(a.cache_size_gb > 0)) return report.usage("--cache-size-gb must be > 0");
  prep.cache.max_bytes = static_cast<uint64_t>(a.cache_size_gb * (1ull << 30));
  if (auto s = prep.check(); !s) return report.usage(s.message());

  ProgressBar bar("transfer");
  Progress progress;
  progress.on_progress = [&bar](double f, const std::string& stage) { bar.update(f, stage); };
  Progress reading;
  reading.on_progress = [&bar](double f, const std::string& stage) { bar.update(0.4 * f, stage); };
  Progress matching;
  matching.on_progress = [&bar](double f, const std::string& stage) { bar.update(0.4 + 0.55 * f, stage); };
  std::vector<pipeline::SetReport> reports;
  Expected<pipeline::PreparedPair> pair = make_error("not prepared");
  // hand-drawn masks replace the segmentation and are part of the cache key
  if (!a.dst_mask.empty())
    if (auto st = read_mask("--dst-mask", a.dst_mask, a.dst, prep.read, prep.destination_mask); !st)
      return report.usage(st.message());
  if (!a.src_mask.empty())
    if (auto st = read_mask("--src-mask", a.src_mask, a.src, prep.read, prep.source_mask); !st)
      return report.usage(st.message());
  pipeline::LiveOptions live;
  if (a.live) {
    live.read.width = a.live_width;
    if (a.live_no_truth && a.truth_normals) return report.usage("--live-no-truth and --truth-normals: the one leaves out what the other needs");
    live.read.load_truth = !a.live_no_truth;
    auto decode = io::parse_reduced_decode(a.live_decode);
    if (!decode) return report.usage(decode.message());
    live.read.decode = *decode;
    live.destination_mask = prep.destination_mask;
    live.source_mask = prep.source_mask;
    if (auto s = live.check(); !s) return report.usage("--live-width / --live-decode: " + s.message());
    pair = pipeline::prepare_live_pair(a.dst, a.src, options, live, &reports, reading);
  } else {
    pair = pipeline::prepare_pair(a.dst, a.src, options, prep, &reports, reading);
  }
  if (!pair) return report.fail(pair.message());
  // an HSH order the destination's lamps cannot determine fails now, not after the transfer
  if (a.hsh_order > 0 && static_cast<size_t>(repaint::hsh_terms(a.hsh_order)) > pair->destination.lights.size())
    return report.usage("--hsh-order " + std::to_string(a.hsh_order) + " has " +
                        std::to_string(repaint::hsh_terms(a.hsh_order)) + " coefficients per colour, the destination has " +
                        std::to_string(pair->destination.lights.size()) + " lamps (at least as many are needed; 0 = automatic)");
  // the truth (simulated sets) released once the quality is measured: nothing after reads it (issue 48: memory)
  auto result = pipeline::transfer_releasing_truth(*pair, options, matching);
  if (!result) return report.fail(result.message());
  std::vector<cv::Vec3d> lamp_directions;
  for (const io::Light& l : pair->destination.lights) lamp_directions.push_back(l.direction);
  // the names the web page shows: the destination object's and the source's (its material)
  web_options.object = pair->destination.object.empty() ? std::filesystem::path(a.dst).filename().string()
                                                        : pair->destination.object;
  web_options.material = pair->source.object.empty() ? std::filesystem::path(a.src).filename().string()
                                                     : pair->source.object;
  Progress writing;
  writing.on_progress = [&bar](double f, const std::string& stage) { bar.update(0.95 + 0.04 * f, stage); };
  if (auto s = pipeline::write_transfer(*result, std::move(*pair), a.out, writing); !s) return report.fail(s.message());
  std::optional<repaint::RtiFit> rti;
  std::optional<repaint::WebExport> web;
  if (!a.rti.empty() || !a.web.empty()) {
    // read once: at full size for the file, else reduced to the page's size as read
    auto photos = read_result_photos(a.out, lamp_directions.size(), a.rti.empty() ? a.web_size : 0);
    if (!photos) return report.fail(photos.message());
    if (!a.rti.empty()) {
      bar.update(0.99, "fitting the relightable file");
      auto fit = export_rti(*photos, lamp_directions, a.rti, rti_options, hsh_options);
      if (!fit) return report.fail(fit.message());
      rti = *fit;
    }
    if (!a.web.empty()) {
      bar.update(0.99, "writing the web page");
      auto page = repaint::export_web(*photos, lamp_directions, a.web, web_options);
      if (!page) return report.fail(page.message());
      web = *page;
    }
  }
  bar.update(0.99, "storing the sets' results in the cache");
  const Status cached = pipeline::finish_cache_writes();  // not fatal: the next run recomputes
  bar.done();
  if (!cached) std::fprintf(stderr, "veneer transfer: warning: %s\n", cached.message().c_str());
  // metrics.json: how the sets were read (cache hit or miss, RAW or developed) and the wall time.
  auto metrics = nlohmann::json::parse(result->metrics_json, nullptr, false);
  if (metrics.is_object()) {
    metrics["io"] = nlohmann::json::parse(pipeline::reports_json(reports));
    if (!a.dst_mask.empty()) metrics["io"]["dst_mask"] = a.dst_mask;
    if (!a.src_mask.empty()) metrics["io"]["src_mask"] = a.src_mask;
    if (a.live) {
      // what the live map was made from: its width and each set's reduced decode
      metrics["live"] = {{"live", true},
                         {"width", a.live_width},
                         {"decode_asked", a.live_decode},
                         {"destination_decode", reports.size() > 0 ? reports[0].photos_from : ""},
                         {"source_decode", reports.size() > 1 ? reports[1].photos_from : ""}};
    } else {
      metrics["io"]["raw_half_size"] = a.raw_half;
      metrics["io"]["demosaic"] = a.demosaic;
    }
    if (rti) {
      metrics["rti"] = nlohmann::json::parse(rti->json());
      metrics["rti"]["file"] = a.rti;
    }
    if (web) {
      metrics["web"] = nlohmann::json::parse(web->json());
      metrics["web"]["folder"] = a.web;
    }
    metrics["timings"]["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_wall).count();
    if (auto s = report.folder(a.out); !s) return report.fail(s.message());  // made by write_transfer
    if (auto s = report.json("metrics.json", metrics); !s) return report.fail(s.message());
  }
  for (const auto& r : reports)
    std::printf("%s: %s, photos from %s, %.2f s\n", r.folder.c_str(),
                r.checksum.empty() ? "cache off" : (r.cache_hit ? "cache hit" : "cache miss"), r.photos_from.c_str(),
                r.total_s);

  std::printf("transfer %s -> %s: %s %s %dx%d, map written to %s\n", a.src.c_str(), a.dst.c_str(), a.method.c_str(),
              a.feature.c_str(), a.patch, a.patch, a.out.c_str());
  if (rti)
    std::printf("  relightable file %s (%s, exposure %.3g): residual %.2f levels RMS, p99 %.2f (the photos spread %.2f)\n",
                a.rti.c_str(), rti->format_label().c_str(), rti->exposure, rti->rms, rti->p99,
                rti->photo_spread);
  if (web)
    std::printf("  web page %s/index.html: the look %dx%d, HSH %d terms, %.2f MB in all (send the whole folder; it "
                "opens by double click, with no network)\n",
                a.web.c_str(), web->size.width, web->size.height, web->terms, web->folder_bytes / 1e6);
  if (a.scale < 1)
    std::printf("  computed at %.2fx (--scale): the map and the pictures are %dx%d, smaller than the sets\n", a.scale,
                result->map.xy.cols, result->map.xy.rows);
  if (result->quality) {
    const auto& g = *result->quality;
    std::printf("  coverage %.1f %%", 100 * g.coverage);
    if (g.normal_mean_deg) std::printf(", normal agreement %.2f deg mean / %.2f deg p95", *g.normal_mean_deg, *g.normal_p95_deg);
    std::printf(", coherence %.1f %%, reuse max %d, source used %.1f %%", 100 * g.coherence, g.reuse_max,
                100 * g.source_used);
    if (g.psnr_db) std::printf(", relight PSNR %.2f dB", *g.psnr_db);
    if (g.psnr_lit_db) std::printf(" (%.2f dB outside cast shadows)", *g.psnr_lit_db);
    std::printf("\n");
  }
  return 0;
}

}  // namespace
}  // namespace veneer::cli

VENEER_ARGS_COMMAND(transfer, veneer::cli::TransferArgs,
                    "correspondence map + destination repainted with the source's look") {
  cmd->add_option("--dst", args->dst, "destination image set (folder)")->required();
  cmd->add_option("--src", args->src, "source image set (folder)")->required();
  cmd->add_option("--dst-mask", args->dst_mask,
                  "the destination's object mask, a PNG of its size (pixels above 127 are the object), instead of "
                  "the automatic segmentation; e.g. drawn by hand in veneer-viewer");
  cmd->add_option("--src-mask", args->src_mask, "the source's object mask, as --dst-mask");
  cmd->add_option("--out", args->out, "output folder (map.pfm, map.png, result_*.png, reuse.png, metrics.json)")
      ->required();
  cmd->add_option("--method", args->method,
                  "combined (the default: finds the motion when the destination is the source moved, scaled or "
                  "cropped, else coherent chunks of the nearest normals; uses normals and photos, --feature is "
                  "ignored) | coherent | linear | flann | candidates | patchmatch | regiongrow | baseline");
  cmd->add_option("--look", args->look,
                  "how the pictures are painted: shaded (the default: the source's texture carried whole through "
                  "the map, each lamp shading it as it shades the destination's own shape, the source's gloss "
                  "placed where the destination's normals put the highlights) | copy (each lamp's source photo "
                  "pasted through the map and blended, the thesis's repaint; --blend, --blend-guide)");
  cmd->add_option("--look-smoothing", args->look_smoothing,
                  "--look shaded: the normals smoothed over this Gaussian sigma, px, for the coarse shading moved "
                  "from the source's normals to the destination's, 0..64 (default 4; the source's relief finer "
                  "than it stays its texture, coarser is re-shaded; 0 re-shades all relief: the source gives only its "
                  "colour and gloss)");
  cmd->add_option("--look-headroom", args->look_headroom,
                  "--look shaded: a lamp's shading ratio at most this x the Lambert model's, 1..100 (default 2; "
                  "smaller keeps pixels whose median lamp is in a cast shadow from blowing up, at some shading error)");
  cmd->add_option("--look-feather", args->look_feather,
                  "--look shaded: spread the texture's steps at chunk seams over about this many px (screened "
                  "Poisson), 0..64 (default 0 = off: the fine detail then follows the source through the map less)");
  cmd->add_option("--feature", args->feature, "normals | intensities (default normals)");
  cmd->add_option("--patch", args->patch, "patch side 1, 3, 5 or 7 (default 1)");
  cmd->add_option("--candidates", args->candidates, "K for candidates, 1..100 (default 10)");
  cmd->add_option("--threshold", args->threshold, "regiongrow threshold >= 0 (default 0.05; 0 = direct matching)");
  cmd->add_option("--iterations", args->iterations, "patchmatch iterations (default 5)");
  cmd->add_option("--coherent-threshold", args->coherent_threshold,
                  "coherent: normal error |dn| a chunk may make, >= 0 (default 0.6 with --look shaded, whose "
                  "shading does not come from the chunks; 0.10, about 6 degrees, with --look copy; larger = "
                  "larger chunks, more texture kept whole, with --look copy less exact shading; with --feature "
                  "intensities converted by the destination's change of intensities per change of normal)");
  cmd->add_option("--coherent-smooth", args->coherent_smooth,
                  "coherent: cost of a seam between two chunks, in coherent thresholds, >= 0 (default 2; 0 = "
                  "chunks only; larger = fewer seams, less exact shading)");
  cmd->add_option("--coherent-guide", args->coherent_guide,
                  "coherent on normals: match against the source's normals smoothed over this many px, 0..32 "
                  "(default 0 = off; 3-6 copies a bumpy source's relief -- dimples, grain -- whole, in larger "
                  "chunks, at the cost of agreement with its fine normals)");
  cmd->add_option("--uniformity", args->uniformity,
                  "coherent, patchmatch: penalty for reusing the same source pixel, >= 0 (default 0 = off)");
  cmd->add_flag("--no-grow", args->no_grow, "coherent: do not grow chunks into the pixels no chunk took");
  cmd->add_option("--blend", args->blend,
                  "repaint: blend the chunks meeting at a seam over this radius, 0..16 px (default 2: softens "
                  "seams and speckle, texture inside chunks stays sharp; 0 = each pixel its own source pixel, "
                  "as the thesis)");
  cmd->add_option("--blend-guide", args->blend_guide,
                  "repaint: blend only what fits -- each chunk's proposal weighed by how well its source normal "
                  "fits the destination's, fall-off |dn|, 0..2 (default 0.1, about 6 degrees; keeps outlines "
                  "such as a leg in front of the body sharp; 0 = plain Gaussian blend)");
  cmd->add_option("--seed", args->seed, "random seed (patchmatch, coherent)");
  cmd->add_option("--threads", args->threads, "threads, 0 = all cores");
  cmd->add_option("--scale", args->scale, "resize both sets first, (0, 1] (default 1)");
  cmd->add_flag("--faithful", args->faithful, "use the thesis's code paths, never the fast engine");
  cmd->add_flag("--truth-normals", args->truth_normals, "match on truth/ normals and masks (simulated sets)");
  cmd->add_flag("--figures", args->figures,
                "also measure the look into metrics.json's look: per-lamp shading error and texture_corr against "
                "the destination's own photos, and on simulated pairs against the truth look rendered once "
                "(off by default: at 5600x3750 it costs a fifth of the transfer)");
  cmd->add_flag("--look-floor", args->look_floor,
                "metrics.json's look (as --figures, which it implies): also the "
                "floor, the `linear` map's pixel copy scored the same way, and shading / floor (a second match "
                "and repaint)");
  cmd->add_option("--photos", args->photos,
                  "auto | raw | developed: the sets' RAW files (linear, LibRaw) or their PNG/JPEG photos (default "
                  "auto = RAW where every photo has one)");
  cmd->add_flag("--raw-half", args->raw_half, "decode RAW files at half size (one pixel per 2x2 Bayer cell, ~4x faster)");
  cmd->add_option("--demosaic", args->demosaic,
                  "RAW interpolation: mhc (the default: ours, on the mosaic LibRaw unpacks, in parallel) | LibRaw's dcb | ahd | ppg | vng | dht | aahd | bilinear");
  cmd->add_option("--rti", args->rti,
                  "also write the repainted destination as a relightable file (a PTM or, with --rti-format hsh, an "
                  "HSH .rti; RTIViewer, Relight), fitted to "
                  "the repainted photos under the destination's lamps; its residual goes to stdout and metrics.json");
  cmd->add_option("--rti-format", args->rti_format,
                  "the relightable file's layout: lrgb (a PTM: luminance polynomial + colour, the default; also "
                  "'ptm') | rgb (a PTM, a polynomial per colour) | hsh (an HSH .rti: hemispherical harmonics per "
                  "colour, --hsh-order)");
  cmd->add_option("--hsh-order", args->hsh_order,
                  "--rti-format hsh and --web: 1, 2 or 3 (1, 4 or 9 coefficients per colour; at least as many lamps as "
                  "coefficients); 0 = automatic, the highest the lamps determine (7 lamps: 2)")
      ->capture_default_str();
  cmd->add_option("--web", args->web,
                  "also write the repainted destination as a web page into this folder: index.html opens by "
                  "double click in a browser with no network, dragging moves the light; the look is the HSH fit "
                  "of the repainted photos (--hsh-order) in Relight's web layout (info.json, plane_K.jpg: "
                  "OpenLIME and Relight open the folder too)");
  cmd->add_option("--web-size", args->web_size,
                  "--web: the look's longer side at most this many px, reduced by area averaging; 0 = full size "
                  "(default 2048: a phone's screen, every WebGL device's textures, a few MB)")
      ->capture_default_str();
  cmd->add_flag("--no-cache", args->no_cache, "neither read nor write the per-set result cache");
  cmd->add_option("--cache-dir", args->cache_dir, "result cache folder (default $XDG_CACHE_HOME/veneer or ~/.cache/veneer)");
  cmd->add_option("--cache-size-gb", args->cache_size_gb, "result cache size cap, GiB (default 4; least recently used go first)");
  cmd->add_flag("--live", args->live,
                "live first: only the map at the live view's size (--live-width), from reduced decodes (RAW "
                "mosaics binned, JPEGs decoded small, RAW previews), with normals and masks at that size, its "
                "own metrics.json; no result cache");
  cmd->add_option("--live-width", args->live_width,
                  "--live: the map's width, px, 64..8192 (default 1280, the live view's; a narrower set keeps its size)");
  cmd->add_flag("--live-no-truth", args->live_no_truth,
                "--live: leave the sets' truth/ unread (simulated sets: quality then measured against the "
                "segmentation, no normal agreement); reading it at 5600x3750 costs about as much as the photos");
  cmd->add_option("--live-decode", args->live_decode,
                  "--live: auto | raw-binned | jpeg-reduced | raw-preview | developed (default auto: per set, the "
                  "JPEG at 1/2-1/8 when the photos are JPEGs, else the RAW mosaic binned, else the photos resized)");
  return [args] { return veneer::cli::run(*args); };
}
