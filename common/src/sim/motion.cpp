#include "veneer/sim/motion.hpp"

#include <cmath>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "live_frame.hpp"
#include "veneer/io/image_io.hpp"

namespace veneer::sim {

namespace {

bool parse_number(const std::string& text, double* v) {
  if (text.empty()) return false;
  std::istringstream in(text);
  char extra = 0;
  return static_cast<bool>(in >> *v) && !(in >> extra) && std::isfinite(*v);
}

}  // namespace

Expected<MotionSpec> parse_motion(const std::string& spec) {
  MotionSpec m;
  std::istringstream parts(spec);
  std::string part;
  while (std::getline(parts, part, ',')) {
    if (part.empty()) continue;
    const auto eq = part.find('=');
    if (eq == std::string::npos) return make_error("motion '" + part + "': expected NAME=VALUE (shift, rotate, scale, turn, lamp, view)");
    const std::string name = part.substr(0, eq), value = part.substr(eq + 1);
    if (name == "shift") {
      const auto colon = value.find(':');
      if (colon == std::string::npos || !parse_number(value.substr(0, colon), &m.shift_px[0]) ||
          !parse_number(value.substr(colon + 1), &m.shift_px[1]))
        return make_error("motion '" + part + "': expected shift=DX:DY in pixels, e.g. shift=30:0");
    } else if (name == "rotate") {
      if (!parse_number(value, &m.rotate_deg) || std::abs(m.rotate_deg) > 180)
        return make_error("motion '" + part + "': expected rotate=DEGREES in [-180, 180]");
    } else if (name == "scale") {
      if (!parse_number(value, &m.scale) || m.scale < 0.25 || m.scale > 4)
        return make_error("motion '" + part + "': expected scale=FACTOR in [0.25, 4]");
    } else if (name == "turn") {
      if (!parse_number(value, &m.turn_deg) || std::abs(m.turn_deg) >= 30)
        return make_error("motion '" + part + "': expected turn=DEGREES in (-30, 30) (a small out-of-plane turn)");
    } else if (name == "lamp") {
      if (value == "sweep") m.lamp_sweep = true;
      else if (value == "fixed") m.lamp_sweep = false;
      else return make_error("motion '" + part + "': expected lamp=sweep or lamp=fixed");
    } else if (name == "view") {
      const auto x = value.find('x');
      double w = 0, h = 0;
      if (x == std::string::npos || !parse_number(value.substr(0, x), &w) || !parse_number(value.substr(x + 1), &h) ||
          w < 16 || h < 16 || w > 16384 || h > 16384 || w != std::floor(w) || h != std::floor(h))
        return make_error("motion '" + part + "': expected view=WIDTHxHEIGHT in pixels (16..16384), e.g. view=320x180");
      m.view = cv::Size(static_cast<int>(w), static_cast<int>(h));
    } else {
      return make_error("motion '" + part + "': unknown motion '" + name + "' (shift, rotate, scale, turn, lamp, view)");
    }
  }
  return m;
}

cv::Matx23d view_transform(cv::Size still, cv::Size view) {
  if (view.area() == 0 || view == still) return cv::Matx23d(1, 0, 0, 0, 1, 0);
  const double still_aspect = static_cast<double>(still.width) / still.height;
  const double view_aspect = static_cast<double>(view.width) / view.height;
  // a wider view shows the full width (crops top and bottom), a narrower one the full height
  const double s = view_aspect >= still_aspect ? static_cast<double>(view.width) / still.width
                                               : static_cast<double>(view.height) / still.height;
  return cv::Matx23d(s, 0, (view.width - 1) / 2.0 - s * (still.width - 1) / 2.0, 0, s,
                     (view.height - 1) / 2.0 - s * (still.height - 1) / 2.0);
}

MotionFrame motion_at(const MotionSpec& spec, int index, int frames, cv::Point2d centre) {
  const double f = frames > 1 ? static_cast<double>(index) / (frames - 1) : 0.0;
  const double a = f * spec.rotate_deg * CV_PI / 180.0;
  const double s = std::pow(spec.scale, f);
  const double fx = std::cos(f * spec.turn_deg * CV_PI / 180.0);
  // counter-clockwise in the picture (y down): x' = c x + s y, y' = -s x + c y
  const cv::Matx22d r(std::cos(a), std::sin(a), -std::sin(a), std::cos(a));
  const cv::Matx22d l = r * cv::Matx22d(s * fx, 0, 0, s);
  const cv::Vec2d c(centre.x, centre.y);
  const cv::Vec2d t = c + f * spec.shift_px - l * c;
  MotionFrame m;
  m.still_to_frame = cv::Matx23d(l(0, 0), l(0, 1), t[0], l(1, 0), l(1, 1), t[1]);
  // the hand lamp: on the 0.47 m ring, from upper left (-60 deg) to upper right (+60 deg)
  const double phi = spec.lamp_sweep ? (-60.0 + 120.0 * f) * CV_PI / 180.0 : 0.0;
  m.lamp_m = {0.47 * std::sin(phi), 0.47 * std::cos(phi), 1.0};
  return m;
}

Expected<MotionSequence> simulate_motion(const std::string& scene_name, const RenderOptions& options,
                                         const MotionSpec& spec, int frames, const Progress& progress) {
  if (frames < 1 || frames > 100000) return make_error("frames " + std::to_string(frames) + ": expected 1..100000");
  if (auto st = options.check(); !st) return st.error();
  auto scene = make_scene(scene_name, options);
  if (!scene) return scene.error();
  // The table without the object (shrunk to a speck at its base), for the
  // pixels the moved object uncovers.
  RenderOptions empty_options = options;
  empty_options.scale = options.scale * 1e-4;
  auto table = make_scene(scene_name, empty_options);
  if (!table) return table.error();
  MotionSequence seq;
  seq.mask = render_truth(**scene, options).mask;
  const cv::Moments mo = cv::moments(seq.mask, true);
  seq.centre = mo.m00 > 0 ? cv::Point2d(mo.m10 / mo.m00, mo.m01 / mo.m00)
                          : cv::Point2d((options.size.width - 1) / 2.0, (options.size.height - 1) / 2.0);
  const cv::Matx23d view = view_transform(options.size, spec.view);
  const cv::Size frame_size = spec.view.area() ? spec.view : options.size;
  for (int i = 0; i < frames; ++i) {
    if (progress.cancelled()) return make_error("cancelled");
    MotionFrame m = motion_at(spec, i, frames, seq.centre);
    Lamp lamp;
    lamp.position_m = m.lamp_m;
    RenderOptions o = options;
    o.shot = static_cast<uint32_t>(i);
    cv::Mat linear = render(**scene, {lamp}, o);
    if (linear.empty()) return make_error("cancelled");
    // Only the object moves: it is laid over the empty table (which then
    // shows no shadow of it; the object's own shading is the still pose's).
    cv::Mat background = render(**table, {lamp}, o);
    cv::Mat moved, alpha, mask_f;
    cv::warpAffine(linear, moved, cv::Mat(m.still_to_frame), options.size, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    seq.mask.convertTo(mask_f, CV_32F, 1.0 / 255.0);
    cv::warpAffine(mask_f, alpha, cv::Mat(m.still_to_frame), options.size, cv::INTER_LINEAR, cv::BORDER_CONSTANT);
    cv::cvtColor(alpha, alpha, cv::COLOR_GRAY2BGR);
    moved = moved.mul(alpha) + background.mul(cv::Scalar::all(1.0) - alpha);
    if (frame_size != options.size || view != cv::Matx23d(1, 0, 0, 0, 1, 0)) {
      // the live view's framing; smaller than the still: blurred first, as a sensor's binning would
      const double s = view(0, 0);
      if (s < 1) cv::GaussianBlur(moved, moved, cv::Size(), 0.5 * std::sqrt(1 / (s * s) - 1));
      cv::warpAffine(moved, moved, cv::Mat(view), frame_size, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
      const cv::Matx33d v(view(0, 0), view(0, 1), view(0, 2), view(1, 0), view(1, 1), view(1, 2), 0, 0, 1);
      const auto& a = m.still_to_frame;
      const cv::Matx33d both = v * cv::Matx33d(a(0, 0), a(0, 1), a(0, 2), a(1, 0), a(1, 1), a(1, 2), 0, 0, 1);
      m.still_to_frame = cv::Matx23d(both(0, 0), both(0, 1), both(0, 2), both(1, 0), both(1, 1), both(1, 2));
    }
    seq.frames.push_back(encode_live_frame(moved));
    seq.truth.push_back(m);
    progress.report(static_cast<double>(i + 1) / frames, "frame " + std::to_string(i + 1));
  }
  return seq;
}

Status write_motion_json(const std::filesystem::path& file, const MotionSequence& seq, const std::string& spec,
                         const std::vector<std::string>& files) {
  nlohmann::json j;
  j["format"] = "veneer-motion/1";
  const cv::Size size = seq.frames.empty() ? cv::Size() : seq.frames[0].size();
  j["size"] = {size.width, size.height};
  j["spec"] = spec;
  j["units"] = "still_to_frame: still pixel -> frame pixel (pixel centres at integers); lamp_m: rig frame, metres";
  j["centre"] = {seq.centre.x, seq.centre.y};
  j["frames"] = nlohmann::json::array();
  for (size_t i = 0; i < seq.truth.size(); ++i) {
    const auto& a = seq.truth[i].still_to_frame;
    const auto& l = seq.truth[i].lamp_m;
    j["frames"].push_back({{"file", i < files.size() ? files[i] : ""},
                           {"still_to_frame", {{a(0, 0), a(0, 1), a(0, 2)}, {a(1, 0), a(1, 1), a(1, 2)}}},
                           {"lamp_m", {l[0], l[1], l[2]}}});
  }
  return io::write_file_atomic(file, j.dump(1) + "\n");
}

Expected<MotionTruth> read_motion_json(const std::filesystem::path& file) {
  auto bytes = io::read_file_bytes(file);
  if (!bytes) return bytes.error();
  try {
    const auto j = nlohmann::json::parse(*bytes);
    if (j.value("format", "") != "veneer-motion/1") return make_error(file.string() + ": not a veneer-motion/1 file");
    MotionTruth t;
    t.size = {j.at("size").at(0).get<int>(), j.at("size").at(1).get<int>()};
    for (const auto& f : j.at("frames")) {
      const auto& a = f.at("still_to_frame");
      MotionFrame m;
      for (int r = 0; r < 2; ++r)
        for (int c = 0; c < 3; ++c) m.still_to_frame(r, c) = a.at(r).at(c).get<double>();
      const auto& l = f.at("lamp_m");
      m.lamp_m = {l.at(0).get<double>(), l.at(1).get<double>(), l.at(2).get<double>()};
      t.files.push_back(f.value("file", ""));
      t.truth.push_back(m);
    }
    return t;
  } catch (const nlohmann::json::exception& e) {
    return make_error(file.string() + ": " + e.what());
  }
}

}  // namespace veneer::sim
