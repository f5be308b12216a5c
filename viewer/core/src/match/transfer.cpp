// Appearance transfer end to end (transfer.hpp).
#include "veneer/match/transfer.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <mutex>
#include <optional>
#include <limits>
#include <type_traits>
#include <utility>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>

#include "veneer/io/image_io.hpp"
#include "veneer/match/fast.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/ps/segmentation.hpp"
#include "veneer/util/log.hpp"

namespace veneer::match {
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

}  // namespace

Status TransferOptions::check() const {
  if (auto s = match.check(); !s) return s;
  if (!(scale > 0 && scale <= 1)) return make_error("scale must be in (0, 1], got " + std::to_string(scale));
  if (blend < 0 || blend > 16) return make_error("blend radius must be in 0..16 px, got " + std::to_string(blend));
  if (!(blend_guide >= 0 && blend_guide <= 2))
    return make_error("blend_guide must be in [0, 2] (|dn|; 0 = off), got " + std::to_string(blend_guide));
  return {};
}

cv::Size scaled_size(cv::Size size, double scale) {
  if (scale == 1.0) return size;
  return {std::max(1, static_cast<int>(std::lround(size.width * scale))),
          std::max(1, static_cast<int>(std::lround(size.height * scale)))};
}

void scale_set(ImageSet& set, double scale) {
  if (scale == 1.0) return;
  const cv::Size size = scaled_size(set.size, scale);
  auto area = [&](cv::Mat& m) {
    if (!m.empty()) cv::resize(m, m, size, 0, 0, cv::INTER_AREA);
  };
  auto nearest = [&](cv::Mat& m) {
    if (!m.empty()) cv::resize(m, m, size, 0, 0, cv::INTER_NEAREST);
  };
  for (auto& im : set.images) area(im);
  area(set.ambient);
  nearest(set.mask);
  nearest(set.truth.mask);
  nearest(set.truth.normals);
  area(set.truth.albedo);
  nearest(set.truth.depth);
  const double sx = static_cast<double>(size.width) / set.size.width;
  set.camera.focal_px *= sx;
  set.camera.cx *= sx;
  set.camera.cy *= static_cast<double>(size.height) / set.size.height;
  set.size = size;
}

namespace {
std::string who_of(const ImageSet& set) { return set.id.empty() ? set.origin.string() : set.id; }
}  // namespace

Expected<cv::Mat> object_mask(const ImageSet& set, bool truth_normals) {
  if (truth_normals) {
    if (!set.truth.present())
      return make_error("set " + who_of(set) + " has no truth/normals.pfm (needed by truth normals)");
    if (!set.truth.mask.empty()) return set.truth.mask.clone();
    cv::Mat m;
    cv::transform(set.truth.normals, m, cv::Matx13f(1, 1, 1));
    return cv::Mat(m != 0);
  }
  auto seg = ps::segment(set);
  if (!seg) return make_error("set " + who_of(set) + ": segmentation: " + seg.message());
  return seg->mask;
}

Expected<PreparedObject> prepare_object(const ImageSet& set, bool truth_normals, const Progress& progress) {
  PreparedObject out;
  auto t0 = Clock::now();
  auto mask = object_mask(set, truth_normals);
  if (!mask) return mask.error();
  out.view.mask = std::move(*mask);
  if (truth_normals) {
    out.view.normals = set.truth.normals.clone();
  } else {
    out.segment_seconds = since(t0);
    t0 = Clock::now();
    auto solved = ps::photometric_stereo(set, out.view.mask, {}, progress);
    if (!solved) return make_error("set " + who_of(set) + ": photometric stereo: " + solved.message());
    if (set.mask.empty()) {  // a base the object stands on is not the object (a supplied mask is the user's word)
      ps::drop_supports(*solved);
      out.view.mask = solved->mask;
    }
    out.normals_seconds = since(t0);
    out.view.normals = solved->normals;
  }
  for (const auto& im : set.images) {
    cv::Mat photo = im.clone();
    if (!set.ambient.empty() && set.ambient.size() == im.size()) {
      photo -= set.ambient;
      photo = cv::max(photo, 0.0);
    }
    out.view.images.push_back(photo);
  }
  for (const auto& light : set.lights) out.view.lamps.push_back(light.lamp_id);
  if (out.view.lamps.size() != out.view.images.size()) out.view.lamps.clear();
  return out;
}

cv::Mat median_photo(const std::vector<cv::Mat>& photos) {
  if (photos.empty()) return {};
  cv::Mat out(photos[0].size(), CV_32FC3);
  const int n = static_cast<int>(photos.size());
  cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& rows) {
    std::vector<float> v(n);
    for (int y = rows.start; y < rows.end; ++y)
      for (int x = 0; x < out.cols; ++x)
        for (int c = 0; c < 3; ++c) {
          for (int i = 0; i < n; ++i) v[i] = photos[i].at<cv::Vec3f>(y, x)[c];
          std::nth_element(v.begin(), v.begin() + n / 2, v.end());
          float m = v[n / 2];
          if (n % 2 == 0) m = 0.5f * (m + *std::max_element(v.begin(), v.begin() + n / 2));
          out.at<cv::Vec3f>(y, x)[c] = m;
        }
  });
  return out;
}

cv::Mat repaint(const Map& map, const cv::Mat& photo, const cv::Mat& backdrop) {
  cv::Mat out = backdrop.empty() ? cv::Mat(map.xy.size(), CV_32FC3, cv::Scalar::all(0)) : backdrop.clone();
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x) {
      const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
      if (m[0] < 0) continue;
      const int sx = static_cast<int>(std::lround(m[0])), sy = static_cast<int>(std::lround(m[1]));
      if (sx < photo.cols && sy < photo.rows) out.at<cv::Vec3f>(y, x) = photo.at<cv::Vec3f>(sy, sx);
    }
  return out;
}

namespace {

// `backdrop` (empty = black) with the plan's pixels blended from `photo`.
Expected<cv::Mat> repaint_planned(const fast::BlendPlan& plan, const cv::Mat& photo, const cv::Mat& backdrop) {
  cv::Mat out = backdrop.empty() ? cv::Mat(plan.destination_size, CV_32FC3, cv::Scalar::all(0)) : backdrop.clone();
  if (auto s = fast::apply_blend(plan, photo, out); !s) return s.error();
  return out;
}

}  // namespace

Expected<cv::Mat> repaint_blended(const Map& map, const cv::Mat& photo, const cv::Mat& source_mask, int radius,
                                  const cv::Mat& backdrop, const fast::BlendGuide* guide) {
  if (radius == 0) return repaint(map, photo, backdrop);
  const cv::Mat smask = source_mask.empty() ? cv::Mat(photo.size(), CV_8UC1, cv::Scalar(255)) : source_mask;
  auto plan = fast::blend_plan(map, {}, smask, radius, 0, guide);  // every mapped pixel
  if (!plan) return plan.error();
  return repaint_planned(*plan, photo, backdrop);
}

cv::Mat map_picture(const Map& map, cv::Size source_size) {
  cv::Mat out(map.xy.size(), CV_8UC3, cv::Scalar::all(0));
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x) {
      const cv::Vec2f m = map.xy.at<cv::Vec2f>(y, x);
      if (m[0] < 0) continue;
      out.at<cv::Vec3b>(y, x) = cv::Vec3b(255, cv::saturate_cast<uchar>(255.0 * m[1] / source_size.height),
                                          cv::saturate_cast<uchar>(255.0 * m[0] / source_size.width));
    }
  return out;
}

cv::Mat reuse_picture(const cv::Mat& counts, const cv::Mat& source_photo) {
  cv::Mat grey(counts.size(), CV_8UC3, cv::Scalar::all(0));
  if (!source_photo.empty()) {
    cv::Mat g;
    cv::cvtColor(tonemap_picture(source_photo), g, cv::COLOR_BGR2GRAY);
    g *= 0.45;  // dimmed so the heat stands out
    cv::cvtColor(g, grey, cv::COLOR_GRAY2BGR);
  }
  double max_count = 0;
  cv::minMaxLoc(counts, nullptr, &max_count);
  if (max_count <= 0) return grey;
  cv::Mat level(counts.size(), CV_8UC1, cv::Scalar(0));
  for (int y = 0; y < counts.rows; ++y)
    for (int x = 0; x < counts.cols; ++x) {
      const int c = counts.at<int>(y, x);
      if (c > 0) level.at<uchar>(y, x) = cv::saturate_cast<uchar>(40 + 215 * std::log1p(c) / std::log1p(max_count));
    }
  cv::Mat heat;
  cv::applyColorMap(level, heat, cv::COLORMAP_INFERNO);
  heat.copyTo(grey, counts > 0);
  return grey;
}

cv::Mat origin_picture(const Map& map, const cv::Mat& destination_photo, const cv::Mat& source_photo,
                       const std::vector<cv::Point>& points) {
  const cv::Mat d = tonemap_picture(destination_photo), s = tonemap_picture(source_photo);
  const int h = std::max(d.rows, s.rows);
  cv::Mat out(h, d.cols + s.cols, CV_8UC3, cv::Scalar::all(0));
  d.copyTo(out(cv::Rect(0, 0, d.cols, d.rows)));
  s.copyTo(out(cv::Rect(d.cols, 0, s.cols, s.rows)));
  cv::line(out, {d.cols, 0}, {d.cols, h - 1}, cv::Scalar(90, 90, 90), 1);
  const int r = std::max(2, d.cols / 200);
  for (size_t i = 0; i < points.size(); ++i) {
    const cv::Point p = points[i];
    // distinct hues around the colour wheel
    cv::Mat hsv(1, 1, CV_8UC3, cv::Scalar(static_cast<double>((i * 37) % 180), 220, 255)), bgr;
    cv::cvtColor(hsv, bgr, cv::COLOR_HSV2BGR);
    const cv::Vec3b c = bgr.at<cv::Vec3b>(0, 0);
    const cv::Scalar colour(c[0], c[1], c[2]);
    if (p.x < 0 || p.y < 0 || p.x >= map.xy.cols || p.y >= map.xy.rows || !map.valid(p.x, p.y)) {
      cv::drawMarker(out, p, cv::Scalar(0, 0, 255), cv::MARKER_TILTED_CROSS, 4 * r, 2);
      continue;
    }
    const cv::Vec2f m = map.xy.at<cv::Vec2f>(p);
    const cv::Point q(d.cols + static_cast<int>(std::lround(m[0])), static_cast<int>(std::lround(m[1])));
    cv::line(out, p, q, colour, 1, cv::LINE_AA);
    cv::circle(out, p, r, colour, -1, cv::LINE_AA);
    cv::circle(out, q, r, colour, -1, cv::LINE_AA);
  }
  return out;
}

std::vector<cv::Point> spread_points(const Map& map, int count) {
  std::vector<cv::Point> mapped;
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x)
      if (map.valid(x, y)) mapped.emplace_back(x, y);
  if (mapped.empty() || count <= 0) return {};
  const cv::Rect box = cv::boundingRect(mapped);
  const int side = std::max(1, static_cast<int>(std::ceil(std::sqrt(static_cast<double>(count)))));
  std::vector<cv::Point> out;
  for (int j = 0; j < side; ++j)
    for (int i = 0; i < side; ++i) {
      const int x = box.x + (2 * i + 1) * box.width / (2 * side), y = box.y + (2 * j + 1) * box.height / (2 * side);
      if (x < map.xy.cols && y < map.xy.rows && map.valid(x, y)) out.emplace_back(x, y);
    }
  return out;
}

Status write_map(const std::filesystem::path& file, const Map& map, Sync sync) {
  std::vector<cv::Mat> channels;
  cv::split(map.xy, channels);
  channels.push_back(map.distance);
  cv::Mat xyd;
  cv::merge(channels, xyd);
  return write_pfm(file, xyd, true, sync);
}

Expected<Map> read_map(const std::filesystem::path& file) {
  auto m = read_pfm(file, true);
  if (!m) return m.error();
  if (m->type() != CV_32FC3) return make_error(file.string() + ": a map has 3 channels (x, y, distance)");
  std::vector<cv::Mat> ch;
  cv::split(*m, ch);
  Map map;
  cv::merge(std::vector<cv::Mat>{ch[0], ch[1]}, map.xy);
  map.distance = ch[2];
  return map;
}

Expected<PreparedPair> prepare_pair(const ImageSet& destination_in, const ImageSet& source_in,
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
}

// metrics.json's "options" (blend_guide as the pictures were blended: 0 plain)
nlohmann::json options_json(const TransferOptions& options, double blend_guide) {
  nlohmann::json j = {{"method", method_name(options.match.method)}, {"feature", feature_name(options.match.feature)}};
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

namespace {

// transfer() of a prepared pair, from `given` when not null (else the map is
// computed); timings' total_s counts from t_all.
Expected<TransferResult> transfer_from(const PreparedPair& pair, const TransferOptions& options, const Map* given,
                                       const Progress& progress, Clock::time_point t_all) {
  if (auto s = options.check(); !s) return s.error();
  if (options.scale != pair.scale || options.truth_normals != pair.truth_normals)
    return make_error("the prepared pair was made with scale " + std::to_string(pair.scale) + " and truth normals " +
                      (pair.truth_normals ? "on" : "off") + ", the options ask for scale " +
                      std::to_string(options.scale) + " and truth normals " + (options.truth_normals ? "on" : "off"));
  const ImageSet& destination = pair.destination;
  const ImageSet& source = pair.source;
  const PreparedObject* dst = &pair.dst;
  const PreparedObject* src = &pair.src;
  nlohmann::json timings;
  timings["segment_destination_s"] = dst->segment_seconds;
  timings["normals_destination_s"] = dst->normals_seconds;
  timings["segment_source_s"] = src->segment_seconds;
  timings["normals_source_s"] = src->normals_seconds;

  auto t0 = Clock::now();
  TransferResult result;
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
  } else {
    auto map = compute_map(dst->view, src->view, options.match, sub_progress(progress, 0.0, 0.85));
    if (!map) return map.error();
    timings["match_s"] = since(t0);
    result.map = std::move(*map);
  }
  result.match_seconds = timings["match_s"].get<double>();
  result.match_options = options.match;
  result.source_size = source.size;
  t0 = Clock::now();
  progress.report(0.9, "repaint");
  const fast::BlendGuide guide = blend_guide_of(pair, options);
  const bool guided = !guide.destination.empty();
  const fast::BlendGuide* g = guided ? &guide : nullptr;
  // every photo through the same map: the blend's weights worked out once
  auto planned = blend_plan_for(pair, options, result.map);
  if (!planned) return make_error("repaint: " + planned.message());
  const std::shared_ptr<const fast::BlendPlan> plan = *planned;
  result.blend = plan;
  auto paint = [&](const cv::Mat& photo, const cv::Mat& backdrop) -> Expected<cv::Mat> {
    if (!plan) return repaint(result.map, photo, backdrop);
    return repaint_planned(*plan, photo, backdrop);
  };
  for (size_t i = 0; options.keep_pictures && i < src->view.images.size() && i < dst->view.images.size(); ++i) {
    auto painted = paint(src->view.images[i], dst->view.images[i]);
    if (!painted) return make_error("repaint: " + painted.message());
    result.repainted.push_back(std::move(*painted));
  }
  result.source_median = pair.source_median;
  auto median = paint(pair.source_median, pair.destination_median);
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
  j["pictures"] = {{"result_light_NN.png, result_median.png",
                    "linear 16-bit RGB at the sets' photometric scale, as the sets' light_NN.png (no exposure or "
                    "gamma change)"},
                   {"map.png, reuse.png, relight_*.png", "8-bit sRGB pictures for viewing"},
                   {"confidence.png", "white = the match fits exactly, black = 4x the median match distance or "
                                      "more, or not mapped"}};
  if (destination.truth.present() && source.truth.present()) {
    t0 = Clock::now();
    Quality q = evaluate(result.map, destination.truth.mask, source.truth.mask, destination.truth.normals,
                         source.truth.normals);
    if (relight_measurable(source.scene)) {
      auto relit = relight(result.map, destination, source, destination.truth.mask, options.blend, g);
      if (relit) {
        q.psnr_db = relit->psnr_db;
        q.psnr_lit_db = relit->psnr_lit_db;
        result.relit = std::move(*relit);
      } else {
        j["relight_error"] = relit.message();
      }
    }
    result.quality = q;
    j["quality"] = quality_json(q);
    j["quality"]["measured_against"] = "truth (simulated sets)";
    timings["quality_s"] = since(t0);
  } else {
    // Real sets: what can be measured without truth -- coverage of the
    // segmented object, coherence, and the agreement of the photometric
    // stereo normals at the matches.
    t0 = Clock::now();
    Quality q = evaluate(result.map, dst->view.mask, src->view.mask, dst->view.normals, src->view.normals);
    j["quality"] = quality_json(q);
    j["quality"]["measured_against"] = "segmentation masks and photometric-stereo normals (no truth)";
    timings["quality_s"] = since(t0);
  }
  if (result.map.motion.searched) {
    // Whether the destination was found to be the source moved (combined):
    // one motion of the whole object, or why not.
    const ObjectMotion& mo = result.map.motion;
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

Expected<TransferResult> transfer(const ImageSet& destination_in, const ImageSet& source_in,
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

std::string transfer_options_json(const TransferOptions& options) {
  return nlohmann::json{{"options", options_json(options, options.blend_guide)}}.dump(2);
}

Expected<TransferOptions> read_transfer_options(const std::filesystem::path& file) {
  auto bytes = read_file_bytes(file);
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
  std::string method = method_name(t.match.method), feature = feature_name(t.match.feature);
  get("method", method), get("feature", feature);
  for_each_option(t, get);
  if (!bad.empty()) return make_error(name + ": options." + bad + " has the wrong type or is out of range");
  auto me = parse_method(method);
  if (!me) return make_error(name + ": options.method: " + me.message());
  auto fe = parse_feature(feature);
  if (!fe) return make_error(name + ": options.feature: " + fe.message());
  t.match.method = *me, t.match.feature = *fe;
  if (auto s = t.check(); !s) return make_error(name + ": options: " + s.message());
  return t;
}

double map_scale(const Map& map, const ImageSet& destination) {
  return destination.size.width > 0 ? static_cast<double>(map.xy.cols) / destination.size.width : 1.0;
}

Expected<Quality> evaluate_sets(const Map& map, const ImageSet& destination_in, const ImageSet& source_in) {
  const double scale = map_scale(map, destination_in);
  if (!(scale > 0 && scale <= 1.0001))
    return make_error("the map is " + std::to_string(map.xy.cols) + " px wide but the destination set " +
                      std::to_string(destination_in.size.width));
  ImageSet destination = destination_in, source = source_in;
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

cv::Mat confidence_picture(const Map& map) {
  cv::Mat pic(map.xy.size(), CV_8UC3, cv::Scalar(0, 0, 0));
  std::vector<float> d;
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x)
      if (map.valid(x, y)) d.push_back(map.distance.at<float>(y, x));
  if (d.empty()) return pic;
  auto mid = d.begin() + d.size() / 2;
  std::nth_element(d.begin(), mid, d.end());
  const float scale = std::max(*mid, 1e-6f) * 4;  // 4x the median distance and beyond: no confidence
  for (int y = 0; y < map.xy.rows; ++y)
    for (int x = 0; x < map.xy.cols; ++x) {
      if (!map.valid(x, y)) continue;  // unmapped (and background): black
      const float c = 1.0f - std::min(1.0f, map.distance.at<float>(y, x) / scale);
      const auto g = static_cast<uchar>(std::lround(255 * c));
      pic.at<cv::Vec3b>(y, x) = {g, g, g};
    }
  return pic;
}

namespace {

// write_transfer's files; with `pair`, the per-lamp pictures are painted from
// its photos one at a time (each into its destination photo, then released).
Status write_files(const TransferResult& r, PreparedPair* pair, const std::filesystem::path& folder,
                   const Progress& progress) {
  std::error_code ec;
  std::filesystem::create_directories(folder, ec);
  if (ec) return make_error("cannot create " + folder.string() + ": " + ec.message());
  // Every file is made and written at once (one task each, encoders on all
  // cores), each through a temporary and a rename but without an fsync of
  // its own; one fsync of the folder at the end, then metrics.json, synced,
  // last: a folder with a metrics.json holds the whole result.
  std::vector<std::function<Status()>> files;
  files.push_back([&] { return write_map(folder / "map.pfm", r.map, Sync::later); });
  files.push_back([&] { return write_picture(folder / "map.png", map_picture(r.map, r.source_size), Sync::later); });
  for (size_t i = 0; i < r.repainted.size(); ++i) {
    files.push_back([&, i] {
      char name[64];
      std::snprintf(name, sizeof name, "result_light_%02zu.png", i);
      // Linear 16-bit at the sets' own scale, as their light_NN.png: a
      // repainted photo and the photos it came from look alike side by side.
      return write_png16(folder / name, r.repainted[i], Sync::later);
    });
  }
  files.push_back([&] { return write_png16(folder / "result_median.png", r.repainted_median, Sync::later); });
  files.push_back(
      [&] { return write_picture(folder / "reuse.png", reuse_picture(r.reuse, r.source_median), Sync::later); });
  files.push_back([&] { return write_picture(folder / "confidence.png", confidence_picture(r.map), Sync::later); });
  if (r.relit) {
    files.push_back([&] {
      // one exposure for both, so that they compare
      cv::Mat both;
      cv::hconcat(r.relit->transferred, r.relit->reference, both);
      const cv::Mat pic = tonemap_picture(both);
      const int w = r.relit->transferred.cols;
      if (auto s = write_picture(folder / "relight_transferred.png", pic(cv::Rect(0, 0, w, pic.rows)).clone(),
                                 Sync::later);
          !s)
        return s;
      return write_picture(folder / "relight_reference.png", pic(cv::Rect(w, 0, w, pic.rows)).clone(), Sync::later);
    });
  }
  // The pictures painted from the pair's photos: one after another (each
  // painting and encoding is parallel within), so one is in memory at a time.
  std::vector<std::function<Status()>> painted;
  if (pair) {
    const size_t lamps = std::min(pair->src.view.images.size(), pair->dst.view.images.size());
    for (size_t i = 0; i < lamps; ++i) {
      painted.push_back([&r, pair, &folder, i]() -> Status {
        cv::Mat& backdrop = pair->dst.view.images[i];
        const cv::Mat& photo = pair->src.view.images[i];
        cv::Mat out;
        if (r.blend) {
          out = backdrop;  // painted in place: the photo is released next
          if (auto s = fast::apply_blend(*r.blend, photo, out); !s) return make_error("repaint: " + s.message());
        } else {
          out = repaint(r.map, photo, backdrop);
        }
        // this lamp's photos are done with: every copy of them goes
        pair->dst.view.images[i].release();
        pair->src.view.images[i].release();
        if (i < pair->destination.images.size()) pair->destination.images[i].release();
        if (i < pair->source.images.size()) pair->source.images[i].release();
        char name[64];
        std::snprintf(name, sizeof name, "result_light_%02zu.png", i);
        return write_png16(folder / name, out, Sync::later);
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
  for (size_t i = 0; i < painted.size(); ++i) {
    written[files.size() + i] = progress.cancelled() ? cancelled : painted[i]();
    one_done();
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
  if (auto s = sync_folder(folder); !s) return s;
  return write_file_atomic(folder / "metrics.json", r.metrics_json + "\n");
}

}  // namespace

Status write_transfer(const TransferResult& r, const std::filesystem::path& folder, const Progress& progress) {
  return write_files(r, nullptr, folder, progress);
}

Status write_transfer(const TransferResult& r, PreparedPair&& pair_in, const std::filesystem::path& folder,
                      const Progress& progress) {
  if (!r.repainted.empty()) return make_error("write_transfer: the result already holds its pictures");
  if (r.map.xy.size() != pair_in.dst.view.mask.size())
    return make_error("write_transfer: the map is not the pair's (another size)");
  PreparedPair pair = std::move(pair_in);
  // the pictures need the photos (and the plan made from the rest): the
  // normals and the truth, a photo's bytes each, go before painting starts
  for (ImageSet* set : {&pair.destination, &pair.source}) set->truth = Truth{};
  for (PreparedObject* object : {&pair.dst, &pair.src}) object->view.normals.release();
  return write_files(r, &pair, folder, progress);
}

}  // namespace veneer::match
