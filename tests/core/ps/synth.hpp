#pragma once
// An analytic Lambertian sphere under point lamps (the Light::intensity
// convention of imageset.hpp) or distant lights, with exact truth: the oracle
// for the photometric-stereo tests and bench, independent of the simulator.
#include <cmath>
#include <random>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"

namespace veneer::ps::test {

struct SynthOptions {
  cv::Size size{256, 170};
  double focal_scale = 1.3;        // focal length = focal_scale * width [px]
  cv::Vec3d center{0, 0, 0};       // sphere centre, rig frame [m]
  double radius = 0.08;            // [m]
  cv::Vec3f albedo_bgr{0.5f, 0.6f, 0.7f};
  bool distant = false;            // true: directional lights (no falloff, constant direction)
  double noise = 0.0;              // Gaussian noise sigma (full scale 1)
  double ambient = 0.0;            // uniform ambient added to every photo (and the ambient frame)
  unsigned seed = 1;
  double lamp_intensity = 1.0;
  cv::Vec3f lamp_tint{1.f, 1.f, 1.f};  // every lamp's colour, RGB (multiplies lamp_intensity)
  double specular = 0.0;           // Blinn-Phong highlight in the lamp's colour: specular * (n . h)^shininess
  double shininess = 40.0;
  // What a calibrated real rig gets wrong: the set records each lamp's
  // direction turned by a random angle in [light_error_min_deg,
  // light_error_deg] about a random axis (the photos use the true one), and
  // its intensity scaled by 1 +- intensity_error.
  double light_error_deg = 0.0;
  double light_error_min_deg = 0.0;
  double intensity_error = 0.0;
  // Cast shadows: an unseen sphere (outside the camera's view) between some
  // lamps and the object blocks their light (radius 0 = none).
  cv::Vec3d occluder_center{0, 0, 0};
  double occluder_radius = 0.0;
  int lamps = 0;                   // 0 = the thesis rig's 7; else that many on two rings (DiLiGenT-like)
};

// The thesis rig: 8 sockets on a 0.47 m circle around the camera at (0,0,1), bottom one empty.
inline std::vector<cv::Vec3d> rig_positions() {
  std::vector<cv::Vec3d> p;
  for (int k = 0; k < 8; ++k) {
    const double a = k * CV_PI / 4;
    if (k == 6) continue;  // 270 degrees: the empty bottom socket
    p.emplace_back(0.47 * std::cos(a), 0.47 * std::sin(a), 1.0);
  }
  return p;
}

inline io::ImageSet synth_sphere(const SynthOptions& o) {
  io::ImageSet set;
  set.id = "synth";
  set.object = "sphere";
  set.size = o.size;
  const double f = o.focal_scale * o.size.width, cx = (o.size.width - 1) * 0.5, cy = (o.size.height - 1) * 0.5;
  set.camera.focal_px = f;
  set.camera.cx = cx;
  set.camera.cy = cy;
  std::vector<cv::Vec3d> pos = rig_positions();
  if (o.lamps > 0) {  // two rings, 0.35 m and 0.7 m (19 and 35 degrees), around the camera at 1 m
    pos.clear();
    for (int k = 0; k < o.lamps; ++k) {
      const double r = (k % 2) ? 0.7 : 0.35, a = 2 * CV_PI * k / o.lamps + 0.3;
      pos.emplace_back(r * std::cos(a), r * std::sin(a), 1.0);
    }
  }
  const int n = static_cast<int>(pos.size());
  std::mt19937 lamp_rng(o.seed * 7919u + 17u);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  std::vector<cv::Vec3d> true_dirs;
  for (int i = 0; i < n; ++i) {
    io::Light l;
    l.index = i;
    l.lamp_id = "synth-" + std::to_string(i);
    l.direction = pos[i] / cv::norm(pos[i]);
    if (!o.distant) l.position_m = pos[i];
    l.intensity = o.lamp_tint * float(o.lamp_intensity);
    set.lights.push_back(l);
    true_dirs.push_back(l.direction);
    if (o.light_error_deg > 0) {  // what the set records: turned about a random axis
      cv::Vec3d axis(uni(lamp_rng) - 0.5, uni(lamp_rng) - 0.5, uni(lamp_rng) - 0.5);
      axis -= axis.dot(l.direction) * l.direction;
      axis /= cv::norm(axis);
      const double ang = (o.light_error_min_deg + (o.light_error_deg - o.light_error_min_deg) * uni(lamp_rng)) * CV_PI / 180;
      const cv::Vec3d d = l.direction;
      set.lights.back().direction = d * std::cos(ang) + axis.cross(d) * std::sin(ang);
      if (!o.distant) set.lights.back().position_m = cv::norm(pos[i]) * set.lights.back().direction;
    }
    if (o.intensity_error > 0)
      set.lights.back().intensity *= static_cast<float>(1.0 + o.intensity_error * (2 * uni(lamp_rng) - 1));
    set.images.emplace_back(o.size, CV_32FC3, cv::Scalar::all(o.ambient));
  }
  if (o.ambient > 0) set.ambient = cv::Mat(o.size, CV_32FC3, cv::Scalar::all(o.ambient));
  set.truth.normals = cv::Mat(o.size, CV_32FC3, cv::Scalar::all(0));
  set.truth.mask = cv::Mat(o.size, CV_8UC1, cv::Scalar(0));
  set.truth.albedo = cv::Mat(o.size, CV_32FC3, cv::Scalar::all(0));
  set.truth.depth = cv::Mat(o.size, CV_32FC1, cv::Scalar(0));
  const cv::Vec3d cam(0, 0, 1);
  for (int v = 0; v < o.size.height; ++v) {
    for (int u = 0; u < o.size.width; ++u) {
      cv::Vec3d d((u - cx) / f, -(v - cy) / f, -1);
      d /= cv::norm(d);
      const cv::Vec3d oc = cam - o.center;
      const double b = oc.dot(d), c = oc.dot(oc) - o.radius * o.radius, disc = b * b - c;
      if (disc <= 0) continue;
      const double t = -b - std::sqrt(disc);
      const cv::Vec3d p = cam + t * d;
      const cv::Vec3d nrm = (p - o.center) / o.radius;
      set.truth.normals.at<cv::Vec3f>(v, u) = cv::Vec3f(nrm);
      set.truth.mask.at<uint8_t>(v, u) = 255;
      set.truth.albedo.at<cv::Vec3f>(v, u) = o.albedo_bgr;
      set.truth.depth.at<float>(v, u) = static_cast<float>(1.0 - p[2]);
      for (int i = 0; i < n; ++i) {
        double shade, gloss = 0, falloff = 1;
        cv::Vec3d l = true_dirs[static_cast<size_t>(i)];
        if (!o.distant) {
          const cv::Vec3d L = pos[i] - p;
          const double d2 = L.dot(L);
          l = L / std::sqrt(d2);
          falloff = pos[i].dot(pos[i]) / d2;
        }
        shade = std::max(0.0, nrm.dot(l)) * falloff;
        if (o.occluder_radius > 0) {  // the ray from p towards the lamp passes the occluder?
          const cv::Vec3d oc2 = p - o.occluder_center;
          const double b2 = oc2.dot(l), c2 = oc2.dot(oc2) - o.occluder_radius * o.occluder_radius;
          if (b2 * b2 - c2 > 0 && -b2 - std::sqrt(b2 * b2 - c2) > 0) shade = 0;
        }
        if (o.specular > 0 && shade > 0) {
          const cv::Vec3d h = (l - d) / cv::norm(l - d);  // half-way between the lamp and the camera (-d)
          gloss = o.specular * std::pow(std::max(0.0, nrm.dot(h)), o.shininess) * falloff;
        }
        cv::Vec3f& px = set.images[i].at<cv::Vec3f>(v, u);
        for (int ch = 0; ch < 3; ++ch)
          px[ch] += static_cast<float>((o.albedo_bgr[ch] * shade + gloss) * o.lamp_intensity * o.lamp_tint[2 - ch]);
      }
    }
  }
  set.mask = cv::Mat();
  if (o.noise > 0) {
    std::mt19937 rng(o.seed);
    std::normal_distribution<float> g(0.f, static_cast<float>(o.noise));
    for (auto& im : set.images)
      for (auto it = im.begin<cv::Vec3f>(); it != im.end<cv::Vec3f>(); ++it)
        for (int ch = 0; ch < 3; ++ch) (*it)[ch] += g(rng);
  }
  for (auto& im : set.images) cv::min(cv::max(im, 0.0), 1.0, im);
  return set;
}

}  // namespace veneer::ps::test
