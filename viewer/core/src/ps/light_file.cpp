// The lights file written by `veneer calibrate` (see calibration.hpp), and
// the picture that shows what the calibration found.
#include <cmath>
#include <string>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/ps/calibration.hpp"

namespace veneer::ps {

namespace {

constexpr const char* kFormat = "veneer-lights/1";

nlohmann::json vec(const cv::Vec3d& v) { return {v[0], v[1], v[2]}; }

Expected<cv::Vec3d> read_vec3(const nlohmann::json& j, const std::string& what) {
  if (!j.is_array() || j.size() != 3 || !j[0].is_number() || !j[1].is_number() || !j[2].is_number())
    return make_error(what + ": expected [x, y, z]");
  const cv::Vec3d v(j[0].get<double>(), j[1].get<double>(), j[2].get<double>());
  if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2])) return make_error(what + ": not finite");
  return v;
}

Expected<cv::Point2d> read_point(const nlohmann::json& j, const std::string& what) {
  if (!j.is_array() || j.size() != 2 || !j[0].is_number() || !j[1].is_number())
    return make_error(what + ": expected [x, y] in pixels");
  return cv::Point2d(j[0].get<double>(), j[1].get<double>());
}

}  // namespace

std::string light_calibration_json(const LightCalibration& c) {
  nlohmann::json j;
  j["format"] = kFormat;
  j["sphere"] = {{"center_px", {c.center.x, c.center.y}}, {"radius_px", c.radius}, {"outline_rms_px", c.circle_rms_px}};
  nlohmann::json lamps = nlohmann::json::array();
  for (size_t i = 0; i < c.directions.size(); ++i) {
    nlohmann::json l = {{"index", i}, {"direction", vec(c.directions[i])}};
    if (i < c.positions_m.size()) l["position_m"] = vec(c.positions_m[i]);
    if (i < c.highlights.size()) l["highlight_px"] = {c.highlights[i].x, c.highlights[i].y};
    if (i < c.highlight_area.size()) l["highlight_area_px"] = c.highlight_area[i];
    lamps.push_back(l);
  }
  j["lamps"] = lamps;
  return j.dump(2) + "\n";
}

Status write_light_calibration(const LightCalibration& calibration, const std::filesystem::path& file) {
  if (calibration.directions.empty()) return make_error("the calibration has no lamps to write");
  return io::write_file_atomic(file, light_calibration_json(calibration));
}

Expected<LightCalibration> parse_light_calibration(const std::string& text) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {
    return make_error(std::string("not JSON: ") + e.what());
  }
  if (!j.is_object() || !j.contains("format") || j["format"] != kFormat)
    return make_error(std::string("not a lights file (format is not \"") + kFormat + "\")");
  LightCalibration c;
  if (j.contains("sphere")) {
    const auto& s = j["sphere"];
    if (!s.is_object()) return make_error("sphere: expected an object");
    if (s.contains("center_px")) {
      auto p = read_point(s["center_px"], "sphere.center_px");
      if (!p) return p.error();
      c.center = *p;
    }
    if (s.contains("radius_px") && s["radius_px"].is_number()) c.radius = s["radius_px"].get<double>();
    if (s.contains("outline_rms_px") && s["outline_rms_px"].is_number())
      c.circle_rms_px = s["outline_rms_px"].get<double>();
  }
  if (!j.contains("lamps") || !j["lamps"].is_array() || j["lamps"].empty())
    return make_error("lamps: expected a non-empty array");
  const auto& lamps = j["lamps"];
  for (size_t i = 0; i < lamps.size(); ++i) {
    const std::string where = "lamps[" + std::to_string(i) + "]";
    const auto& l = lamps[i];
    if (!l.is_object() || !l.contains("direction")) return make_error(where + ": expected an object with a direction");
    auto d = read_vec3(l["direction"], where + ".direction");
    if (!d) return d.error();
    if (std::abs(cv::norm(*d) - 1.0) > 1e-3) return make_error(where + ".direction: not a unit vector");
    if ((*d)[2] <= 0) return make_error(where + ".direction: points away from the camera (z <= 0)");
    c.directions.push_back(*d);
    if (l.contains("position_m")) {
      auto p = read_vec3(l["position_m"], where + ".position_m");
      if (!p) return p.error();
      if (i != c.positions_m.size()) return make_error(where + ": a position for some lamps but not all");
      c.positions_m.push_back(*p);
    }
    if (l.contains("highlight_px")) {
      auto p = read_point(l["highlight_px"], where + ".highlight_px");
      if (!p) return p.error();
      c.highlights.push_back(*p);
    }
    if (l.contains("highlight_area_px") && l["highlight_area_px"].is_number())
      c.highlight_area.push_back(l["highlight_area_px"].get<double>());
  }
  if (!c.positions_m.empty() && c.positions_m.size() != c.directions.size())
    return make_error("a position for some lamps but not all");
  if (c.highlights.size() != c.directions.size()) c.highlights.clear();
  if (c.highlight_area.size() != c.directions.size()) c.highlight_area.clear();
  return c;
}

Expected<LightCalibration> read_light_calibration(const std::filesystem::path& file) {
  auto bytes = io::read_file_bytes(file);
  if (!bytes) return make_error(file.string() + ": " + bytes.message());
  auto c = parse_light_calibration(*bytes);
  if (!c) return make_error(file.string() + ": " + c.message());
  return c;
}

cv::Mat calibration_picture(const io::ImageSet& set, const LightCalibration& calibration) {
  if (set.images.empty()) return {};
  cv::Mat brightest = set.images[0].clone();
  for (size_t i = 1; i < set.images.size(); ++i) cv::max(brightest, set.images[i], brightest);
  // The sphere is dark but for its highlights: show its outline faintly too.
  cv::Mat pic = io::tonemap_picture(brightest, 99.0);
  if (pic.channels() == 1) cv::cvtColor(pic, pic, cv::COLOR_GRAY2BGR);
  const int shift = 4, one = 1 << shift;
  auto fixed = [&](cv::Point2d p) { return cv::Point(cvRound(p.x * one), cvRound(p.y * one)); };
  if (calibration.radius > 0)
    cv::circle(pic, fixed(calibration.center), cvRound(calibration.radius * one), {0, 255, 0}, 1, cv::LINE_AA, shift);
  cv::drawMarker(pic, cv::Point(cvRound(calibration.center.x), cvRound(calibration.center.y)), {0, 255, 0},
                 cv::MARKER_CROSS, 7, 1);
  for (size_t i = 0; i < calibration.highlights.size(); ++i) {
    const cv::Point2d h = calibration.highlights[i];
    const cv::Point hp(cvRound(h.x), cvRound(h.y));
    cv::drawMarker(pic, hp, {0, 0, 255}, cv::MARKER_CROSS, 9, 1);
    cv::putText(pic, std::to_string(i + 1), hp + cv::Point(5, -5), cv::FONT_HERSHEY_PLAIN, 0.9, {0, 200, 255}, 1,
                cv::LINE_AA);
  }
  return pic;
}

}  // namespace veneer::ps
