// veneer calibrate — lamp directions from a chrome-sphere set: the sphere's
// circle, each lamp's highlight, the reflected directions (and positions with
// --distance), written as a lights file that `veneer normals --lights` reads;
// with --rig-config, the lamps' positions go into the rig's veneerd.json.
#include <cstdio>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "command.hpp"
#include "output.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"
#include "veneer/ps/calibration.hpp"

namespace fs = std::filesystem;

namespace {

struct CalibrateArgs {
  std::string set, out, picture, rig_config;
  double distance = 0;
  double highlight = veneer::ps::CalibrationOptions{}.highlight_fraction;
};

::veneer::cli::Output report{"calibrate"};

// The rig's config with the lamps' positions put in as lamps.positions_m,
// everything else in it kept; the count must match lamps.lamps.
veneer::Expected<std::string> rig_config_with_positions(const fs::path& file, const veneer::ps::LightCalibration& cal) {
  auto bytes = veneer::io::read_file_bytes(file);
  if (!bytes) return veneer::make_error(file.string() + ": " + bytes.message());
  nlohmann::json doc;
  try {
    doc = nlohmann::json::parse(*bytes);
  } catch (const nlohmann::json::exception& e) {
    return veneer::make_error(file.string() + ": not JSON: " + e.what());
  }
  if (!doc.is_object()) return veneer::make_error(file.string() + ": not a veneerd config (not a JSON object)");
  nlohmann::json& lamps = doc["lamps"];
  if (lamps.is_null()) lamps = nlohmann::json::object();
  if (!lamps.is_object()) return veneer::make_error(file.string() + ": lamps is not an object");
  if (lamps.contains("lamps") && lamps["lamps"].is_array() && lamps["lamps"].size() != cal.positions_m.size())
    return veneer::make_error(file.string() + ": lamps.lamps names " + std::to_string(lamps["lamps"].size()) +
                              " lamps, the calibration found " + std::to_string(cal.positions_m.size()));
  nlohmann::json pos = nlohmann::json::array();
  for (const auto& p : cal.positions_m) pos.push_back({p[0], p[1], p[2]});
  lamps["positions_m"] = pos;
  return doc.dump(2) + "\n";
}

int run_calibrate(const CalibrateArgs& a) {
  if (a.set.empty()) return report.usage("a SET folder (photos of a chrome sphere, one per lamp) is required");
  if (a.out.empty()) return report.usage("--out FILE.json is required");
  if (!a.rig_config.empty() && a.distance <= 0)
    return report.usage("--rig-config stores the lamps' positions: give --distance (the lamps' distance from the "
                        "sphere, metres)");
  veneer::ps::CalibrationOptions o;
  o.highlight_fraction = a.highlight;
  o.lamp_distance_m = a.distance;
  if (auto st = o.check(); !st) return report.usage(st.message());

  auto set = veneer::io::read_set(a.set);
  if (!set) return report.fail(set.message());
  auto cal = veneer::ps::calibrate_mirror_sphere(*set, {}, o);
  if (!cal) return report.fail(a.set + ": " + cal.message());

  // Everything is checked before anything is written.
  std::string rig_config;
  if (!a.rig_config.empty()) {
    auto text = rig_config_with_positions(a.rig_config, *cal);
    if (!text) return report.fail(text.message());
    rig_config = *text;
  }
  if (auto st = veneer::ps::write_light_calibration(*cal, a.out); !st) return report.fail(st.message());
  const std::string picture = a.picture.empty() ? fs::path(a.out).replace_extension(".png").string() : a.picture;
  if (auto st = veneer::io::write_picture(picture, veneer::ps::calibration_picture(*set, *cal)); !st)
    return report.fail(st.message());
  if (!a.rig_config.empty()) {
    if (auto st = veneer::io::write_file_atomic(a.rig_config, rig_config); !st) return report.fail(st.message());
  }

  std::printf("sphere: centre (%.2f, %.2f) px, radius %.2f px (outline %.2f px RMS off the circle)\n", cal->center.x,
              cal->center.y, cal->radius, cal->circle_rms_px);
  // A set that came with directions (DiLiGenT's light_directions.txt, a rig's
  // set.json) is compared with what was found.
  const bool compare = set->lights.size() == cal->directions.size();
  double sum = 0;
  for (size_t i = 0; i < cal->directions.size(); ++i) {
    const cv::Vec3d d = cal->directions[i];
    std::printf("lamp %2zu: highlight (%.2f, %.2f) px, direction (%.4f, %.4f, %.4f)", i + 1, cal->highlights[i].x,
                cal->highlights[i].y, d[0], d[1], d[2]);
    if (compare) {
      const double deg = veneer::ps::angle_deg(d, set->lights[i].direction);
      sum += deg;
      std::printf(", %.2f deg from the set's", deg);
    }
    std::printf("\n");
  }
  if (compare) std::printf("mean %.2f deg from the set's directions\n", sum / cal->directions.size());
  return report.wrote(a.out + " " + picture + (a.rig_config.empty() ? "" : " " + a.rig_config));
}

}  // namespace

VENEER_ARGS_COMMAND(calibrate, CalibrateArgs,
                    "lamp directions from photos of a chrome sphere (one per lamp): fits the sphere's outline, finds "
                    "each lamp's highlight and writes the reflected directions as a lights file for `normals "
                    "--lights` (a picture of what was found beside it)") {
  cmd->add_option("SET", args->set, "set of chrome-sphere photos (its mask.png, if any, outlines the sphere)");
  cmd->add_option("--out", args->out, "the lights file to write (JSON, veneer-lights/1)");
  cmd->add_option("--picture", args->picture, "picture of the circle and highlights (default: --out with .png)");
  cmd->add_option("--distance", args->distance,
                  "the lamps' distance from the sphere, metres: positions too (direction x distance)");
  cmd->add_option("--highlight", args->highlight,
                  "a highlight is the pixels above this fraction of the photo's brightest, (0, 1)")
      ->capture_default_str();
  cmd->add_option("--rig-config", args->rig_config,
                  "store the lamps' positions in this veneerd.json (lamps.positions_m; needs --distance)");
  return [args] { return run_calibrate(*args); };
}
