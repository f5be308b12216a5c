// veneer normals — photometric stereo on one set: normals (PFM + picture),
// albedo, mask, residual/confidence picture, and, for simulated sets with
// truth/, the angular error against it (printed and in metrics.json).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "command.hpp"
#include "output.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/ps/calibration.hpp"
#include "veneer/ps/photometric_stereo.hpp"
#include "veneer/ps/segmentation.hpp"

namespace fs = std::filesystem;

namespace {

struct NormalsArgs {
  std::string set, out, rect, model = "automatic", lights;
  bool robust = false, plain = false, near_light = false, distant = false, otsu = false;
  double threshold = -1;
  bool supplied_mask = false, no_clean = false, keep_base = false, recorded_lights = false;
  // the solver's defaults are the library's (PsOptions)
  float shadow = veneer::ps::PsOptions{}.shadow_fraction, saturation = veneer::ps::PsOptions{}.saturation,
        outliers = veneer::ps::PsOptions{}.outlier_fraction, chroma = veneer::ps::PsOptions{}.diffuse_chroma;
  int iterations = veneer::ps::PsOptions{}.near_iterations, threads = 0;
};

::veneer::cli::Output report{"normals"};

bool parse_rect(const std::string& text, cv::Rect* r) {
  std::istringstream in(text);
  int x = 0, y = 0, w = 0, h = 0;
  char a = 0, b = 0, c = 0, extra = 0;
  if (!(in >> x >> a >> y >> b >> w >> c >> h) || a != ',' || b != ',' || c != ',' || (in >> extra)) return false;
  *r = {x, y, w, h};
  return true;
}

// Albedo is relative to a white Lambertian surface (1.0): shown as an sRGB picture.
cv::Mat albedo_picture(const cv::Mat& albedo) {
  cv::Mat out(albedo.size(), CV_8UC3);
  for (int y = 0; y < albedo.rows; ++y) {
    const cv::Vec3f* a = albedo.ptr<cv::Vec3f>(y);
    cv::Vec3b* o = out.ptr<cv::Vec3b>(y);
    for (int x = 0; x < albedo.cols; ++x)
      for (int c = 0; c < 3; ++c) {
        const float v = std::clamp(a[x][c], 0.f, 1.f);
        const float s = v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.f / 2.4f) - 0.055f;
        o[x][c] = static_cast<uint8_t>(std::lround(s * 255.f));
      }
  }
  return out;
}

int run_normals(const NormalsArgs& a) {
  if (a.set.empty()) return report.usage("a SET folder is required");
  if (a.out.empty()) return report.usage("--out is required");
  if (a.near_light && a.distant) return report.usage("--near-light and --distant exclude each other");
  if (a.robust && a.plain) return report.usage("--robust and --plain exclude each other");
  if (a.otsu && a.threshold >= 0) return report.usage("--otsu and --threshold exclude each other");
  if (a.plain) {
    // The plain least-squares solve keeps every sample: the robust solve's settings would do nothing.
    const veneer::ps::PsOptions d;
    for (auto [given, name] : {std::pair{a.shadow != d.shadow_fraction, "--shadow"},
                               std::pair{a.saturation != d.saturation, "--saturation"},
                               std::pair{a.outliers != d.outlier_fraction, "--outliers"},
                               std::pair{a.chroma != d.diffuse_chroma, "--chroma"}})
      if (given) return report.usage(std::string(name) + " tunes the robust solve, which --plain turns off: drop one of them");
  }

  veneer::ps::PsOptions po;
  po.robust = !a.plain;
  po.light_model = a.near_light ? veneer::ps::LightModel::near
                   : a.distant  ? veneer::ps::LightModel::distant
                                : veneer::ps::LightModel::automatic;
  po.shadow_fraction = a.shadow;
  po.saturation = a.saturation;
  po.outlier_fraction = a.outliers;
  po.refine_lights = !a.recorded_lights;
  po.diffuse_chroma = a.chroma;
  po.near_iterations = a.iterations;
  po.threads = a.threads;
  if (auto st = po.check(); !st) return report.usage(st.message());

  veneer::ps::SegmentOptions so;
  if (a.otsu) so.method = veneer::ps::SegmentMethod::otsu;
  if (a.threshold >= 0) {
    so.method = veneer::ps::SegmentMethod::threshold;
    so.threshold = a.threshold;
  }
  if (a.supplied_mask) so.method = veneer::ps::SegmentMethod::supplied;
  so.clean = !a.no_clean;
  if (!a.rect.empty()) {
    cv::Rect r;
    if (!parse_rect(a.rect, &r)) return report.usage("--rect '" + a.rect + "': expected x,y,w,h in pixels");
    so.rect = r;
  }
  if (auto st = so.check(); !st) return report.usage(st.message());

  veneer::cli::ProgressBar bar("normals");
  bar.update(0.0, "reading " + a.set);
  auto set = veneer::io::read_set(a.set);
  if (set && !a.lights.empty()) {
    // Lamps calibrated from a chrome sphere (`veneer calibrate`) replace the set's.
    auto cal = veneer::ps::read_light_calibration(a.lights);
    if (!cal) return report.fail(cal.message());
    if (auto st = veneer::ps::apply_calibration(*set, *cal); !st)
      return report.fail("--lights " + a.lights + ": " + st.message());
  }
  if (set && a.near_light) {
    // Near light needs where each lamp is and the camera's focal length.
    int without = 0;
    for (const auto& l : set->lights) without += l.position_m ? 0 : 1;
    if (without > 0 || set->camera.focal_px <= 0)
      return report.usage("--near-light needs the lamps' positions and the camera's focal length, and " + a.set +
                         (without > 0 ? " gives no position for " + std::to_string(without) + " of its " +
                                            std::to_string(set->lights.size()) + " lamps"
                                      : std::string(" gives no camera focal length (camera.focal_px)")) +
                         ": leave --near-light out (distant lights, from the directions) or add them to set.json");
  }
  if (!set) return report.fail(set.message());
  bar.update(0.3, "segmenting");
  auto seg = veneer::ps::segment(*set, so);
  if (!seg) return report.fail(seg.message());
  veneer::Progress progress;
  progress.on_progress = [&bar](double f, const std::string& stage) { bar.update(0.35 + 0.45 * f, stage); };
  auto res = veneer::ps::photometric_stereo(*set, seg->mask, po, progress);
  if (!res) return report.fail(res.message());
  // A base the object stands on is not the object (a supplied mask is the user's word).
  veneer::ps::SupportRemoval base;
  if (seg->method_used != veneer::ps::SegmentMethod::supplied && !a.keep_base) base = veneer::ps::drop_supports(*res);

  bar.update(0.85, "writing " + a.out);
  if (auto st = report.folder(a.out); !st) return report.fail(st.message());
  if (auto st = report.pfm("normals.pfm", res->normals, true); !st) return report.fail(st.message());
  if (auto st = report.picture("normals.png", veneer::io::normals_picture(res->normals)); !st)
    return report.fail(st.message());
  if (auto st = report.pfm("albedo.pfm", res->albedo, false); !st) return report.fail(st.message());
  if (auto st = report.picture("albedo.png", albedo_picture(res->albedo)); !st) return report.fail(st.message());
  if (auto st = report.picture("mask.png", res->mask); !st) return report.fail(st.message());
  if (auto st = report.picture("reliable.png", res->reliable); !st) return report.fail(st.message());
  if (auto st = report.pfm("residual.pfm", res->residual, false); !st) return report.fail(st.message());
  if (auto st = report.picture("residual.png", veneer::ps::residual_picture(*res)); !st)
    return report.fail(st.message());
  if (!res->depth.empty()) {
    if (auto st = report.pfm("depth.pfm", res->depth, false); !st) return report.fail(st.message());
  }

  nlohmann::json m;
  m["set"] = a.set;
  m["size"] = {res->normals.cols, res->normals.rows};
  m["lights"] = set->images.size();
  m["light_model"] = veneer::ps::light_model_name(res->model_used);
  if (!a.lights.empty()) m["lights_file"] = a.lights;
  m["robust"] = po.robust;
  m["segmentation"] = veneer::ps::segment_method_name(seg->method_used);
  m["threshold"] = seg->threshold;
  m["base_dropped_pixels"] = base.removed_pixels;
  m["lights_refined"] = res->lights_refined;
  if (res->lights_refined) {
    nlohmann::json lamps = nlohmann::json::array();
    for (size_t i = 0; i < res->lights.size(); ++i) {
      const auto& l = res->lights[i];
      lamps.push_back({{"index", i},
                       {"direction", {l.direction[0], l.direction[1], l.direction[2]}},
                       {"intensity", {l.intensity[0], l.intensity[1], l.intensity[2]}},
                       {"moved_deg", res->light_change_deg[i]}});
    }
    m["refined_lights"] = lamps;
  }
  m["object_pixels"] = res->solved_pixels;
  m["unreliable_pixels"] = res->unreliable_pixels;
  m["mean_residual"] = cv::mean(res->residual, res->mask)[0];
  bar.update(1.0, "done");
  bar.done();
  std::printf("normals: %s, %d object pixels (%s), %s lights%s, %d unreliable\n", a.set.c_str(), res->solved_pixels,
              veneer::ps::segment_method_name(seg->method_used), veneer::ps::light_model_name(res->model_used),
              po.robust ? ", robust" : "", res->unreliable_pixels);
  if (res->lights_refined) {
    const auto [lo, hi] = std::minmax_element(res->light_change_deg.begin(), res->light_change_deg.end());
    std::printf("lamp directions refined from the photos: moved %.1f-%.1f deg (metrics.json: refined_lights; "
                "--recorded-lights keeps the set's)\n", *lo, *hi);
  }
  if (base.removed_pixels > 0)
    std::printf("left out a base the object stands on: %d pixels on %d flat faces (--keep-base keeps it)\n",
                base.removed_pixels, base.planes);
  if (set->truth.present()) {
    const cv::Mat& tm = set->truth.mask.empty() ? res->mask : set->truth.mask;
    cv::Mat both;
    cv::bitwise_and(tm, res->mask, both);
    auto e = veneer::ps::angular_error(res->normals, set->truth.normals, both);
    m["angular_error_deg"] = {{"mean", e.mean_deg}, {"median", e.median_deg}, {"p95", e.p95_deg},
                              {"max", e.max_deg},   {"pixels", e.pixels}};
    std::printf("angular error vs truth: mean %.2f deg, median %.2f, 95th percentile %.2f (%d pixels)\n", e.mean_deg,
                e.median_deg, e.p95_deg, e.pixels);
  }
  if (auto st = report.json("metrics.json", m); !st) return report.fail(st.message());
  return report.wrote();
}

}  // namespace

VENEER_ARGS_COMMAND(normals, NormalsArgs,
                    "photometric stereo on a set: normals (PFM + picture), albedo, mask, residual; angular error "
                    "when the set has truth/. Default: robust, near-light when the lamp positions and focal length "
                    "are known, the set's own mask if it has one, else the object against the backdrop under its "
                    "brightest lamp (contrast), a base it stands on left out") {
  cmd->add_option("SET", args->set, "image set folder (veneer-set/1, DiLiGenT or thesis layout)");
  cmd->add_option("--out", args->out, "output folder");
  cmd->add_flag("--robust", args->robust, "drop shadowed and saturated samples per pixel (the default)");
  cmd->add_flag("--plain", args->plain, "plain least squares over every sample");
  cmd->add_flag("--near-light", args->near_light, "per-pixel light vectors from the lamp positions, 1/r^2 falloff");
  cmd->add_flag("--distant", args->distant, "one light direction per lamp for the whole image");
  cmd->add_option("--threshold", args->threshold,
                  "segment by the mean intensity over lamps (the thesis's summed-intensity threshold), 0..1");
  cmd->add_flag("--otsu", args->otsu, "segment by Otsu's threshold on the summed intensity");
  cmd->add_flag("--supplied-mask", args->supplied_mask, "use the set's own mask (fail when it has none)");
  cmd->add_option("--rect", args->rect, "limit the object to the rectangle x,y,w,h (pixels)");
  cmd->add_flag("--no-clean", args->no_clean, "keep specks and holes in a thresholded mask");
  cmd->add_option("--lights", args->lights,
                  "lamp directions (and positions) from `veneer calibrate` instead of the set's");
  cmd->add_flag("--recorded-lights", args->recorded_lights,
                "use the set's lamp directions and intensities as recorded (by default, with distant lights, they are refined from the photos)");
  cmd->add_flag("--keep-base", args->keep_base, "keep a plinth, stand or table top the object stands on in the mask (left out by default)");
  cmd->add_option("--shadow", args->shadow, "robust: shadow threshold as a fraction of the pixel's brightest sample")
      ->capture_default_str();
  cmd->add_option("--saturation", args->saturation, "robust: a sample at or above this level is saturated")
      ->capture_default_str();
  cmd->add_option("--outliers", args->outliers,
                  "robust: drop the sample farthest from a first fit when off by more than this fraction of the "
                  "pixel's brightest sample (cast shadows, highlights on grey surfaces); 0 = off")
      ->capture_default_str();
  cmd->add_option("--diffuse-chroma", args->chroma,
                  "robust: solve pixels at least this coloured (|sum of colour - grey| / sum of grey over the lamps) "
                  "on their colour's off-grey part, which a glossy highlight (the lamps' colour) does not reach; "
                  "0 = off")
      ->capture_default_str();
  cmd->add_option("--iterations", args->iterations, "near-light depth refinements (0..5)")->capture_default_str();
  cmd->add_option("--threads", args->threads, "worker threads (0 = all cores)")->capture_default_str();
  return [args] { return run_normals(*args); };
}
