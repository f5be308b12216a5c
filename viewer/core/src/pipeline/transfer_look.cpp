// metrics.json's "look" block (transfer_look.hpp).
#include "transfer_look.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <optional>
#include <sstream>

#include <opencv2/core/utility.hpp>

#include "veneer/eval/look.hpp"
#include "veneer/eval/metrics.hpp"
#include "veneer/match/fast.hpp"
#include "veneer/repaint/gloss.hpp"
#include "veneer/sim/simulator.hpp"

namespace veneer::pipeline::detail {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

nlohmann::json shading_json(const eval::ShadingError& s) {
  return {{"shading_mean", s.mean}, {"shading_median", s.median}, {"shading_p90", s.p90}, {"samples", s.samples}};
}

// Marks in `read` the source pixels a map's nearest-pixel lookups reach.
void mark_read(const cv::Mat& xy, cv::Mat& read) {
  if (read.empty()) return;
  for (int y = 0; y < xy.rows; ++y) {
    const cv::Vec2f* m = xy.ptr<cv::Vec2f>(y);
    for (int x = 0; x < xy.cols; ++x) {
      if (!(m[x][0] >= 0 && m[x][1] >= 0)) continue;
      const int sx = std::clamp(static_cast<int>(std::nearbyint(m[x][0])), 0, read.cols - 1);
      const int sy = std::clamp(static_cast<int>(std::nearbyint(m[x][1])), 0, read.rows - 1);
      read.at<uchar>(sy, sx) = 255;
    }
  }
}

// The transfer's pictures in grey: taken from the result, or painted again
// one at a time (each released once in grey) when it did not keep them --
// by the shaded look when there is one, else by `paint`.
Expected<std::vector<cv::Mat>> grey_pictures(const std::vector<cv::Mat>& kept, const PreparedPair& pair,
                                             const Paint& paint, const repaint::ShadedLook* look = nullptr) {
  std::vector<cv::Mat> out;
  if (!kept.empty()) {
    for (const cv::Mat& p : kept) out.push_back(eval::look_gray(p));
    return out;
  }
  const auto& src = pair.src.view.images;
  const auto& dst = pair.dst.view.images;
  for (size_t i = 0; i < dst.size() && (look || i < src.size()); ++i) {
    auto painted = look ? look->paint(i, dst[i]) : paint(src[i], dst[i]);
    if (!painted) return painted.error();
    out.push_back(eval::look_gray(*painted));
  }
  return out;
}

// eval::median_image of half-float colour photos (PrepareOptions::half_photos)
// where `mask` is set, each row widened in turn: no grey copy of the set.
cv::Mat grey_median(const std::vector<cv::Mat>& photos, const cv::Mat& mask) {
  const int n = static_cast<int>(photos.size());
  cv::Mat out(photos[0].size(), CV_32FC1, cv::Scalar(0));
  cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& rows) {
    repaint::PhotoRows rows_of(photos);
    std::vector<float> v(n);
    for (int y = rows.start; y < rows.end; ++y) {
      const uchar* m = mask.ptr<uchar>(y);
      if (cv::countNonZero(mask.row(y)) == 0) continue;
      const cv::Vec3f* const* p = rows_of.row(y);
      float* o = out.ptr<float>(y);
      for (int x = 0; x < out.cols; ++x) {
        if (!m[x]) continue;
        for (int i = 0; i < n; ++i) v[i] = (p[i][x][0] + p[i][x][1] + p[i][x][2]) * (1.0f / 3);
        const int h = n / 2;
        std::nth_element(v.begin(), v.begin() + h, v.end());
        o[x] = n % 2 ? v[h] : 0.5f * (v[h] + *std::max_element(v.begin(), v.begin() + h));
      }
    }
  });
  return out;
}

// A photo as float: itself, or widened from half floats.
cv::Mat widened(const cv::Mat& photo) {
  if (photo.empty() || photo.depth() != CV_16F) return photo;
  cv::Mat out;
  photo.convertTo(out, CV_32F);
  return out;
}

std::vector<cv::Mat> greys(const std::vector<cv::Mat>& photos) {
  std::vector<cv::Mat> out(photos.size());
  cv::parallel_for_(cv::Range(0, static_cast<int>(photos.size())), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) out[i] = eval::look_gray(photos[i]);
  });
  return out;
}

// The truth look: the destination's scene in the source's material under the
// same lamps and pose, as `veneer simulate --scene A --material B` makes it
// (its default noise, 0.005 of full scale, seed 1, a noise stream per lamp:
// where the destination was made the same way its background is the same to
// the bit). When the destination's background is not that (another noise, or
// none), it is rendered without noise. Lamp by lamp, each kept in grey only
// (a whole set at once went over the transfer's memory bound). Refused when
// it does not line up with the destination (lamps or object mask differ: a
// pose the set does not record).
struct TruthLook {
  std::vector<cv::Mat> photos;  // grey
  double noise = 0;             // the noise it was rendered with
};
Expected<TruthLook> truth_look(const io::ImageSet& destination, const io::ImageSet& source, const Progress& progress) {
  sim::RenderOptions o;
  o.size = destination.size;
  o.focal_px = destination.camera.focal_px;
  o.noise_sigma = 0.005;
  auto scene = sim::make_scene_with_material(destination.scene, source.scene, o);
  if (!scene) return scene.error();
  const std::vector<sim::Lamp> lamps = sim::thesis_rig();
  if (lamps.size() != destination.images.size() || destination.images.empty())
    return make_error("the truth look has " + std::to_string(lamps.size()) + " lamps, the destination " +
                      std::to_string(destination.images.size()));
  for (size_t i = 0; i < lamps.size() && i < destination.lights.size(); ++i) {
    const auto& b = destination.lights[i].position_m;
    if (b && cv::norm(lamps[i].position_m - *b) > 1e-3)
      return make_error("the truth look's lamp " + std::to_string(i) + " is not the destination's");
  }
  cv::Mat object;  // the truth look's object mask
  {
    const io::Truth truth = sim::render_truth(**scene, o);
    object = truth.mask;
  }
  if (!destination.truth.mask.empty() && destination.truth.mask.size() == object.size()) {
    cv::Mat both, either;
    cv::bitwise_and(destination.truth.mask, object, both);
    cv::bitwise_or(destination.truth.mask, object, either);
    const double overlap = cv::countNonZero(both) / std::max(1.0, double(cv::countNonZero(either)));
    if (overlap < 0.98)
      return make_error("the truth look does not line up with the destination (object masks overlap " +
                        std::to_string(overlap) + "): posed otherwise than `veneer simulate` poses it?");
  }
  auto shot = [&](size_t i) {
    sim::RenderOptions oi = o;
    oi.shot = static_cast<uint32_t>(i);
    return sim::render(**scene, {lamps[i]}, oi);
  };
  TruthLook out;
  out.noise = o.noise_sigma;
  // The background under the first lamp: the same noise makes most of its
  // lit pixels the same to the bit (not all: the object's shadow and its
  // base change with its material).
  cv::Mat first = shot(0);
  if (first.empty()) return make_error("rendering the truth look failed");
  const cv::Mat a = eval::look_gray(destination.images[0]), b = eval::look_gray(first);
  long lit = 0, same = 0;
  for (int y = 0; y < a.rows; ++y)
    for (int x = 0; x < a.cols; ++x) {
      if (!object.empty() && object.at<uchar>(y, x)) continue;
      const float u = a.at<float>(y, x), v = b.at<float>(y, x);
      if (u <= 0 && v <= 0) continue;
      ++lit;
      same += u == v;
    }
  if (lit == 0 || same < 0.9 * static_cast<double>(lit)) {
    o.noise_sigma = 0;
    out.noise = 0;
    first = shot(0);
  }
  out.photos.push_back(eval::look_gray(first));
  first.release();
  for (size_t i = 1; i < lamps.size(); ++i) {
    if (progress.cancelled()) return make_error("truth look: cancelled");
    progress.report(static_cast<double>(i) / lamps.size(), "truth look");
    const cv::Mat photo = shot(i);
    if (photo.empty()) return make_error("rendering the truth look failed");
    out.photos.push_back(eval::look_gray(photo));
  }
  return out;
}

// The last truth look rendered, for the next transfer of the same pair (the
// viewer transfers a pair again whenever an option changes; the render is
// seconds at 1024x680, the figures milliseconds). Keyed by what it was
// rendered from: the scenes, the size, the focal length and the destination's
// first photo (its sum and a few pixels).
struct TruthCache {
  std::mutex lock;
  std::string key;
  std::optional<TruthLook> look;
};
TruthCache& truth_cache() {
  static TruthCache cache;
  return cache;
}
std::string truth_key(const io::ImageSet& destination, const io::ImageSet& source) {
  std::ostringstream k;
  k.precision(17);
  k << destination.scene << '|' << source.scene << '|' << destination.size.width << 'x' << destination.size.height
    << '|' << destination.camera.focal_px << '|' << destination.images.size();
  if (!destination.images.empty()) {
    cv::Mat first = destination.images[0];
    if (first.depth() != CV_32F) first.convertTo(first, CV_32F);  // photos kept as half floats
    k << '|' << cv::sum(first)[0] << '|' << cv::sum(first)[1] << '|' << cv::sum(first)[2];
  }
  for (const auto& light : destination.lights)
    if (light.position_m) k << '|' << (*light.position_m)[0] << ',' << (*light.position_m)[1] << ',' << (*light.position_m)[2];
  return k.str();
}
Expected<TruthLook> cached_truth_look(const io::ImageSet& destination, const io::ImageSet& source,
                                      const Progress& progress) {
  TruthCache& cache = truth_cache();
  const std::string key = truth_key(destination, source);
  {
    std::lock_guard hold(cache.lock);
    if (cache.look && cache.key == key) return *cache.look;
  }
  auto look = truth_look(destination, source, progress);
  if (!look) return look;
  std::lock_guard hold(cache.lock);
  cache.key = key;
  cache.look = *look;
  return look;
}

// The figures of one set of pictures against the references.
struct Scored {
  nlohmann::json json;
  double shading = 0;  // against the first reference
};
Expected<Scored> score(const std::vector<cv::Mat>& pictures, const cv::Mat& median_picture,
                       const std::vector<const std::vector<cv::Mat>*>& references, const cv::Mat& mask,
                       const cv::Mat& source_median, const cv::Mat& map_xy) {
  Scored out;
  for (size_t k = 0; k < references.size(); ++k) {
    auto s = eval::shading_error(pictures, *references[k], mask);
    if (!s) return s.error();
    if (k == 0) {
      out.json = shading_json(*s);
      out.shading = s->mean;
    } else {
      out.json["own_photos"] = shading_json(*s);
    }
  }
  auto corr = eval::texture_corr(median_picture, source_median, map_xy, mask);
  if (corr) out.json["texture_corr"] = *corr;
  else out.json["texture_corr_error"] = corr.message();
  return out;
}

}  // namespace

Expected<LookBegun> look_begin(const PreparedPair& pair, const TransferResult& result, bool floor,
                               const Progress& progress) {
  const auto t0 = Clock::now();
  LookBegun out;
  nlohmann::json& j = out.json;
  // look.py's mask: the destination's mask.png when it has one, else every pixel
  const cv::Mat& mask = pair.destination.mask;
  const bool masked = !mask.empty() && mask.size() == pair.dst.view.mask.size();
  if (masked) out.mask = mask;
  std::string reference = "the destination's own photos";
  // The truth look is the simulator's truth: rendered for sets that carry
  // theirs (truth/), not for sets whose truth was set aside -- those are
  // scored as a user's sets are (at 5600x3750 its render was 25 s).
  if (!pair.destination.scene.empty() && !pair.source.scene.empty() && pair.destination.truth.present() &&
      pair.source.truth.present()) {
    auto rendered = cached_truth_look(pair.destination, pair.source, progress);
    if (rendered) {
      out.truth = std::move(rendered->photos);
      reference = "the truth look: " + pair.destination.scene + " in " + pair.source.scene +
                  "'s material (veneer simulate --scene " + pair.destination.scene + " --material " +
                  pair.source.scene + ", same size and lamps, noise " + std::to_string(rendered->noise) +
                  "); own_photos: against the destination's own photos";
      j["truth_noise"] = rendered->noise;
    } else {
      j["truth_error"] = rendered.message();
    }
  }
  j["reference"] = reference;
  j["mask"] = masked ? "the destination's mask" : "every pixel (the destination has no mask)";
  // The source's median where the map reads it (texture_corr's nearest
  // pixel): the rest of it is never looked at.
  const auto& source_photos = pair.src.view.images;
  cv::Mat read(source_photos.empty() ? cv::Size() : source_photos[0].size(), CV_8UC1, cv::Scalar(0));
  mark_read(result.map.xy, read);
  if (floor) read.setTo(255);  // the floor's map reads elsewhere
  out.source_median = source_photos.empty() || source_photos[0].type() == CV_32FC3
                          ? eval::median_image(source_photos, read)
                      : source_photos[0].type() == CV_16FC3 ? grey_median(source_photos, read)
                                                            : eval::median_image(greys(source_photos), read);
  // Without a mask the background, the destination's own photo in the result,
  // dilutes the figures (the bull is 3 % of its frame): the same over the
  // object the transfer repainted.
  const bool truth_masks = pair.destination.truth.present() && pair.source.truth.present();
  out.object = truth_masks ? pair.destination.truth.mask : pair.dst.view.mask;
  out.object_name = truth_masks ? "the destination's truth mask" : "the destination's object (segmented)";
  out.seconds = since(t0);
  return out;
}

namespace {
struct Ended {
  nlohmann::json json;
  std::vector<const std::vector<cv::Mat>*> references;
  Scored scored;
  std::optional<Scored> on_object;
};
Expected<Ended> end_scored(const LookBegun& begun, const std::vector<cv::Mat>& pictures,
                           const std::vector<cv::Mat>& own, const cv::Mat& repainted_median, const cv::Mat& map_xy) {
  Ended e;
  e.json = begun.json;
  e.references = {&own};
  if (!begun.truth.empty()) e.references.insert(e.references.begin(), &begun.truth);
  auto scored = score(pictures, repainted_median, e.references, begun.mask, begun.source_median, map_xy);
  if (!scored) return scored.error();
  e.scored = std::move(*scored);
  e.json.update(e.scored.json);
  if (begun.mask.empty()) {
    auto o = score(pictures, repainted_median, e.references, begun.object, begun.source_median, map_xy);
    if (!o) return o.error();
    e.on_object = std::move(*o);
    e.json["object"] = e.on_object->json;
    e.json["object"]["mask"] = begun.object_name;
  }
  return e;
}
}  // namespace

Expected<nlohmann::json> look_end(const LookBegun& begun, const std::vector<cv::Mat>& pictures,
                                  const std::vector<cv::Mat>& own, const cv::Mat& repainted_median,
                                  const cv::Mat& map_xy, double coverage, double coherence) {
  const auto t0 = Clock::now();
  auto e = end_scored(begun, pictures, own, repainted_median, map_xy);
  if (!e) return e.error();
  e->json["coverage"] = coverage;
  e->json["coherence"] = coherence;
  e->json["look_s"] = begun.seconds + since(t0);
  return std::move(e->json);
}

Expected<nlohmann::json> look_block(const PreparedPair& pair, const TransferOptions& options,
                                    const TransferResult& result, const Paint& paint, double coverage,
                                    double coherence, const Progress& progress) {
  const auto t0 = Clock::now();
  auto begun = look_begin(pair, result, options.look_floor, progress.part(0.0, 0.4));
  if (!begun) return begun.error();
  auto pictures = grey_pictures(result.repainted, pair, paint, result.look.get());
  if (!pictures) return pictures.error();
  auto ended = end_scored(*begun, *pictures, pair.destination.images, result.repainted_median, result.map.xy);
  if (!ended) return ended.error();
  nlohmann::json& j = ended->json;
  const auto& references = ended->references;
  const auto& scored = ended->scored;
  const auto& on_object = ended->on_object;
  const cv::Mat& source_median = begun->source_median;
  const cv::Mat& object = begun->object;
  const cv::Mat& mask = begun->mask;
  const bool masked = !mask.empty();
  const bool truth_masks = pair.destination.truth.present() && pair.source.truth.present();
  j["coverage"] = coverage;
  j["coherence"] = coherence;
  j["look_s"] = since(t0);

  if (options.look_floor) {
    // The floor of pixel copying: the exact nearest-normal map, painted the
    // way the transfer paints a copy (its blend), scored the same way.
    const auto t1 = Clock::now();
    match::MatchOptions linear = options.match;
    linear.method = match::Method::linear;
    auto map = match::compute_map(pair.dst.view, pair.src.view, linear, progress.part(0.4, 0.9));
    if (!map) return make_error("floor: " + map.message());
    auto plan = blend_plan_for(pair, options, *map);
    if (!plan) return make_error("floor: " + plan.message());
    const std::shared_ptr<const fast::BlendPlan> floor_plan = *plan;
    const Paint copy = [&](const cv::Mat& photo_in, const cv::Mat& backdrop_in) -> Expected<cv::Mat> {
      // photos kept in half floats (PrepareOptions::half_photos) are widened for the copy, one at a time
      const cv::Mat photo = widened(photo_in), backdrop = widened(backdrop_in);
      if (!floor_plan) return repaint::repaint(*map, photo, backdrop);
      return repaint::repaint_planned(*floor_plan, photo, backdrop);
    };
    auto floor_pictures = grey_pictures({}, pair, copy);
    if (!floor_pictures) return make_error("floor: " + floor_pictures.message());
    auto floor_median = copy(pair.source_median, pair.destination_median);
    if (!floor_median) return make_error("floor: " + floor_median.message());
    auto floor = score(*floor_pictures, *floor_median, references, masked ? mask : cv::Mat(), source_median, map->xy);
    if (!floor) return make_error("floor: " + floor.message());
    const eval::Quality q = eval::evaluate(*map, truth_masks ? pair.destination.truth.mask : pair.dst.view.mask,
                                           truth_masks ? pair.source.truth.mask : pair.src.view.mask);
    nlohmann::json f = {{"method", "linear"}, {"what", "the exact nearest-normal map's pixel copy"}};
    f.update(floor->json);
    f["coverage"] = q.coverage;
    f["coherence"] = q.coherence;
    f["floor_s"] = since(t1);
    j["floor"] = f;
    if (on_object) {
      auto o = score(*floor_pictures, *floor_median, references, object, source_median, map->xy);
      if (!o) return make_error("floor: " + o.message());
      j["floor"]["object"] = o->json;
      if (o->shading > 0) j["object"]["shading_vs_floor"] = on_object->shading / o->shading;
    }
    if (floor->shading > 0) j["shading_vs_floor"] = scored.shading / floor->shading;
  }
  return j;
}

}  // namespace veneer::pipeline::detail
