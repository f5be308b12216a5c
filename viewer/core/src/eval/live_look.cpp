// The live look, measured frame by frame (live_look.hpp).
#include "veneer/eval/live_look.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>

#include <nlohmann/json.hpp>
#include "veneer/io/codecs.hpp"
#include <opencv2/imgproc.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/sim/light_path.hpp"

namespace veneer::eval {
namespace fs = std::filesystem;

namespace {

cv::Mat identity_map(cv::Size size) {
  cv::Mat xy(size, CV_32FC2);
  for (int y = 0; y < size.height; ++y)
    for (int x = 0; x < size.width; ++x) xy.at<cv::Vec2f>(y, x) = {static_cast<float>(x), static_cast<float>(y)};
  return xy;
}

const std::array<float, 256>& srgb_to_linear() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) {
      const double v = i / 255.0;
      t[static_cast<size_t>(i)] = static_cast<float>(v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4));
    }
    return t;
  }();
  return table;
}

}  // namespace

std::string LiveLook::json() const {
  nlohmann::ordered_json j;
  j["measure"] = std::string("look.py per frame against the truth frames: shading |d_f| over the truth's mask where "
                             "both are lit (medians over the sequence), ") +
                 (texture_from_source ? "texture_corr of the high-passes of the frame and the source's median photo "
                                        "warped through the map (look.py's)"
                                      : "texture_corr of the high-passes of the frame and the truth frame (identity map)") +
                 ", light: the estimated light's angle to the path's lamp";
  j["frames"] = nlohmann::ordered_json::array();
  for (size_t i = 0; i < frames.size(); ++i) {
    const FrameLook& f = frames[i];
    nlohmann::ordered_json r;
    r["frame"] = i;
    r["file"] = f.file;
    r["shading_mean"] = f.shading.mean;
    r["shading_median"] = f.shading.median;
    r["shading_p90"] = f.shading.p90;
    r["samples"] = f.shading.samples;
    r["texture_corr"] = f.texture_corr ? nlohmann::ordered_json(*f.texture_corr) : nlohmann::ordered_json();
    r["lost"] = f.lost;
    r["light_angle_deg"] = f.light_angle_deg ? nlohmann::ordered_json(*f.light_angle_deg) : nlohmann::ordered_json();
    j["frames"].push_back(r);
  }
  auto opt = [](const std::optional<double>& v) { return v ? nlohmann::ordered_json(*v) : nlohmann::ordered_json(); };
  j["mean"] = {{"shading_mean", shading_mean},
               {"texture_corr", opt(texture_corr_mean)},
               {"texture_corr_min", opt(texture_corr_min)},
               {"texture_from_source", texture_from_source},
               {"light_angle_median_deg", opt(light_angle_median_deg)},
               {"light_angle_max_deg", opt(light_angle_max_deg)}};
  j["pooled"] = {{"shading_mean", pooled.mean},
                 {"shading_median", pooled.median},
                 {"shading_p90", pooled.p90},
                 {"samples", pooled.samples}};
  return j.dump(1);
}

std::string LiveLook::table() const {
  std::string out = "frame  shading mean  median    p90   texture_corr  samples  light deg\n";
  char line[160];
  auto fmt = [](const std::optional<double>& v, const char* f, char* buf, size_t n) {
    if (v) std::snprintf(buf, n, f, *v);
    else std::snprintf(buf, n, "%s", "-");
  };
  for (size_t i = 0; i < frames.size(); ++i) {
    const FrameLook& f = frames[i];
    char corr[32], angle[32];
    fmt(f.texture_corr, "%.3f", corr, sizeof corr);
    fmt(f.light_angle_deg, "%.2f", angle, sizeof angle);
    std::snprintf(line, sizeof line, "%5zu  %12.4f  %6.4f  %6.4f  %13s  %7lld  %9s%s\n", i, f.shading.mean,
                  f.shading.median, f.shading.p90, corr, f.shading.samples, angle, f.lost ? "  (lost)" : "");
    out += line;
  }
  char corr[32], angle[32];
  fmt(texture_corr_mean, "%.3f", corr, sizeof corr);
  fmt(light_angle_median_deg, "%.2f", angle, sizeof angle);
  std::snprintf(line, sizeof line, " mean  %12.4f  %6s  %6s  %13s  %7s  %9s (light: median)\n", shading_mean, "", "",
                corr, "", angle);
  out += line;
  fmt(texture_corr_min, "%.3f", corr, sizeof corr);
  fmt(light_angle_max_deg, "%.2f", angle, sizeof angle);
  std::snprintf(line, sizeof line, "worst  %12s  %6s  %6s  %13s  %7s  %9s\n", "", "", "", corr, "", angle);
  out += line;
  std::snprintf(line, sizeof line, "pooled %11.4f  %6.4f  %6.4f  %13s  %7lld\n", pooled.mean, pooled.median, pooled.p90, "",
                pooled.samples);
  out += line;
  return out;
}

Expected<LiveLook> live_look(const std::vector<cv::Mat>& result, const std::vector<cv::Mat>& truth, const cv::Mat& mask,
                             const LiveLookTexture& texture) {
  if (result.size() != truth.size())
    return make_error(std::to_string(result.size()) + " repainted frames for " + std::to_string(truth.size()) + " truth frames");
  if (result.empty()) return make_error("no frame to score");
  auto per_frame = shading_error_per_lamp(result, truth, mask);
  if (!per_frame) return per_frame.error();
  auto pooled = shading_error(result, truth, mask);
  if (!pooled) return pooled.error();
  LiveLook look;
  look.pooled = *pooled;
  look.texture_from_source = !texture.empty();
  const cv::Mat map = look.texture_from_source ? texture.map_xy : identity_map(truth[0].size());
  if (map.size() != truth[0].size())
    return make_error("the map is " + std::to_string(map.cols) + "x" + std::to_string(map.rows) + ", the frames " +
                      std::to_string(truth[0].cols) + "x" + std::to_string(truth[0].rows));
  double shading_sum = 0, corr_sum = 0;
  int shading_n = 0, corr_n = 0;
  for (size_t i = 0; i < result.size(); ++i) {
    FrameLook f;
    f.shading = (*per_frame)[i];
    auto corr = texture_corr(look_gray(result[i]), look.texture_from_source ? texture.source_median : look_gray(truth[i]),
                             map, mask);
    if (corr) f.texture_corr = *corr;
    if (f.texture_corr && std::isfinite(*f.texture_corr))
      look.texture_corr_min = std::min(look.texture_corr_min.value_or(*f.texture_corr), *f.texture_corr);
    if (f.shading.samples > 0) {
      shading_sum += f.shading.mean;
      ++shading_n;
    }
    if (f.texture_corr && std::isfinite(*f.texture_corr)) {
      corr_sum += *f.texture_corr;
      ++corr_n;
    }
    look.frames.push_back(f);
  }
  look.shading_mean = shading_n ? shading_sum / shading_n : 0;
  if (corr_n) look.texture_corr_mean = corr_sum / corr_n;
  return look;
}

Expected<cv::Mat> read_live_picture(const fs::path& file) {
  const cv::Mat raw = veneer::io::codecs::imread(file.string(), cv::IMREAD_UNCHANGED);
  if (raw.empty()) return make_error(file.string() + ": cannot read it as a picture");
  cv::Mat bgr;
  if (raw.channels() == 1) cv::cvtColor(raw, bgr, cv::COLOR_GRAY2BGR);
  else if (raw.channels() == 4) cv::cvtColor(raw, bgr, cv::COLOR_BGRA2BGR);
  else bgr = raw;
  cv::Mat out(bgr.size(), CV_32FC3);
  if (bgr.depth() == CV_8U) {
    const auto& lut = srgb_to_linear();
    for (int y = 0; y < bgr.rows; ++y) {
      const uchar* s = bgr.ptr<uchar>(y);
      float* o = out.ptr<float>(y);
      for (int x = 0; x < bgr.cols * 3; ++x) o[x] = lut[s[x]];
    }
  } else if (bgr.depth() == CV_16U) {
    bgr.convertTo(out, CV_32F, 1.0 / 65535.0);
  } else {
    return make_error(file.string() + ": neither an 8-bit nor a 16-bit picture");
  }
  return out;
}

Expected<LiveLook> live_look_folders(const fs::path& repainted, const fs::path& sequence, const fs::path& map_path,
                                     const fs::path& source_set) {
  if (map_path.empty() != source_set.empty())
    return make_error("texture from the source needs both the map and the source set");
  auto sidecar = sim::read_light_path_json(sequence / "light_path.json");
  if (!sidecar) return make_error("--truth " + sequence.string() + ": " + sidecar.message());
  if (sidecar->truth_mask.empty() || sidecar->truth_files.empty() || sidecar->truth_files[0].empty())
    return make_error(sequence.string() + ": the sequence has no truth frames (simulate it with --material SOURCE)");
  // the repainted frames: report.json's order (and which were lost), else frame_*.png by name
  std::vector<fs::path> files;
  std::vector<bool> lost;
  std::vector<std::optional<cv::Vec3d>> estimated;  // report.json's light direction per frame
  if (fs::exists(repainted / "report.json")) {
    auto bytes = io::read_file_bytes(repainted / "report.json");
    if (!bytes) return bytes.error();
    const auto j = nlohmann::json::parse(*bytes, nullptr, false);
    if (j.is_object() && j.contains("per_frame") && j["per_frame"].is_array())
      for (const auto& f : j["per_frame"]) {
        files.push_back(repainted / f.value("file", ""));
        lost.push_back(f.value("lost", false));
        std::optional<cv::Vec3d> d;
        if (f.contains("light") && f["light"].is_object() && f["light"].contains("direction")) {
          const auto& v = f["light"]["direction"];
          if (v.is_array() && v.size() == 3 && v[0].is_number() && v[1].is_number() && v[2].is_number())
            d = cv::Vec3d(v[0].get<double>(), v[1].get<double>(), v[2].get<double>());
        }
        estimated.push_back(d);
      }
  }
  if (files.empty()) {
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(repainted, ec)) {
      const std::string name = e.path().filename().string();
      if (name.rfind("frame_", 0) == 0 && e.path().extension() == ".png") files.push_back(e.path());
    }
    if (ec) return make_error(repainted.string() + ": " + ec.message());
    std::sort(files.begin(), files.end());
    lost.assign(files.size(), false);
  }
  estimated.resize(files.size());
  if (files.empty()) return make_error(repainted.string() + ": no repainted frames (frame_NNNN.png, report.json)");
  if (files.size() != sidecar->truth_files.size())
    return make_error(repainted.string() + " holds " + std::to_string(files.size()) + " repainted frames, " +
                      sequence.string() + " " + std::to_string(sidecar->truth_files.size()) + " truth frames");
  auto mask = io::read_mask(sequence / sidecar->truth_mask);
  if (!mask) return mask.error();
  std::vector<cv::Mat> result, truth;
  for (size_t i = 0; i < files.size(); ++i) {
    auto r = read_live_picture(files[i]);
    if (!r) return r.error();
    auto t = read_live_picture(sequence / sidecar->truth_files[i]);
    if (!t) return t.error();
    if (r->size() != t->size())
      return make_error(files[i].string() + " is " + std::to_string(r->cols) + "x" + std::to_string(r->rows) +
                        ", its truth frame " + std::to_string(t->cols) + "x" + std::to_string(t->rows) +
                        " (repaint the sequence through a map of the destination's size)");
    result.push_back(std::move(*r));
    truth.push_back(std::move(*t));
  }
  if (mask->size() != truth[0].size()) return make_error(sidecar->truth_mask + ": not the truth frames' size");
  LiveLookTexture texture;
  if (!map_path.empty()) {
    const fs::path map_file = fs::is_directory(map_path) ? map_path / "map.pfm" : map_path;
    auto map = io::read_pfm(map_file, /*xyz_order=*/true);
    if (!map) return map.error();
    auto photos = look_photos(source_set);
    if (!photos) return photos.error();
    if (photos->empty()) return make_error(source_set.string() + ": no photos");
    texture.map_xy = *map;
    texture.source_median = median_image(*photos);
    if (map->size() != truth[0].size())
      return make_error(map_file.string() + " is " + std::to_string(map->cols) + "x" + std::to_string(map->rows) +
                        ", the repainted frames " + std::to_string(truth[0].cols) + "x" + std::to_string(truth[0].rows));
  }
  auto look = live_look(result, truth, *mask, texture);
  if (!look) return look.error();
  std::vector<double> angles;
  for (size_t i = 0; i < files.size(); ++i) {
    look->frames[i].file = files[i].filename().string();
    look->frames[i].lost = lost[i];
    if (estimated[i] && i < sidecar->lights.size()) {
      const cv::Vec3d a = *estimated[i], b = sidecar->lights[i].direction;
      const double na = cv::norm(a), nb = cv::norm(b);
      if (na > 0 && nb > 0) {
        const double deg = std::acos(std::clamp(a.dot(b) / (na * nb), -1.0, 1.0)) * 180.0 / CV_PI;
        look->frames[i].light_angle_deg = deg;
        angles.push_back(deg);
      }
    }
  }
  if (!angles.empty()) {
    std::vector<double> sorted = angles;
    std::sort(sorted.begin(), sorted.end());
    const size_t n = sorted.size();
    look->light_angle_median_deg = n % 2 ? sorted[n / 2] : 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]);
    look->light_angle_max_deg = sorted.back();
  }
  return look;
}

}  // namespace veneer::eval
