// veneer info SET [--json]: what an image set holds (any layout read_set reads)
// and how it was read (layout, photo files, linearisation or RAW decode).
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>

#include "command.hpp"
#include "output.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/imageset.hpp"

namespace veneer::cli {
namespace {
namespace fs = std::filesystem;

std::string vec3(const cv::Vec3d& v) {
  char buf[80];
  std::snprintf(buf, sizeof buf, "(%+.4f, %+.4f, %+.4f)", v[0], v[1], v[2]);
  return buf;
}

void print_summary(const io::ImageSet& set, const fs::path& folder) {
  auto row = [](const char* key, const std::string& value) { std::printf("%-10s %s\n", key, value.c_str()); };
  row("set", folder.string());
  row("format", set.layout.empty() ? "-" : set.layout);
  row("photos", set.photos_read.empty() ? "-" : set.photos_read);
  row("id", set.id);
  row("object", set.object.empty() ? "-" : set.object);
  row("role", io::role_name(set.role));
  if (!set.created.empty()) row("created", set.created);
  if (!set.scene.empty()) row("scene", set.scene);
  row("size", std::to_string(set.size.width) + "x" + std::to_string(set.size.height));
  const io::CameraInfo& c = set.camera;
  if (!c.model.empty() || c.exposure_s > 0 || c.focal_px > 0) {
    char buf[256];
    std::snprintf(buf, sizeof buf, "%s, exposure %g s, f/%g, ISO %d", c.model.empty() ? "?" : c.model.c_str(),
                  c.exposure_s, c.aperture, c.iso);
    std::string cam = buf;
    if (c.focal_px > 0) {
      std::snprintf(buf, sizeof buf, ", focal %.1f px, centre (%.1f, %.1f)", c.focal_px, c.cx, c.cy);
      cam += buf;
    }
    row("camera", cam);
  }
  row("ambient", set.ambient.empty() ? "no" : "yes");
  row("mask", set.mask.empty() ? "no" : "yes (" + std::to_string(cv::countNonZero(set.mask)) + " object pixels)");
  std::string truth;
  for (auto [name, m] : {std::pair{"normals", &set.truth.normals}, std::pair{"mask", &set.truth.mask},
                         std::pair{"albedo", &set.truth.albedo}, std::pair{"depth", &set.truth.depth}}) {
    if (!m->empty()) truth += (truth.empty() ? "" : ", ") + std::string(name);
  }
  row("truth", truth.empty() ? "none" : truth);
  row("lights", std::to_string(set.lights.size()));
  std::printf("  %-3s %-10s %-33s %-16s %s\n", "#", "lamp", "direction (x right, y up, z out)", "intensity r,g,b",
              "mean level");
  for (size_t i = 0; i < set.lights.size(); ++i) {
    const io::Light& l = set.lights[i];
    cv::Scalar mean = cv::mean(set.images[i]);
    char in[64];
    std::snprintf(in, sizeof in, "%.3g, %.3g, %.3g", l.intensity[0], l.intensity[1], l.intensity[2]);
    std::printf("  %-3d %-10s %-33s %-16s %.4f", l.index, l.lamp_id.empty() ? "-" : l.lamp_id.c_str(),
                vec3(l.direction).c_str(), in, (mean[0] + mean[1] + mean[2]) / 3);
    if (l.position_m) std::printf("   at %s m", vec3(*l.position_m).c_str());
    std::printf("\n");
  }
  if (set.warnings.empty()) {
    row("warnings", "none");
  } else {
    for (const auto& w : set.warnings) row("warning", w);
  }
}

::veneer::cli::Output report{"info"};

int run(const std::string& folder, bool as_json) {
  auto set = io::read_set(folder);
  if (!set) {
    return report.fail(set.message());
  }
  if (as_json) {
    // A veneer set's own manifest as stored; other layouts as the manifest
    // they would get if written as a veneer set.
    if (fs::exists(fs::path(folder) / "set.json")) {
      auto text = io::read_file_bytes(fs::path(folder) / "set.json");
      if (!text) {
        return report.fail(text.message());
      }
      std::cout << *text;
      if (!text->empty() && text->back() != '\n') std::cout << "\n";
    } else {
      std::cout << io::manifest_json(*set);
    }
    return 0;
  }
  print_summary(*set, folder);
  return 0;
}

}  // namespace

VENEER_COMMAND(info) {
  auto* cmd = app.add_subcommand("info", "Describe an image set (veneer-set/1, DiLiGenT, thesis or RTI .lp folder) and how its photos are read");
  auto folder = std::make_shared<std::string>();
  auto as_json = std::make_shared<bool>(false);
  cmd->add_option("SET", *folder, "the set's folder")->required();
  cmd->add_flag("--json", *as_json, "print the manifest (set.json) instead of a summary");
  return [=] { return run(*folder, *as_json); };
}

}  // namespace veneer::cli
