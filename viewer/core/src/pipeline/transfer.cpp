// Appearance transfer end to end (transfer.hpp).
#include "veneer/pipeline/transfer.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <future>
#include <mutex>
#include <optional>
#include <limits>
#include <type_traits>
#include <utility>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "veneer/eval/look.hpp"
#include "veneer/eval/metrics.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/match/fast.hpp"
#include "veneer/match/map_file.hpp"
#include "veneer/match/refine.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/ps/segmentation.hpp"
#include "veneer/repaint/repaint.hpp"
#include "veneer/util/log.hpp"
#include "transfer_look.hpp"

namespace veneer::pipeline {

using eval::evaluate;
using eval::Quality;
using eval::relight;
using eval::relight_measurable;
using eval::reuse_counts;
using match::object_mask;
using match::prepare_object;
using match::scale_set;
using match::write_map;
using repaint::confidence_picture;
using repaint::map_picture;
using repaint::median_photo;
using repaint::repaint_blended;
using repaint::repaint_planned;
using match::Feature;
using match::parse_feature;
using match::parse_method;
using repaint::reuse_picture;
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

Progress sub_progress(const Progress& p, double from, double to) { return p.part(from, to); }

nlohmann::json quality_json(const Quality& q) {
  nlohmann::json j;
  j["destination_pixels"] = q.destination_pixels;
  j["mapped_pixels"] = q.mapped_pixels;
  j["coverage"] = q.coverage;
  j["background_hits"] = q.background_hits;
  if (q.normal_mean_deg) j["normal_mean_deg"] = *q.normal_mean_deg;
  if (q.normal_p95_deg) j["normal_p95_deg"] = *q.normal_p95_deg;
  j["coherence"] = q.coherence;
  j["reuse_max"] = q.reuse_max;
  j["source_used"] = q.source_used;
  if (q.psnr_db) j["relight_psnr_db"] = *q.psnr_db;
  if (q.psnr_lit_db) j["relight_psnr_lit_db"] = *q.psnr_lit_db;
  return j;
}

// A photo as CV_32F: itself when it is, else widened (photos kept as half
// floats, PrepareOptions::half_photos).
cv::Mat as_float(const cv::Mat& photo) {
  if (photo.empty() || photo.depth() == CV_32F) return photo;
  cv::Mat out;
  photo.convertTo(out, CV_32F);
  return out;
}

// `view` at `size` with float photos, for the matcher: normals averaged and
// made unit again, the mask where most of a pixel is object, each photo
// widened and reduced one at a time. At its own size only the photos change.
match::ObjectView float_view(const match::ObjectView& view, cv::Size size) {
  match::ObjectView out;
  out.lamps = view.lamps;
  const bool same = size == view.mask.size();
  if (same) {
    out.normals = view.normals;
    out.mask = view.mask;
  } else {
    cv::resize(view.normals, out.normals, size, 0, 0, cv::INTER_AREA);
    cv::Mat mask;
    cv::resize(view.mask, mask, size, 0, 0, cv::INTER_AREA);
    out.mask = mask > 127;
    out.normals.forEach<cv::Vec3f>([&](cv::Vec3f& n, const int* at) {
      const float l = static_cast<float>(cv::norm(n));
      n = out.mask.at<uchar>(at[0], at[1]) && l > 1e-6f ? n / l : cv::Vec3f(0, 0, 0);
    });
  }
  for (const cv::Mat& photo : view.images) {
    cv::Mat f = as_float(photo);
    if (!same) cv::resize(f, f, size, 0, 0, cv::INTER_AREA);
    out.images.push_back(f);
  }
  return out;
}

bool float_photos(const match::ObjectView& view) {
  return std::all_of(view.images.begin(), view.images.end(), [](const cv::Mat& m) { return m.depth() == CV_32F; });
}

}  // namespace

Status TransferOptions::check() const {
  if (auto s = match.check(); !s) return s;
  if (!(scale > 0 && scale <= 1)) return make_error("scale must be in (0, 1], got " + std::to_string(scale));
  if (blend < 0 || blend > 16) return make_error("blend radius must be in 0..16 px, got " + std::to_string(blend));
  if (!(blend_guide >= 0 && blend_guide <= 2))
    return make_error("blend_guide must be in [0, 2] (|dn|; 0 = off), got " + std::to_string(blend_guide));
  if (refine_from_width != 0 && (refine_from_width < 64 || refine_from_width > 8192))
    return make_error("refine_from_width must be 0 (off) or 64..8192 px, got " + std::to_string(refine_from_width));
  if (look == repaint::Look::shaded) return look_options.check();
  return {};
}



MatchOptions default_match_options(repaint::Look look) {
  MatchOptions m;
  m.method = match::Method::combined;
  if (look == repaint::Look::shaded) m.coherent_threshold = 0.6;
  return m;
}

TransferOptions default_transfer_options(repaint::Look look) {
  TransferOptions o;
  o.look = look;
  o.match = default_match_options(look);
  return o;
}

Expected<PreparedPair> prepare_pair(const io::ImageSet& destination_in, const io::ImageSet& source_in,
                                    const TransferOptions& options, const Progress& progress) {
  if (auto s = options.check(); !s) return s.error();
  PreparedPair pair;
  pair.destination = destination_in;
  pair.source = source_in;
  pair.scale = options.scale;
  pair.truth_normals = options.truth_normals;
  scale_set(pair.destination, options.scale);
  scale_set(pair.source, options.scale);
  auto dst = prepare_object(pair.destination, options.truth_normals, sub_progress(progress, 0.0, 0.5));
  if (!dst) return make_error("destination: " + dst.message());
  auto src = prepare_object(pair.source, options.truth_normals, sub_progress(progress, 0.5, 1.0));
  if (!src) return make_error("source: " + src.message());
  pair.dst = std::move(*dst);
  pair.src = std::move(*src);
  pair.destination_median = median_photo(pair.dst.view.images);
  pair.source_median = median_photo(pair.src.view.images);
  return pair;
}

namespace {

// metrics.json's "options" besides method and feature, one list for the
// writer and the reader: f(key, member) for each.
template <class Options, class F>
void for_each_option(Options& t, F&& f) {
  auto& m = t.match;
  f("patch", m.patch), f("candidates", m.candidates), f("threshold", m.threshold), f("iterations", m.iterations);
  f("coherent_threshold", m.coherent_threshold), f("uniformity", m.uniformity), f("coherent_grow", m.coherent_grow);
  f("coherent_smooth", m.coherent_smooth), f("coherent_sweeps", m.coherent_sweeps);
  f("coherent_guide", m.coherent_guide), f("fast", m.fast), f("seed", m.seed), f("truth_normals", t.truth_normals);
  f("scale", t.scale), f("blend", t.blend), f("blend_guide", t.blend_guide);
  f("refine_from_width", t.refine_from_width);
  auto& l = t.look_options;
  f("look_normal_smoothing", l.normal_smoothing), f("look_seam_feather", l.seam_feather);
  f("look_source_gloss", l.source_gloss), f("look_destination_gloss", l.destination_gloss);
}

// metrics.json's "options" (blend_guide as the pictures were blended: 0 plain)
nlohmann::json options_json(const TransferOptions& options, double blend_guide) {
  nlohmann::json j = {{"method", method_name(options.match.method)},
                      {"feature", feature_name(options.match.feature)},
                      {"look", repaint::look_name(options.look)}};
  TransferOptions written = options;
  written.blend_guide = blend_guide;
  for_each_option(std::as_const(written), [&](const char* key, const auto& value) { j[key] = value; });
  return j;
}

// The blend weighs each proposal by its fit to the normals, when the map was
// matched on them. (A map matched on intensities is not guided by normals:
// on bull <- sphere-red-gloss that re-matched it by normals, 17.4 dB of
// relighting PSNR against 18.3 blended plain and 17.9 not blended.) Empty
// normals when the blend is plain.
fast::BlendGuide blend_guide_of(const PreparedPair& pair, const TransferOptions& options) {
  const bool guided = options.blend > 0 && options.blend_guide > 0 && options.match.feature == Feature::normals &&
                      !pair.dst.view.normals.empty() && !pair.src.view.normals.empty();
  if (!guided) return {{}, {}, options.blend_guide};
  return {pair.dst.view.normals, pair.src.view.normals, options.blend_guide};
}

}  // namespace

Expected<std::shared_ptr<const fast::BlendPlan>> blend_plan_for(const PreparedPair& pair,
                                                                const TransferOptions& options, const Map& map) {
  if (auto s = options.check(); !s) return s.error();
  if (options.blend == 0) return std::shared_ptr<const fast::BlendPlan>();
  const cv::Size want = pair.dst.view.mask.size();
  if (map.xy.size() != want || map.xy.type() != CV_32FC2)
    return make_error("the map is " + std::to_string(map.xy.cols) + "x" + std::to_string(map.xy.rows) +
                      ", the prepared destination " + std::to_string(want.width) + "x" + std::to_string(want.height));
  const fast::BlendGuide guide = blend_guide_of(pair, options);
  auto made = fast::blend_plan(map, {}, pair.src.view.mask, options.blend, 0,
                               guide.destination.empty() ? nullptr : &guide);
  if (!made) return made.error();
  return std::shared_ptr<const fast::BlendPlan>(std::make_shared<const fast::BlendPlan>(std::move(*made)));
}

Expected<std::shared_ptr<const repaint::ShadedLook>> shaded_look(const PreparedPair& pair,
                                                                 const TransferOptions& options, const Map& map,
                                                                 const Progress& progress) {
  if (auto s = options.check(); !s) return s.error();
  std::vector<cv::Vec3d> dst_lamps, src_lamps;
  for (const io::Light& l : pair.destination.lights) dst_lamps.push_back(l.direction);
  for (const io::Light& l : pair.source.lights) src_lamps.push_back(l.direction);
  auto look = repaint::ShadedLook::make({pair.dst.view, dst_lamps}, {pair.src.view, src_lamps}, map,
                                        options.look_options, progress);
  if (!look) return look.error();
  return std::shared_ptr<const repaint::ShadedLook>(std::make_shared<const repaint::ShadedLook>(std::move(*look)));
}

Expected<std::shared_ptr<const repaint::LiveLook>> live_look(const PreparedPair& pair, const TransferOptions& options,
                                                             const Map& map,
                                                             std::shared_ptr<const repaint::ShadedLook> still,
                                                             const repaint::LiveLookOptions& live_options,
                                                             const Progress& progress) {
  if (!still) {
    auto made = shaded_look(pair, options, map, progress.part(0.0, 0.6));
    if (!made) return made.error();
    still = *made;
  }
  std::vector<cv::Vec3d> dst_lamps, src_lamps, positions;
  for (const io::Light& l : pair.destination.lights) dst_lamps.push_back(l.direction);
  for (const io::Light& l : pair.source.lights) {
    src_lamps.push_back(l.direction);
    if (l.position_m) positions.push_back(*l.position_m);
  }
  if (positions.size() != src_lamps.size()) positions.clear();  // distant lamps, or not every one placed
  const io::CameraInfo& sc = pair.source.camera;
  const cv::Vec3d source_camera = sc.focal_px > 0 ? cv::Vec3d(sc.focal_px, sc.cx, sc.cy) : cv::Vec3d(0, 0, 0);
  auto live = repaint::LiveLook::make(*still, {pair.dst.view, dst_lamps}, {pair.src.view, src_lamps, source_camera}, map, positions,
                                      live_options, progress.part(0.6, 1.0));
  if (!live) return live.error();
  return std::shared_ptr<const repaint::LiveLook>(std::make_shared<const repaint::LiveLook>(std::move(*live)));
}

namespace {

// transfer() of a prepared pair, from `given` when not null (else the map is
// computed); timings' total_s counts from t_all.
Expected<TransferResult> transfer_from(const PreparedPair& pair, const TransferOptions& options, const Map* given,
                                       const Progress& progress, Clock::time_point t_all,
                                       PreparedPair* release_truth = nullptr) {
  if (auto s = options.check(); !s) return s.error();
  if (options.scale != pair.scale || options.truth_normals != pair.truth_normals)
    return make_error("the prepared pair was made with scale " + std::to_string(pair.scale) + " and truth normals " +
                      (pair.truth_normals ? "on" : "off") + ", the options ask for scale " +
                      std::to_string(options.scale) + " and truth normals " + (options.truth_normals ? "on" : "off"));
  const io::ImageSet& destination = pair.destination;
  const io::ImageSet& source = pair.source;
  const PreparedObject* dst = &pair.dst;
  const PreparedObject* src = &pair.src;
  nlohmann::json timings;
  timings["segment_destination_s"] = dst->segment_seconds;
  timings["normals_destination_s"] = dst->normals_seconds;
  timings["segment_source_s"] = src->segment_seconds;
  timings["normals_source_s"] = src->normals_seconds;

  auto t0 = Clock::now();
  TransferResult result;
  std::optional<double> made_at_coherence;  // the map's coherence where it was made, when refined
  cv::Size made_at;
  if (given) {
    const cv::Size want = dst->view.mask.size();
    if (given->xy.size() != want || given->xy.type() != CV_32FC2 || given->distance.size() != want)
      return make_error("the map given is " + std::to_string(given->xy.cols) + "x" + std::to_string(given->xy.rows) +
                        ", the prepared destination " + std::to_string(want.width) + "x" +
                        std::to_string(want.height));
    result.map = *given;
    result.map_given = true;
    timings["match_s"] = 0.0;
    timings["map_given"] = true;
  } else if (options.refine_from_width > 0 && dst->view.mask.cols > options.refine_from_width) {
    // Refine, don't recompute (issue 42): the map made at a working width,
    // then continued to full resolution by the normals.
    const double k = static_cast<double>(options.refine_from_width) / dst->view.mask.cols;
    auto reduced = [k](cv::Size s) {
      return cv::Size(std::max(1, static_cast<int>(std::lround(s.width * k))),
                      std::max(1, static_cast<int>(std::lround(s.height * k))));
    };
    const match::ObjectView coarse_dst = float_view(dst->view, reduced(dst->view.mask.size()));
    const match::ObjectView coarse_src = float_view(src->view, reduced(src->view.mask.size()));
    auto coarse = compute_map(coarse_dst, coarse_src, options.match, sub_progress(progress, 0.0, 0.6));
    if (!coarse) return coarse.error();
    auto refined = match::refine_map(*coarse, dst->view, src->view, {}, sub_progress(progress, 0.6, 0.85));
    if (!refined) return refined.error();
    refined->motion = coarse->motion;
    timings["match_s"] = since(t0);
    timings["match_made_at"] = {coarse_dst.mask.cols, coarse_dst.mask.rows};
    result.map = std::move(*refined);
    // the coherence of the map as it was made (at full resolution each pixel
    // picks its nearest normal around the continued match: a chunk's pixels
    // no longer continue each other exactly, though it is the same chunk)
    made_at_coherence = eval::evaluate(*coarse, coarse_dst.mask, coarse_src.mask).coherence;
    made_at = coarse_dst.mask.size();
  } else {
    // Half-float photos are widened for the matcher only when it reads them as
    // float (the intensities feature): matching normals reads no photo, and
    // `combined` widens the ones it reads as it reads them (issue 48: widening
    // every photo took most of the fast engine's FLANN map on the demo pair).
    const bool widen = options.match.feature == match::Feature::intensities &&
                       !(float_photos(dst->view) && float_photos(src->view));
    auto map = !widen ? compute_map(dst->view, src->view, options.match, sub_progress(progress, 0.0, 0.85))
                   : compute_map(float_view(dst->view, dst->view.mask.size()),
                                 float_view(src->view, src->view.mask.size()), options.match,
                                 sub_progress(progress, 0.0, 0.85));
    if (!map) return map.error();
    timings["match_s"] = since(t0);
    result.map = std::move(*map);
  }
  // The quality against the truth measured now, and the truth (both sets'
  // normals and masks, 0.5 GB at 5600x3750) released before the look is made
  // (issue 48: held through it, it made the transfer's peak), when the caller
  // gave the pair up to that and nothing later reads the truth.
  std::optional<Quality> early_quality;
  double early_quality_s = 0;
  if (release_truth && destination.truth.present() && source.truth.present() && !options.look_figures &&
      !options.look_floor && !relight_measurable(source.scene)) {
    const auto t_q = Clock::now();
    early_quality = evaluate(result.map, destination.truth.mask, source.truth.mask, destination.truth.normals,
                             source.truth.normals);
    early_quality_s = since(t_q);
    release_truth->destination.truth = io::Truth{};
    release_truth->source.truth = io::Truth{};
  }
  result.match_seconds = timings["match_s"].get<double>();
  result.match_options = options.match;
  result.source_size = source.size;
  t0 = Clock::now();
  progress.report(0.9, "repaint");
  const fast::BlendGuide guide = blend_guide_of(pair, options);
  const bool guided = !guide.destination.empty();
  const fast::BlendGuide* g = guided ? &guide : nullptr;
  // every photo through the same map: the blend's weights worked out once;
  // not for a shaded look whose pictures are painted later (write_transfer
  // paints them by the look): at 5600x3750 a plan is up to 25 terms a pixel
  const bool needs_plan = options.look != repaint::Look::shaded || options.keep_pictures;
  auto planned = needs_plan ? blend_plan_for(pair, options, result.map)
                            : Expected<std::shared_ptr<const fast::BlendPlan>>(std::shared_ptr<const fast::BlendPlan>());
  if (!planned) return make_error("repaint: " + planned.message());
  const std::shared_ptr<const fast::BlendPlan> plan = *planned;
  result.blend = plan;
  auto paint = [&](const cv::Mat& photo, const cv::Mat& backdrop) -> Expected<cv::Mat> {
    if (!plan) return repaint::repaint(result.map, as_float(photo), as_float(backdrop));
    return repaint_planned(*plan, as_float(photo), as_float(backdrop));
  };
  if (options.look == repaint::Look::shaded) {
    auto look = shaded_look(pair, options, result.map, sub_progress(progress, 0.85, 0.9));
    if (!look) return make_error("repaint: " + look.message());
    result.look = std::move(*look);
    timings["shaded_look_s"] = since(t0);
  }
  const size_t lamps = std::min(src->view.images.size(), dst->view.images.size());
  for (size_t i = 0; options.keep_pictures && i < (result.look ? dst->view.images.size() : lamps); ++i) {
    auto painted = result.look ? result.look->paint(i, dst->view.images[i]) : paint(src->view.images[i], dst->view.images[i]);
    if (!painted) return make_error("repaint: " + painted.message());
    result.repainted.push_back(std::move(*painted));
  }
  result.source_median = pair.source_median;
  auto median = result.look ? result.look->median(dst->view.images) : paint(pair.source_median, pair.destination_median);
  if (!median) return make_error("repaint: " + median.message());
  result.repainted_median = std::move(*median);
  result.reuse = reuse_counts(result.map, source.size);
  timings["repaint_s"] = since(t0);

  nlohmann::json j;
  j["destination"] = {{"id", destination.id}, {"scene", destination.scene}, {"size", {destination.size.width, destination.size.height}},
                      {"object_pixels", cv::countNonZero(dst->view.mask)}};
  j["source"] = {{"id", source.id}, {"scene", source.scene}, {"size", {source.size.width, source.size.height}},
                 {"object_pixels", cv::countNonZero(src->view.mask)}};
  j["options"] = options_json(options, guided ? options.blend_guide : 0.0);
  if (result.look) {
    j["repaint"] = {{"look", "shaded"},
                 {"means", "the source's texture through the map under the destination's shading per lamp, the "
                           "source's gloss lobe at the destination's normals (repaint/look.hpp)"},
                 {"source_gloss_exponent", result.look->source_exponent()},
                 {"destination_gloss_exponent", result.look->destination_exponent()},
                 {"seams_feathered", result.look->seams()}};
  } else {
    j["repaint"] = {{"look", "copy"}, {"means", "each lamp's source photo pasted through the map"}};
  }
  j["pictures"] = {{"result_light_NN.png, result_median.png",
                    "linear 16-bit RGB at the sets' photometric scale, as the sets' light_NN.png (no exposure or "
                    "gamma change)"},
                   {"map.png, reuse.png, relight_*.png", "8-bit sRGB pictures for viewing"},
                   {"confidence.png", "white = the match fits exactly, black = 4x the median match distance or "
                                      "more, or not mapped"}};
  if (early_quality || (destination.truth.present() && source.truth.present())) {
    t0 = Clock::now();
    Quality q = early_quality ? *early_quality
                              : evaluate(result.map, destination.truth.mask, source.truth.mask,
                                         destination.truth.normals, source.truth.normals);
    if (!early_quality && relight_measurable(source.scene)) {
      auto relit = relight(result.map, destination, source, destination.truth.mask, options.blend, g);
      if (relit) {
        q.psnr_db = relit->psnr_db;
        q.psnr_lit_db = relit->psnr_lit_db;
        result.relit = std::move(*relit);
      } else {
        j["relight_error"] = relit.message();
      }
    }
    if (made_at_coherence) q.coherence = *made_at_coherence;
    result.quality = q;
    j["quality"] = quality_json(q);
    j["quality"]["measured_against"] = "truth (simulated sets)";
    timings["quality_s"] = since(t0) + early_quality_s;
  } else {
    // Real sets: what can be measured without truth -- coverage of the
    // segmented object, coherence, and the agreement of the photometric
    // stereo normals at the matches.
    t0 = Clock::now();
    Quality q = evaluate(result.map, dst->view.mask, src->view.mask, dst->view.normals, src->view.normals);
    if (made_at_coherence) q.coherence = *made_at_coherence;
    j["quality"] = quality_json(q);
    j["quality"]["measured_against"] = "segmentation masks and photometric-stereo normals (no truth)";
    timings["quality_s"] = since(t0);
  }
  if (made_at_coherence)
    j["quality"]["coherence_measured_at"] = {{"size", {made_at.width, made_at.height}},
                                             {"means", "the map's coherence where it was made, before "
                                                       "match::refine_map continued it to full resolution"}};
  if (!options.look_figures && !options.look_floor) {
    // not asked for: nothing measured that is not written (issue 48)
  } else if (options.look_when_written && !options.keep_pictures && !options.look_floor) {
    result.look_pending = true;  // write_transfer(result, pair) measures it while it paints
  } else {
    // The look (eval/look.hpp): shading per lamp and texture, beside coverage and coherence.
    const nlohmann::json& qj = j["quality"];
    auto look = detail::look_block(pair, options, result, paint, qj.value("coverage", 0.0), qj.value("coherence", 0.0),
                                   sub_progress(progress, 0.92, 1.0));
    if (look) j["look"] = std::move(*look);
    else j["look_error"] = look.message();
  }
  if (result.map.motion.searched) {
    // Whether the destination was found to be the source moved (combined):
    // one motion of the whole object, or why not.
    const match::ObjectMotion& mo = result.map.motion;
    nlohmann::json mj = {{"found", mo.found}};
    if (mo.found) {
      const cv::Matx23d& a = mo.affine;
      mj["affine"] = {{a(0, 0), a(0, 1), a(0, 2)}, {a(1, 0), a(1, 1), a(1, 2)}};
      mj["affine_means"] = "source pixel = affine x (destination x, y, 1), at the scale the map was computed";
      mj["share_of_pixels"] = mo.share;
    } else {
      mj["why_not"] = mo.note;
    }
    j["motion"] = mj;
  }
  timings["total_s"] = since(t_all);
  j["timings"] = timings;
  result.metrics_json = j.dump(2);
  progress.report(1.0, "done");
  return result;
}

}  // namespace

Expected<TransferResult> transfer(const io::ImageSet& destination_in, const io::ImageSet& source_in,
                                  const TransferOptions& options, const Progress& progress) {
  const auto t_all = Clock::now();  // the total includes the preparation
  auto pair = prepare_pair(destination_in, source_in, options, sub_progress(progress, 0.0, 0.3));
  if (!pair) return pair.error();
  return transfer_from(*pair, options, nullptr, sub_progress(progress, 0.3, 1.0), t_all);
}

Expected<TransferResult> transfer(const PreparedPair& pair, const TransferOptions& options, const Progress& progress) {
  return transfer_from(pair, options, nullptr, progress, Clock::now());
}

Expected<TransferResult> transfer(const PreparedPair& pair, const TransferOptions& options, const Map& map,
                                  const Progress& progress) {
  return transfer_from(pair, options, &map, progress, Clock::now());
}

Expected<TransferResult> transfer_releasing_truth(PreparedPair& pair, const TransferOptions& options,
                                                  const Progress& progress) {
  return transfer_from(pair, options, nullptr, progress, Clock::now(), &pair);
}

std::string transfer_options_json(const TransferOptions& options) {
  return nlohmann::json{{"options", options_json(options, options.blend_guide)}}.dump(2);
}

Expected<TransferOptions> read_transfer_options(const std::filesystem::path& file) {
  auto bytes = io::read_file_bytes(file);
  if (!bytes) return bytes.error();
  return parse_transfer_options(*bytes, file.string());
}

Expected<TransferOptions> parse_transfer_options(std::string_view text, const std::string& name) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return make_error(name + ": not a JSON object");
  TransferOptions t;
  if (!j.contains("options")) return t;
  const nlohmann::json& o = j["options"];
  if (!o.is_object()) return make_error(name + ": \"options\" is not an object");
  std::string bad;  // the first key of the wrong type
  auto get = [&](const char* key, auto& into) {  // into: a member of t
    if (!o.contains(key) || !bad.empty()) return;
    using T = std::decay_t<decltype(into)>;
    const nlohmann::json& v = o[key];
    const bool fits = std::is_same_v<T, bool>          ? v.is_boolean()
                      : std::is_same_v<T, std::string> ? v.is_string()
                      : std::is_unsigned_v<T>          ? v.is_number_unsigned()
                      : std::is_integral_v<T>          ? v.is_number_integer()
                                                       : v.is_number();
    bool in_range = fits;
    if constexpr (std::is_integral_v<T> && !std::is_same_v<T, bool>) {
      if (fits && v.is_number_unsigned())
        in_range = v.get<uint64_t>() <= static_cast<uint64_t>(std::numeric_limits<T>::max());
      else if (fits)
        in_range = v.get<int64_t>() >= static_cast<int64_t>(std::numeric_limits<T>::min()) &&
                   v.get<int64_t>() <= static_cast<int64_t>(std::numeric_limits<T>::max());
    }
    if (!in_range) {
      bad = key;
      return;
    }
    into = v.get<T>();
  };
  std::string method = method_name(t.match.method), feature = feature_name(t.match.feature),
              look = repaint::look_name(t.look);
  get("method", method), get("feature", feature), get("look", look);
  for_each_option(t, get);
  if (!bad.empty()) return make_error(name + ": options." + bad + " has the wrong type or is out of range");
  auto me = parse_method(method);
  if (!me) return make_error(name + ": options.method: " + me.message());
  auto fe = parse_feature(feature);
  if (!fe) return make_error(name + ": options.feature: " + fe.message());
  auto lo = repaint::parse_look(look);
  if (!lo) return make_error(name + ": options.look: " + lo.message());
  t.match.method = *me, t.match.feature = *fe, t.look = *lo;
  if (auto s = t.check(); !s) return make_error(name + ": options: " + s.message());
  return t;
}

double map_scale(const Map& map, const io::ImageSet& destination) {
  return destination.size.width > 0 ? static_cast<double>(map.xy.cols) / destination.size.width : 1.0;
}

Expected<Quality> evaluate_sets(const Map& map, const io::ImageSet& destination_in, const io::ImageSet& source_in) {
  const double scale = map_scale(map, destination_in);
  if (!(scale > 0 && scale <= 1.0001))
    return make_error("the map is " + std::to_string(map.xy.cols) + " px wide but the destination set " +
                      std::to_string(destination_in.size.width));
  io::ImageSet destination = destination_in, source = source_in;
  if (std::abs(scale - 1.0) > 1e-9) {
    scale_set(destination, scale);
    scale_set(source, scale);
  }
  if (map.xy.size() != destination.size)
    return make_error("the map's size does not match the destination set's (scaled) size");
  if (destination.truth.present() && source.truth.present()) {
    Quality q = evaluate(map, destination.truth.mask, source.truth.mask, destination.truth.normals,
                         source.truth.normals);
    if (relight_measurable(source.scene)) {
      auto relit = relight(map, destination, source, destination.truth.mask);
      if (!relit) return make_error("relighting: " + relit.message());
      q.psnr_db = relit->psnr_db;
      q.psnr_lit_db = relit->psnr_lit_db;
    }
    return q;
  }
  auto dm = ps::segment(destination);
  if (!dm) return make_error("destination: segmentation: " + dm.message());
  auto sm = ps::segment(source);
  if (!sm) return make_error("source: segmentation: " + sm.message());
  return evaluate(map, dm->mask, sm->mask);
}


namespace {

// write_transfer's files; with `pair`, the per-lamp pictures are painted from
// its photos one at a time (each into its destination photo, then released).
Status write_files(const TransferResult& r, PreparedPair* pair, const std::filesystem::path& folder,
                   const Progress& progress, std::string* metrics_out = nullptr,
                   std::optional<detail::LookBegun> begun = std::nullopt,
                   const std::function<void()>& painted_all = {}) {
  std::string metrics = r.metrics_json;
  std::error_code ec;
  std::filesystem::create_directories(folder, ec);
  if (ec) return make_error("cannot create " + folder.string() + ": " + ec.message());
  // Every file is made and written at once (one task each, encoders on all
  // cores), each through a temporary and a rename but without an fsync of
  // its own; one fsync of the folder at the end, then metrics.json, synced,
  // last: a folder with a metrics.json holds the whole result.
  std::vector<std::function<Status()>> files;
  files.push_back([&] { return write_map(folder / "map.pfm", r.map, io::Sync::later); });
  files.push_back([&] { return io::write_picture(folder / "map.png", map_picture(r.map, r.source_size), io::Sync::later); });
  for (size_t i = 0; i < r.repainted.size(); ++i) {
    files.push_back([&, i] {
      char name[64];
      std::snprintf(name, sizeof name, "result_light_%02zu.png", i);
      // Linear 16-bit at the sets' own scale, as their light_NN.png: a
      // repainted photo and the photos it came from look alike side by side.
      return io::write_png16(folder / name, r.repainted[i], io::Sync::later);
    });
  }
  files.push_back([&] { return io::write_png16(folder / "result_median.png", r.repainted_median, io::Sync::later); });
  files.push_back(
      [&] { return io::write_picture(folder / "reuse.png", reuse_picture(r.reuse, r.source_median), io::Sync::later); });
  files.push_back([&] { return io::write_picture(folder / "confidence.png", confidence_picture(r.map), io::Sync::later); });
  if (r.relit) {
    files.push_back([&] {
      // one exposure for both, so that they compare
      cv::Mat both;
      cv::hconcat(r.relit->transferred, r.relit->reference, both);
      const cv::Mat pic = io::tonemap_picture(both);
      const int w = r.relit->transferred.cols;
      if (auto s = io::write_picture(folder / "relight_transferred.png", pic(cv::Rect(0, 0, w, pic.rows)).clone(),
                                 io::Sync::later);
          !s)
        return s;
      return io::write_picture(folder / "relight_reference.png", pic(cv::Rect(w, 0, w, pic.rows)).clone(), io::Sync::later);
    });
  }
  // The pictures painted from the pair's photos: one after another (each
  // painting is parallel within), each encoded and written on its own thread
  // while the next is painted (issue 48), so at most two are in memory at a time.
  std::vector<std::function<Expected<cv::Mat>()>> painted;
  // the look measured from the pictures as they are painted (look_pending):
  // each picture and its destination photo kept in grey, 1/3 of their bytes
  std::vector<cv::Mat> picture_greys, own_greys;
  if (!pair) begun.reset();
  if (pair) {
    const size_t lamps = r.look ? pair->dst.view.images.size()
                                : std::min(pair->src.view.images.size(), pair->dst.view.images.size());
    for (size_t i = 0; i < lamps; ++i) {
      if (begun) picture_greys.emplace_back(), own_greys.emplace_back();
      painted.push_back([&r, pair, i, &begun, &picture_greys, &own_greys]() -> Expected<cv::Mat> {
        cv::Mat& backdrop = pair->dst.view.images[i];
        const cv::Mat& photo = pair->src.view.images[i];
        cv::Mat out;
        if (r.look) {
          auto shaded = r.look->paint(i, backdrop);
          if (!shaded) return make_error("repaint: " + shaded.message());
          out = std::move(*shaded);
        } else if (r.blend) {
          out = as_float(backdrop);  // painted in place: the photo is released next
          if (auto s = fast::apply_blend(*r.blend, as_float(photo), out); !s)
            return make_error("repaint: " + s.message());
        } else {
          out = repaint::repaint(r.map, as_float(photo), as_float(backdrop));
        }
        if (begun) {
          picture_greys[i] = eval::look_gray(out);
          const bool own = i < pair->destination.images.size() && !pair->destination.images[i].empty();
          own_greys[i] = eval::look_gray(own ? pair->destination.images[i] : backdrop);
        }
        // this lamp's photos are done with: every copy of them goes
        pair->dst.view.images[i].release();
        pair->src.view.images[i].release();
        if (i < pair->destination.images.size()) pair->destination.images[i].release();
        if (i < pair->source.images.size()) pair->source.images[i].release();
        return out;
      });
    }
  }
  std::vector<Status> written(files.size() + painted.size(), Status::success());
  std::mutex report_lock;
  size_t done = 0;
  const double total = static_cast<double>(written.size() + 1);
  auto one_done = [&] {
    std::lock_guard<std::mutex> hold(report_lock);
    progress.report(static_cast<double>(++done) / total, "writing " + folder.string());
  };
  progress.report(0.0, "writing " + folder.string());
  const Status cancelled = make_error("writing " + folder.string() + " cancelled");
  // the painted ones first: they release the pair's photos, the largest
  // part of what is held, before the other files are made all at once
  {
    std::future<void> writing;  // the picture before, being encoded and written
    for (size_t i = 0; i < painted.size(); ++i) {
      const size_t at = files.size() + i;
      if (progress.cancelled()) {
        written[at] = cancelled;
        one_done();
        continue;
      }
      auto picture = painted[i]();
      if (writing.valid()) writing.get();
      if (!picture) {
        written[at] = picture.error();
        one_done();
        continue;
      }
      writing = std::async(std::launch::async, [&, at, i, out = std::move(*picture)] {
        char name[64];
        std::snprintf(name, sizeof name, "result_light_%02zu.png", i);
        written[at] = io::write_png16(folder / name, out, io::Sync::later);
        one_done();
      });
    }
    if (writing.valid()) writing.get();
  }
  if (painted_all) painted_all();
  if (begun && !progress.cancelled()) {
    bool painted_all = true;
    for (size_t i = 0; i < painted.size(); ++i) painted_all = painted_all && written[files.size() + i].ok();
    if (painted_all) {
      nlohmann::json j = nlohmann::json::parse(metrics, nullptr, false);
      const nlohmann::json q = j.is_object() && j.contains("quality") ? j["quality"] : nlohmann::json::object();
      auto look = detail::look_end(*begun, picture_greys, own_greys, r.repainted_median, r.map.xy,
                                   q.value("coverage", 0.0), q.value("coherence", 0.0));
      if (look) j["look"] = std::move(*look);
      else j["look_error"] = look.message();
      metrics = j.dump(2);
    }
    picture_greys.clear(), own_greys.clear(), begun.reset();
  }
  tbb::parallel_for(size_t(0), files.size(), [&](size_t i) {
    // a cancel stops the files not yet begun; those being encoded finish
    // (each is whole under its own name or absent, never half-written)
    written[i] = progress.cancelled() ? cancelled : files[i]();
    one_done();
  });
  if (progress.cancelled()) return cancelled;  // and no metrics.json: the folder is not a whole result
  for (const Status& s : written) {
    if (!s) return s;  // the first by file order, whatever finished first
  }
  if (auto s = io::sync_folder(folder); !s) return s;
  if (metrics_out) *metrics_out = metrics;
  return io::write_file_atomic(folder / "metrics.json", metrics + "\n");
}

}  // namespace

Status write_transfer(const TransferResult& r, const std::filesystem::path& folder, const Progress& progress) {
  return write_files(r, nullptr, folder, progress);
}

Status write_transfer(TransferResult& r, PreparedPair&& pair_in, const std::filesystem::path& folder,
                      const Progress& progress) {
  if (!r.repainted.empty()) return make_error("write_transfer: the result already holds its pictures");
  if (r.map.xy.size() != pair_in.dst.view.mask.size())
    return make_error("write_transfer: the map is not the pair's (another size)");
  PreparedPair pair = std::move(pair_in);
  // nothing here reads the normals (a shaded look holds the destination's)
  // or the destination's median (the result holds its own)
  for (PreparedObject* object : {&pair.dst, &pair.src}) object->view.normals.release();
  pair.destination_median.release();
  // the look's figures need, besides the pictures, what goes next (the truth, every source photo)
  std::optional<detail::LookBegun> begun;
  if (r.look_pending) {
    auto b = detail::look_begin(pair, r, false, progress.part(0.0, 0.0));
    if (!b) return make_error("the look: " + b.message());
    begun = std::move(*b);
  }
  // the pictures need the photos (and the plan made from the rest): the
  // normals and the truth, a photo's bytes each, go before painting starts
  for (io::ImageSet* set : {&pair.destination, &pair.source}) set->truth = io::Truth{};
  // a shaded look paints on the destination's photos alone: the source's go now (the look's figures
  // took their median above), 0.9 GB at 5600x3750 in half floats (issue 42: memory)
  if (r.look) {
    for (cv::Mat& photo : pair.src.view.images) photo.release();
    for (cv::Mat& photo : pair.source.images) photo.release();
  }
  std::string metrics;
  // once every picture is painted the shaded look has done its work: what it holds (the texture, the
  // glosses' weights, the shading medians: ~0.6 GB at 5600x3750) goes before the look's figures and
  // the other files are made (issue 42: memory)
  Status s = write_files(r, &pair, folder, progress, &metrics, std::move(begun), [&r] { r.look.reset(); });
  if (s) r.metrics_json = std::move(metrics), r.look_pending = false;
  return s;
}

}  // namespace veneer::pipeline
