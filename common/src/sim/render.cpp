// The ray caster: camera rays once per image geometry (a cached G-buffer of
// hit point, normals, albedo, specular parameters; pixels on an outline or a
// crease also get a grid of samples over their square), then one cheap
// shading pass per shot: Lambert x albedo + Blinn-Phong lobe, attached and
// cast shadows (a shadow ray to the point lamp), 1/r^2 falloff, ambient,
// exposure, the optical low-pass filter, counter-based Gaussian noise,
// clipping to [0, 1] like a sensor.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <cstdlib>
#include <numbers>
#include <vector>

#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "noise.hpp"
#include "scene.hpp"
#include "veneer/sim/simulator.hpp"
#include "veneer/util/log.hpp"
#include "veneer/util/utc_time.hpp"

namespace veneer::sim {

namespace {

constexpr double kRingRadius = 0.47;  // m, the thesis rig's lamp circle
constexpr double kCameraZ = 1.0;      // m, camera (and lamp plane) distance from the object
// A rig lamp at full white delivers irradiance 1 at the origin: its radiant
// intensity is |lamp|^2 = 1 + 0.47^2 in these units.
constexpr double kRigIntensity = kCameraZ * kCameraZ + kRingRadius * kRingRadius;
constexpr double kShadowEps = 2e-5;  // m, shadow-ray start offset along the geometric normal

template <class F>
void for_rows(int rows, int threads, F&& body) {
  auto run = [&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, rows, 4), [&](const tbb::blocked_range<int>& r) {
      for (int y = r.begin(); y < r.end(); ++y) body(y);
    });
  };
  if (threads > 0) {
    tbb::task_arena arena(threads);
    arena.execute(run);
  } else {
    run();
  }
}

V3 f3(const float* v) { return {v[0], v[1], v[2]}; }
void set3(float* dst, const V3& v) {
  dst[0] = static_cast<float>(v.x);
  dst[1] = static_cast<float>(v.y);
  dst[2] = static_cast<float>(v.z);
}

// The standard normal distribution as 65 536 equally likely values: the
// quantiles Phi^-1((i + 0.5) / 65536), tails to +-4.3 sigma. A 16-bit index
// from the pixel's hash picks one, which is far cheaper than Box-Muller and
// exactly reproducible.
const std::vector<float>& normal_quantiles() {
  static const std::vector<float> table = [] {
    constexpr int n = 65536;
    std::vector<float> t(n);
    auto cdf = [](double x) { return 0.5 * std::erfc(-x / std::numbers::sqrt2); };
    double x = 0;
    for (int i = n / 2; i < n; ++i) {
      double p = (i + 0.5) / n;
      for (int it = 0; it < 8; ++it) {  // Newton from the previous quantile
        double step = (cdf(x) - p) / (std::exp(-0.5 * x * x) / std::sqrt(2 * std::numbers::pi));
        x -= step;
        if (std::abs(step) < 1e-12) break;
      }
      t[i] = static_cast<float>(x);
      t[n - 1 - i] = static_cast<float>(-x);
    }
    return t;
  }();
  return table;
}

// Three independent standard normal deviates for (key, pixel).
void gauss3(const float* quantiles, uint64_t key, uint64_t pixel, double out[3]) {
  uint64_t h = hash_combine(key, pixel);
  out[0] = quantiles[h & 0xffff];
  out[1] = quantiles[(h >> 16) & 0xffff];
  out[2] = quantiles[(h >> 32) & 0xffff];
}

std::string created_now() {
  // SOURCE_DATE_EPOCH (reproducible-builds convention) pins the timestamp, so
  // two runs with the same seed can produce byte-identical manifests.
  std::time_t t = std::time(nullptr);
  if (const char* epoch = std::getenv("SOURCE_DATE_EPOCH")) t = static_cast<std::time_t>(std::atoll(epoch));
  return utc_time(t);
}

}  // namespace

double default_focal(int width) {
  // An 8 cm object at 1 m covers about 21 000 pixels at 1024 px wide (as in the thesis).
  return 2.0 * width;
}

std::vector<Lamp> thesis_rig() {
  // Sockets every 45 degrees, starting at the top and going clockwise as seen
  // in the picture (i.e. from the camera looking at the object): top,
  // top-right, right, bottom-right, [bottom: empty], bottom-left, left, top-left.
  std::vector<Lamp> lamps;
  for (int socket = 0; socket < 8; ++socket) {
    if (socket == 4) continue;
    double a = socket * std::numbers::pi / 4;
    Lamp lamp;
    auto snap = [](double v) { return std::abs(v) < 1e-12 ? 0.0 : v; };  // exact zeros on the axes
    lamp.position_m = {snap(kRingRadius * std::sin(a)), snap(kRingRadius * std::cos(a)), kCameraZ};
    lamps.push_back(lamp);
  }
  return lamps;
}

Status RenderOptions::check() const {
  if (size.width < 8 || size.height < 8 || size.width > 16384 || size.height > 16384)
    return make_error("render options: size " + std::to_string(size.width) + "x" + std::to_string(size.height) +
                      " is outside 8x8 .. 16384x16384");
  if (!(focal_px >= 0) || !std::isfinite(focal_px)) return make_error("render options: focal_px must be >= 0");
  if (!(exposure > 0) || !std::isfinite(exposure)) return make_error("render options: exposure must be > 0");
  if (!(noise_sigma >= 0) || noise_sigma > 1) return make_error("render options: noise_sigma must be in [0, 1]");
  if (!(ambient >= 0) || !std::isfinite(ambient)) return make_error("render options: ambient must be >= 0");
  if (!(scale > 0) || scale > 10) return make_error("render options: scale must be in (0, 10]");
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(offset_m[i]) || std::abs(offset_m[i]) > 0.5)
      return make_error("render options: offset_m components must be within +-0.5 m");
  }
  if (threads < 0) return make_error("render options: threads must be >= 0");
  if (edge_samples < 1 || edge_samples > 16) return make_error("render options: edge_samples must be in 1..16");
  if (!(olpf_spread_px >= 0) || olpf_spread_px > 2) return make_error("render options: olpf_spread_px must be in [0, 2]");
  return Status::success();
}

Expected<std::shared_ptr<const Scene>> make_scene(const std::string& name, const RenderOptions& options) {
  if (auto st = options.check(); !st) return st.error();
  auto scene = build_scene(name);
  if (!scene) {
    std::string known;
    for (const auto& n : scene_names()) known += (known.empty() ? "" : ", ") + n;
    return make_error("unknown scene '" + name + "' (known: " + known + ")");
  }
  scene->offset = {options.offset_m[0], options.offset_m[1], options.offset_m[2]};
  scene->scale = options.scale;
  std::shared_ptr<const Scene> shared = std::move(scene);
  return shared;
}

namespace {

// Whether two neighbouring centre samples see different geometry, where a
// point sample per pixel would alias: another surface (outline, the table, a
// plinth), another primitive (a crease where two meet), or a fold. Texture
// (albedo, bumps) at pixel scale is left to the optical low-pass filter, as
// sampling it finer would cost several material evaluations per pixel.
bool geometry_differs(const GPixel& a, const GPixel& b) {
  if (a.kind != b.kind) return true;
  if (a.kind == 0 || a.kind == 1) return false;
  if (a.prim != b.prim) return true;
  return dot(f3(a.ng), f3(b.ng)) < 0.9962;  // 5 degrees
}

}  // namespace

std::shared_ptr<const GBuffer> Scene::gbuffer(cv::Size size, double focal, int edge_samples, int threads) const {
  edge_samples = std::max(1, edge_samples);
  {
    std::lock_guard lock(mutex_);
    if (cache_ && cache_->size == size && cache_->focal == focal && cache_->edge_samples == edge_samples) return cache_;
  }
  auto gb = std::make_shared<GBuffer>();
  gb->size = size;
  gb->focal = focal;
  gb->edge_samples = edge_samples;
  gb->cx = (size.width - 1) * 0.5;
  gb->cy = (size.height - 1) * 0.5;
  gb->px.resize(static_cast<size_t>(size.area()));
  const V3 camera{0, 0, kCameraZ};
  const V3 cam_obj = to_object(camera);
  const double table_z_world = table_world_z();
  // The camera ray through image point (x, y) (pixel centres at integers).
  auto cast = [&](double x, double y, GPixel& g) {
    g = GPixel{};
    g.prim = -1;
    V3 d = normalize({(x - gb->cx) / focal, -(y - gb->cy) / focal, -1.0});
    V3 n;
    int prim = -1;
    double t_obj = shape.intersect(cam_obj, d, 1e-9, 1e9, &n, &prim);
    if (t_obj > 0) {
      V3 p_obj = cam_obj + d * t_obj;
      SurfaceSample s;
      s.normal = n;
      material(p_obj, n, prim, shape.prims[static_cast<size_t>(prim)].part, &s);
      V3 ns = normalize(s.normal);
      if (dot(ns, d) > -0.02) ns = normalize(ns - d * (dot(ns, d) + 0.02));  // keep bumps facing the camera
      set3(g.p, to_world(p_obj));
      set3(g.ng, n);
      set3(g.n, ns);
      set3(g.albedo, s.albedo);
      g.ks = static_cast<float>(s.ks);
      g.shininess = static_cast<float>(s.shininess);
      g.prim = prim;
      g.kind = shape.prims[static_cast<size_t>(prim)].part == support_part ? 3 : 2;
    } else if (d.z < 0) {
      double t = (table_z_world - camera.z) / d.z;
      V3 p = camera + d * t;
      // a faint speckled cloth (cells of 0.5 mm, about a pixel): dark, never flat zero
      double v = 0.85 + 0.3 * cell_rand(static_cast<int>(std::floor(p.x * 2000)),
                                        static_cast<int>(std::floor(p.y * 2000)), 0, 991);
      set3(g.p, p);
      set3(g.ng, {0, 0, 1});
      set3(g.n, {0, 0, 1});
      set3(g.albedo, table_albedo * v);
      g.ks = 0;
      g.shininess = 1;
      g.kind = 1;
    }
  };
  for_rows(size.height, threads, [&](int y) {
    for (int x = 0; x < size.width; ++x) cast(x, y, gb->px[static_cast<size_t>(y) * size.width + x]);
  });
  if (edge_samples > 1) {
    // Pixels whose centre differs from a 4-neighbour's get the box aperture.
    const int w = size.width, h = size.height;
    std::vector<uint8_t> flagged(static_cast<size_t>(size.area()), 0);
    for_rows(h, threads, [&](int y) {
      for (int x = 0; x < w; ++x) {
        const size_t i = static_cast<size_t>(y) * w + x;
        const GPixel& g = gb->px[i];
        flagged[i] = (x > 0 && geometry_differs(g, gb->px[i - 1])) || (x + 1 < w && geometry_differs(g, gb->px[i + 1])) ||
                     (y > 0 && geometry_differs(g, gb->px[i - w])) || (y + 1 < h && geometry_differs(g, gb->px[i + w]));
      }
    });
    const uint32_t per = static_cast<uint32_t>(edge_samples * edge_samples);
    gb->first.assign(flagged.size() + 1, 0);
    for (size_t i = 0; i < flagged.size(); ++i) gb->first[i + 1] = gb->first[i] + (flagged[i] ? per : 0);
    gb->sub.resize(gb->first.back());
    for_rows(h, threads, [&](int y) {
      for (int x = 0; x < w; ++x) {
        const size_t i = static_cast<size_t>(y) * w + x;
        if (!flagged[i]) continue;
        GPixel* out = gb->sub.data() + gb->first[i];
        for (int sy = 0; sy < edge_samples; ++sy)
          for (int sx = 0; sx < edge_samples; ++sx)
            cast(x - 0.5 + (sx + 0.5) / edge_samples, y - 0.5 + (sy + 0.5) / edge_samples, *out++);
      }
    });
  }
  std::shared_ptr<const GBuffer> result = gb;
  std::lock_guard lock(mutex_);
  cache_ = result;
  return result;
}

namespace {

struct ShotLamp {
  V3 pos;
  V3 radiant;  // RGB radiant intensity (irradiance = radiant / r^2)
};

// The optical low-pass filter on a float image, in place: a birefringent
// filter splits each ray into spots +-spread/2 px apart in x and in y (4
// spots), here on the pixel grid by linear interpolation. spread 1 is the
// kernel [1/4 1/2 1/4] per axis, which has a zero at the sensor's Nyquist
// frequency (where a Bayer mosaic's colours alias into each other).
void low_pass(cv::Mat& img, double spread) {
  if (!(spread > 0)) return;
  const double h = spread / 2;  // each spot's shift, <= 1 px
  const cv::Mat k = (cv::Mat_<float>(3, 1) << static_cast<float>(h / 2), static_cast<float>(1 - h), static_cast<float>(h / 2));
  cv::sepFilter2D(img, img, -1, k, k, cv::Point(-1, -1), 0, cv::BORDER_REFLECT);
}

// Shades one shot from the G-buffer into a BGR CV_32FC3: each pixel the mean
// radiance over its samples, x exposure, low-pass filtered, then sensor noise
// and clipping.
cv::Mat shade(const Scene& scene, const GBuffer& gb, const std::vector<ShotLamp>& lamps, const RenderOptions& o) {
  cv::Mat out(gb.size, CV_32FC3);
  const V3 camera{0, 0, kCameraZ};
  const uint64_t key = hash_combine(hash_combine(0x7665'6e65'6572ULL, o.seed), o.shot);
  const double inv_scale = 1.0 / scene.scale;
  const float* quantiles = normal_quantiles().data();
  auto radiance = [&](const GPixel& g) {
    V3 rgb{0, 0, 0};
    if (g.kind == 0) return rgb;
    V3 p = f3(g.p), n = f3(g.n), ng = f3(g.ng), albedo = f3(g.albedo);
    V3 v = normalize(camera - p);
    V3 shadow_origin = scene.to_object(p + ng * kShadowEps);
    for (const auto& lamp : lamps) {
      V3 L = lamp.pos - p;
      double r2 = dot(L, L), r = std::sqrt(r2);
      V3 l = L / r;
      double ndl = dot(n, l);
      if (ndl <= 0 || dot(ng, l) <= 0) continue;  // attached shadow
      if (o.cast_shadows && scene.shape.occluded(shadow_origin, l, 1e-9, (r - kShadowEps) * inv_scale))
        continue;  // cast shadow
      V3 E = lamp.radiant / r2;
      double spec = 0;
      if (g.ks > 0) {
        V3 hv = normalize(l + v);
        double ndh = dot(n, hv);
        if (ndh > 0) spec = g.ks * std::pow(ndh, static_cast<double>(g.shininess));
      }
      rgb += mul(E, albedo * ndl + V3{spec, spec, spec});
    }
    rgb += albedo * o.ambient;
    return rgb;
  };
  for_rows(gb.size.height, o.threads, [&](int y) {
    auto* row = out.ptr<cv::Vec3f>(y);
    for (int x = 0; x < gb.size.width; ++x) {
      const auto [begin, end] = gb.samples(static_cast<size_t>(y) * gb.size.width + x);
      V3 rgb{0, 0, 0};
      for (const GPixel* g = begin; g != end; ++g) rgb += radiance(*g);
      rgb = rgb * (o.exposure / static_cast<double>(end - begin));
      row[x] = cv::Vec3f(static_cast<float>(rgb.z), static_cast<float>(rgb.y), static_cast<float>(rgb.x));  // BGR
    }
  });
  low_pass(out, o.olpf_spread_px);
  for_rows(gb.size.height, o.threads, [&](int y) {
    auto* row = out.ptr<cv::Vec3f>(y);
    for (int x = 0; x < gb.size.width; ++x) {
      cv::Vec3f& v = row[x];
      if (o.noise_sigma > 0) {
        double nz[3];
        gauss3(quantiles, key, static_cast<size_t>(y) * gb.size.width + x, nz);
        // (the noise triple is drawn in r, g, b order)
        v[2] = static_cast<float>(v[2] + nz[0] * o.noise_sigma);
        v[1] = static_cast<float>(v[1] + nz[1] * o.noise_sigma);
        v[0] = static_cast<float>(v[0] + nz[2] * o.noise_sigma);
      }
      for (int c = 0; c < 3; ++c) v[c] = std::clamp(v[c], 0.0f, 1.0f);  // clipped like a sensor
    }
  });
  return out;
}

std::vector<ShotLamp> shot_lamps(const std::vector<Lamp>& lamps) {
  std::vector<ShotLamp> out;
  for (const auto& l : lamps) {
    double k = kRigIntensity * std::clamp(static_cast<double>(l.brightness), 0.0, 1.0);
    if (k <= 0) continue;
    out.push_back({{l.position_m[0], l.position_m[1], l.position_m[2]},
                   {l.color[0] * k, l.color[1] * k, l.color[2] * k}});
  }
  return out;
}

double focal_for(const RenderOptions& o) { return o.focal_px > 0 ? o.focal_px : default_focal(o.size.width); }

}  // namespace

cv::Mat render(const Scene& scene, const std::vector<Lamp>& lamps, const RenderOptions& options,
               const Progress& progress) {
  if (auto st = options.check(); !st) {
    VLOG_ERROR("Sim", "render: {}", st.message());
    return {};
  }
  progress.report(0.0, "casting camera rays");
  auto gb = scene.gbuffer(options.size, focal_for(options), options.edge_samples, options.threads);
  if (progress.cancelled()) return {};
  progress.report(0.5, "shading");
  cv::Mat out = shade(scene, *gb, shot_lamps(lamps), options);
  progress.report(1.0, "done");
  return out;
}

io::Truth render_truth(const Scene& scene, const RenderOptions& options) {
  io::Truth t;
  if (auto st = options.check(); !st) {
    VLOG_ERROR("Sim", "render_truth: {}", st.message());
    return t;
  }
  auto gb = scene.gbuffer(options.size, focal_for(options), options.edge_samples, options.threads);
  const cv::Size size = gb->size;
  t.normals = cv::Mat(size, CV_32FC3, cv::Scalar::all(0));
  t.mask = cv::Mat(size, CV_8UC1, cv::Scalar::all(0));
  t.albedo = cv::Mat(size, CV_32FC3, cv::Scalar::all(0));
  t.depth = cv::Mat(size, CV_32FC1, cv::Scalar::all(0));
  // In bands of rows, each with the one row either side the low-pass filter
  // reads (its 3x3 kernel gives a band's own rows as the whole image would:
  // the image's edges are a band's edges too): the sums below are 32 bytes a
  // pixel, 0.6 GiB at 5600x3750 for the whole image, a few MB for a band.
  const int band = 256;
  const int halo = options.olpf_spread_px > 0 ? 1 : 0;
  for (int y0 = 0; y0 < size.height; y0 += band) {
    const int y1 = std::min(size.height, y0 + band);
    const int a = std::max(0, y0 - halo), b = std::min(size.height, y1 + halo);
    const cv::Size bs(size.width, b - a);
    // Per pixel, over its samples: the object's coverage, its albedo-weighted
    // normal, albedo and depth sums (as fractions of the samples); then the
    // same low-pass filter as the photos.
    cv::Mat cover(bs, CV_32FC1), weighted_n(bs, CV_32FC3), albedo(bs, CV_32FC3), depth(bs, CV_32FC1);
    for_rows(bs.height, options.threads, [&](int by) {
      const int y = a + by;
      for (int x = 0; x < size.width; ++x) {
        const auto [begin, end] = gb->samples(static_cast<size_t>(y) * size.width + x);
        double c = 0, d = 0;
        V3 n{0, 0, 0}, al{0, 0, 0};
        for (const GPixel* g = begin; g != end; ++g) {
          if (g->kind != 2) continue;
          const V3 ga = f3(g->albedo);
          c += 1;
          n += f3(g->n) * ((ga.x + ga.y + ga.z) / 3 + 1e-6);
          al += ga;
          d += kCameraZ - g->p[2];
        }
        const double k = 1.0 / static_cast<double>(end - begin);
        cover.at<float>(by, x) = static_cast<float>(c * k);
        weighted_n.at<cv::Vec3f>(by, x) = {static_cast<float>(n.x * k), static_cast<float>(n.y * k),
                                           static_cast<float>(n.z * k)};
        albedo.at<cv::Vec3f>(by, x) = {static_cast<float>(al.z * k), static_cast<float>(al.y * k),
                                       static_cast<float>(al.x * k)};
        depth.at<float>(by, x) = static_cast<float>(d * k);
      }
    });
    for (cv::Mat* m : {&cover, &weighted_n, &albedo, &depth}) low_pass(*m, options.olpf_spread_px);
    for (int y = y0; y < y1; ++y) {
      const int by = y - a;
      for (int x = 0; x < size.width; ++x) {
        const float c = cover.at<float>(by, x);
        const cv::Vec3f n = weighted_n.at<cv::Vec3f>(by, x);
        const double len = cv::norm(n);
        if (c < 0.5f || !(len > 0)) continue;
        t.normals.at<cv::Vec3f>(y, x) = n / static_cast<float>(len);
        if (!(options.olpf_spread_px > 0)) {
          // a point-sampled pixel keeps its sample's normal bit for bit (whatever the albedo)
          const auto [begin, end] = gb->samples(static_cast<size_t>(y) * size.width + x);
          if (end - begin == 1) t.normals.at<cv::Vec3f>(y, x) = {begin->n[0], begin->n[1], begin->n[2]};
        }
        t.mask.at<uint8_t>(y, x) = 255;
        t.albedo.at<cv::Vec3f>(y, x) = albedo.at<cv::Vec3f>(by, x) / c;
        t.depth.at<float>(y, x) = depth.at<float>(by, x) / c;
      }
    }
  }
  return t;
}

namespace {

// simulate_set of a scene made already; `object` names it in the set (its
// object name and id), `scene_name` is the shape's scene.
Expected<io::ImageSet> simulate_scene_set(const Scene& scene, const std::string& scene_name, const std::string& object,
                                      const RenderOptions& options, io::Role role, const Progress& progress) {
  const auto lamps = thesis_rig();
  const double focal = focal_for(options);

  io::ImageSet set;
  set.role = role;
  set.object = object;
  set.scene = scene_name;
  set.id = "sim-" + object + "-" + std::to_string(options.seed);
  set.created = created_now();
  set.size = options.size;
  set.camera.model = "veneer simulated camera";
  set.camera.exposure_s = options.exposure / 30.0;  // 1/30 s, f/8, ISO 100 is gain 1
  set.camera.aperture = 8.0;
  set.camera.iso = 100;
  set.camera.focal_px = focal;
  set.camera.cx = (options.size.width - 1) * 0.5;
  set.camera.cy = (options.size.height - 1) * 0.5;

  const int shots = static_cast<int>(lamps.size()) + 1;
  progress.report(0.0, "casting camera rays");
  auto gb = scene.gbuffer(options.size, focal, options.edge_samples, options.threads);
  for (size_t i = 0; i < lamps.size(); ++i) {
    if (progress.cancelled()) return make_error("simulate " + object + ": cancelled");
    progress.report((0.3 + i) / shots, "lamp " + std::to_string(i + 1));
    RenderOptions o = options;
    o.shot = static_cast<uint32_t>(i);
    set.images.push_back(shade(scene, *gb, shot_lamps({lamps[i]}), o));
    io::Light light;
    light.index = static_cast<int>(i);
    light.lamp_id = "sim-" + std::to_string(i);
    cv::Vec3d pos = lamps[i].position_m;
    light.position_m = pos;
    light.direction = pos / cv::norm(pos);
    // irradiance at the origin, in image units (exposure folded in, so the
    // albedo photometric stereo recovers is the material's albedo)
    double e = kRigIntensity * lamps[i].brightness / pos.dot(pos) * options.exposure;
    light.intensity = cv::Vec3f(static_cast<float>(lamps[i].color[0] * e), static_cast<float>(lamps[i].color[1] * e),
                                static_cast<float>(lamps[i].color[2] * e));
    set.lights.push_back(light);
  }
  if (progress.cancelled()) return make_error("simulate " + object + ": cancelled");
  progress.report((shots - 0.7) / shots, "ambient frame");
  RenderOptions o = options;
  o.shot = 255;
  set.ambient = shade(scene, *gb, {}, o);
  set.truth = render_truth(scene, options);
  progress.report(1.0, "done");
  return set;
}

}  // namespace

Expected<io::ImageSet> simulate_set(const std::string& scene_name, const RenderOptions& options, io::Role role,
                                const Progress& progress) {
  auto scene = make_scene(scene_name, options);
  if (!scene) return scene.error();
  return simulate_scene_set(**scene, scene_name, scene_name, options, role, progress);
}

Expected<io::ImageSet> simulate_set_with_material(const std::string& shape_scene, const std::string& material_scene,
                                              const RenderOptions& options, io::Role role, const Progress& progress) {
  auto scene = make_scene_with_material(shape_scene, material_scene, options);
  if (!scene) return scene.error();
  return simulate_scene_set(**scene, shape_scene, shape_scene + "-in-" + material_scene, options, role, progress);
}

}  // namespace veneer::sim
