// A live sequence under one moving lamp, with truth (light_path.hpp).
#include "veneer/sim/light_path.hpp"

#include <cmath>
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

Expected<LightPathSpec> named_path(const std::string& name) {
  LightPathSpec s;
  s.name = name;
  if (name == "spiral") return s;  // the defaults
  if (name == "circle") {
    s.inner_m = s.radius_m = 0.65;
    s.height_m = 0.75;
    s.from_deg = 22.5;
    s.to_deg = 382.5;
    s.closed = true;
    return s;
  }
  if (name == "arc") {
    s.inner_m = s.radius_m = 0.3;
    s.height_m = 1.1;
    s.from_deg = -90;
    s.to_deg = 90;
    return s;
  }
  return make_error("light path '" + name + "': unknown (spiral, circle, arc)");
}

nlohmann::json vec(const cv::Vec3d& v) { return {v[0], v[1], v[2]}; }
nlohmann::json vec(const cv::Vec3f& v) { return {v[0], v[1], v[2]}; }

}  // namespace

std::vector<std::string> light_path_names() { return {"spiral", "circle", "arc"}; }

Status LightPathSpec::check() const {
  if (!(inner_m >= 0 && inner_m <= 5) || !(radius_m >= 0 && radius_m <= 5))
    return make_error("light path: radius and inner must be 0..5 m");
  if (!(height_m > 0.05 && height_m <= 10)) return make_error("light path: height must be in (0.05, 10] m (in front of the object)");
  if (!std::isfinite(from_deg) || !std::isfinite(to_deg) || std::abs(from_deg) > 3600 || std::abs(to_deg) > 3600)
    return make_error("light path: from and to must be finite degrees, within +-3600");
  for (int c = 0; c < 3; ++c)
    if (!(colour[c] >= 0 && colour[c] <= 4)) return make_error("light path: colour components must be 0..4");
  return Status::success();
}

Expected<LightPathSpec> parse_light_path(const std::string& spec) {
  std::istringstream parts(spec);
  std::string part;
  std::getline(parts, part, ',');
  auto s = named_path(part.empty() ? "spiral" : part);
  if (!s) return s.error();
  while (std::getline(parts, part, ',')) {
    if (part.empty()) continue;
    const auto eq = part.find('=');
    if (eq == std::string::npos)
      return make_error("light path '" + part + "': expected NAME=VALUE (radius, inner, height, from, to, colour)");
    const std::string name = part.substr(0, eq), value = part.substr(eq + 1);
    double v = 0;
    if (name == "colour" || name == "color") {
      std::istringstream in(value);
      std::string c;
      int i = 0;
      while (std::getline(in, c, ':')) {
        if (i > 2 || !parse_number(c, &v)) { i = 4; break; }
        s->colour[i++] = static_cast<float>(v);
      }
      if (i != 3) return make_error("light path '" + part + "': expected colour=R:G:B, e.g. colour=1:0.9:0.8");
      continue;
    }
    if (!parse_number(value, &v)) return make_error("light path '" + part + "': " + value + " is not a number");
    if (name == "radius") {
      // one radius for a circle or an arc; a spiral's outer end
      if (s->inner_m == s->radius_m) s->inner_m = v;
      s->radius_m = v;
    } else if (name == "inner") {
      s->inner_m = v;
    } else if (name == "height") {
      s->height_m = v;
    } else if (name == "from") {
      s->from_deg = v;
    } else if (name == "to") {
      s->to_deg = v;
    } else {
      return make_error("light path '" + part + "': unknown setting '" + name + "' (radius, inner, height, from, to, colour)");
    }
  }
  if (auto st = s->check(); !st) return make_error(st.message() + " (in '" + spec + "')");
  return s;
}

std::vector<PathLight> light_path_lights(const LightPathSpec& spec, int frames, double exposure) {
  std::vector<PathLight> out;
  // a rig lamp's radiant intensity: irradiance 1 at the origin from its socket
  const cv::Vec3d socket = thesis_rig()[0].position_m;
  const double rig_intensity = socket.dot(socket);
  for (int i = 0; i < frames; ++i) {
    const double steps = spec.closed ? frames : std::max(1, frames - 1);
    const double f = frames > 1 ? i / steps : 0.0;
    const double phi = (spec.from_deg + f * (spec.to_deg - spec.from_deg)) * CV_PI / 180.0;
    const double r = spec.inner_m + f * (spec.radius_m - spec.inner_m);
    auto snap = [](double v) { return std::abs(v) < 1e-12 ? 0.0 : v; };
    PathLight l;
    l.position_m = {snap(r * std::sin(phi)), snap(r * std::cos(phi)), spec.height_m};
    const double d2 = l.position_m.dot(l.position_m);
    l.direction = l.position_m / std::sqrt(d2);
    l.colour = spec.colour;
    l.intensity = spec.colour * static_cast<float>(exposure);
    // as bright at the object as a rig lamp (1/r^2 from its own distance)
    const float gain = static_cast<float>(d2 / rig_intensity);
    l.lamp.position_m = l.position_m;
    l.lamp.color = spec.colour * gain;
    l.lamp.brightness = 1.0f;
    out.push_back(l);
  }
  return out;
}

Expected<LightSequence> simulate_light_path(const std::string& source_scene, const std::string& destination_scene,
                                            const RenderOptions& options, const LightPathSpec& spec, int frames,
                                            const Progress& progress) {
  if (frames < 1 || frames > 100000) return make_error("frames " + std::to_string(frames) + ": expected 1..100000");
  if (auto st = options.check(); !st) return st.error();
  if (auto st = spec.check(); !st) return st.error();
  auto scene = make_scene(source_scene, options);
  if (!scene) return scene.error();
  std::shared_ptr<const Scene> truth_scene;
  LightSequence seq;
  RenderOptions clean = options;
  clean.noise_sigma = 0;
  if (!destination_scene.empty()) {
    auto t = make_scene_with_material(destination_scene, source_scene, options);
    if (!t) return t.error();
    truth_scene = *t;
    seq.truth_mask = render_truth(*truth_scene, clean).mask;
  }
  seq.mask = render_truth(**scene, clean).mask;
  const cv::Moments mo = cv::moments(seq.mask, true);
  seq.centre = mo.m00 > 0 ? cv::Point2d(mo.m10 / mo.m00, mo.m01 / mo.m00)
                          : cv::Point2d((options.size.width - 1) / 2.0, (options.size.height - 1) / 2.0);
  seq.lights = light_path_lights(spec, frames, options.exposure);
  for (int i = 0; i < frames; ++i) {
    if (progress.cancelled()) return make_error("cancelled");
    RenderOptions o = options;
    o.shot = static_cast<uint32_t>(i);
    const cv::Mat linear = render(**scene, {seq.lights[static_cast<size_t>(i)].lamp}, o);
    if (linear.empty()) return make_error("cancelled");
    seq.frames.push_back(encode_live_frame(linear));
    if (truth_scene) {
      cv::Mat truth = render(*truth_scene, {seq.lights[static_cast<size_t>(i)].lamp}, clean);
      if (truth.empty()) return make_error("cancelled");
      seq.truth.push_back(truth);
    }
    progress.report(static_cast<double>(i + 1) / frames, "frame " + std::to_string(i + 1));
  }
  return seq;
}

Status write_light_path_json(const std::filesystem::path& file, const LightPathFile& c) {
  nlohmann::ordered_json j;
  j["format"] = "veneer-light-path/1";
  j["spec"] = c.spec;
  j["source"] = c.source;
  j["destination"] = c.destination;
  j["size"] = {c.size.width, c.size.height};
  j["units"] = "position_m: rig frame, metres (x right, y up, z toward the camera); direction: unit, object -> lamp; "
               "intensity: irradiance at the object in image units [r, g, b] (as set.json's lights); colour: the "
               "lamp's [r, g, b]; frames 8-bit sRGB, truth 16-bit linear";
  j["truth_mask"] = c.truth_mask;
  j["frames"] = nlohmann::ordered_json::array();
  for (size_t i = 0; i < c.lights.size(); ++i) {
    const PathLight& l = c.lights[i];
    nlohmann::ordered_json f;
    f["file"] = i < c.files.size() ? c.files[i] : "";
    f["truth"] = i < c.truth_files.size() ? c.truth_files[i] : "";
    f["position_m"] = vec(l.position_m);
    f["direction"] = vec(l.direction);
    f["intensity"] = vec(l.intensity);
    f["colour"] = vec(l.colour);
    j["frames"].push_back(f);
  }
  return io::write_file_atomic(file, j.dump(1) + "\n");
}

Expected<LightPathFile> read_light_path_json(const std::filesystem::path& file) {
  auto bytes = io::read_file_bytes(file);
  if (!bytes) return bytes.error();
  try {
    const auto j = nlohmann::json::parse(*bytes);
    if (j.value("format", "") != "veneer-light-path/1") return make_error(file.string() + ": not a veneer-light-path/1 file");
    LightPathFile c;
    c.spec = j.value("spec", "");
    c.source = j.value("source", "");
    c.destination = j.value("destination", "");
    c.size = {j.at("size").at(0).get<int>(), j.at("size").at(1).get<int>()};
    c.truth_mask = j.value("truth_mask", "");
    auto v3 = [](const nlohmann::json& a) { return cv::Vec3d(a.at(0).get<double>(), a.at(1).get<double>(), a.at(2).get<double>()); };
    const cv::Vec3d socket = thesis_rig()[0].position_m;
    for (const auto& f : j.at("frames")) {
      PathLight l;
      l.position_m = v3(f.at("position_m"));
      l.direction = v3(f.at("direction"));
      l.intensity = cv::Vec3f(v3(f.at("intensity")));
      l.colour = cv::Vec3f(v3(f.at("colour")));
      l.lamp.position_m = l.position_m;
      l.lamp.color = l.colour * static_cast<float>(l.position_m.dot(l.position_m) / socket.dot(socket));
      c.files.push_back(f.value("file", ""));
      c.truth_files.push_back(f.value("truth", ""));
      c.lights.push_back(l);
    }
    return c;
  } catch (const nlohmann::json::exception& e) {
    return make_error(file.string() + ": " + e.what());
  }
}

}  // namespace veneer::sim
