// Image sets on disk: the veneer-set/1 folder (read and written), and two
// layouts that are only read: DiLiGenT and the thesis's PPM/PFM folders.
//
// veneer-set/1 (DESIGN.md, "Image set"):
//   set.json, light_NN.png (16-bit linear RGB, NN = 0-based light index),
//   ambient.png (optional), mask.png (optional, 8-bit), truth/ (simulated sets:
//   normals.pfm xyz, mask.png 8-bit, albedo.png 16-bit, depth.pfm).
//
// DiLiGenT (detected by filenames.txt):
//   filenames.txt          one image file per line, in light order
//   light_directions.txt   "x y z" per line, unit vectors in the rig frame
//   light_intensities.txt  optional, "r g b" per line
//   mask.png               optional object mask
//
// Thesis layout (anything else with a lights.txt): the PPM/PFM files of the
// thesis's experiments, arranged as
//   lights.txt             one lamp per line, "x y z" (unit direction) optionally
//                          followed by "r g b" (intensity); '#' starts a comment
//   <N>.ppm|.pgm|.pfm|.png one image per lamp; N is a decimal number (leading
//                          zeros allowed: 1.ppm, 02.ppm, ...); images are taken
//                          in increasing N and matched to lights.txt line by line
//   ambient.ppm|.pfm|.png  optional
//   mask.pgm|.png          optional
//   normals.pfm            optional reference normals (x,y,z in R,G,B), kept as truth
#include "veneer/io/imageset.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>

#include "set_detail.hpp"
#include "veneer/util/enum_names.hpp"

namespace veneer::io {
namespace fs = std::filesystem;
using namespace detail;

// --- public ----------------------------------------------------------------------

constexpr EnumName<Role> kRoleNames[] = {
    {Role::destination, "destination"}, {Role::source, "source"}, {Role::unknown, "unknown"}};
constexpr EnumName<PhotoSource> kPhotoSourceNames[] = {
    {PhotoSource::automatic, "auto"}, {PhotoSource::raw, "raw"}, {PhotoSource::developed, "developed"}};

const char* role_name(Role role) { return name_of(kRoleNames, role); }

std::optional<Role> parse_role(const std::string& name) {
  if (name.empty()) return Role::unknown;
  return find_value(kRoleNames, name);
}

const char* photo_source_name(PhotoSource p) { return name_of(kPhotoSourceNames, p, "auto"); }

Expected<PhotoSource> parse_photo_source(const std::string& name) {
  return parse_name(kPhotoSourceNames, name, "photo source");
}

Status ReadOptions::check() const { return raw.check(); }
Status validate(const ImageSet& set) {
  if (set.size.width <= 0 || set.size.height <= 0 || set.size.width > kMaxSide || set.size.height > kMaxSide)
    return make_error("size " + size_text(set.size) + " is not a valid image size");
  if (set.lights.empty()) return make_error("the set has no lights");
  if (set.lights.size() > kMaxLights) return make_error("the set has too many lights");
  if (set.images.size() != set.lights.size())
    return make_error("the set has " + std::to_string(set.lights.size()) + " lights but " +
                      std::to_string(set.images.size()) + " images");
  for (size_t i = 0; i < set.lights.size(); ++i) {
    const Light& l = set.lights[i];
    const std::string lw = "light " + std::to_string(i);
    if (l.index != static_cast<int>(i))
      return make_error(lw + ": index is " + std::to_string(l.index) + ", expected its position " + std::to_string(i));
    if (auto e = direction_problem(l.direction); !e.empty()) return make_error(lw + ": " + e);
    if (auto e = intensity_problem(cv::Vec3d(l.intensity[0], l.intensity[1], l.intensity[2])); !e.empty())
      return make_error(lw + ": " + e);
    if (l.position_m && !finite3(*l.position_m)) return make_error(lw + ": position_m " + fmt_vec(*l.position_m) + " is not finite");
    const cv::Mat& im = set.images[i];
    // float, or half floats (ReadOptions::half_floats): every photo of a set alike
    if (im.type() != CV_32FC3 && im.type() != CV_16FC3)
      return make_error("image " + std::to_string(i) + ": expected CV_32FC3 or CV_16FC3 (linear BGR)");
    if (im.type() != set.images[0].type())
      return make_error("image " + std::to_string(i) + ": of another type than image 0 (float and half floats mixed)");
    if (im.size() != set.size)
      return make_error("image " + std::to_string(i) + ": is " + size_text(im.size()) + " but the set is " + size_text(set.size));
  }
  auto check = [&](const cv::Mat& m, int type, const char* what, const char* type_name) -> Status {
    if (m.empty()) return Status::success();
    if (m.type() != type) return make_error(std::string(what) + ": expected " + type_name);
    if (m.size() != set.size)
      return make_error(std::string(what) + ": is " + size_text(m.size()) + " but the set is " + size_text(set.size));
    return Status::success();
  };
  if (set.raw.size() > set.images.size()) return make_error("the set has more RAW files than images");
  auto raw_problem = [](const ImageSet::RawFile& r) {
    if (r.bytes.empty()) return false;
    return r.extension.empty() || r.extension.size() > 8 ||
           !std::all_of(r.extension.begin(), r.extension.end(), [](unsigned char c) { return std::isalnum(c); });
  };
  for (const auto& r : set.raw) {
    if (raw_problem(r)) return make_error("a RAW file's extension must be 1-8 letters or digits");
  }
  if (raw_problem(set.ambient_raw)) return make_error("the ambient RAW file's extension must be 1-8 letters or digits");
  if (Status s = check(set.ambient, set.images[0].type(), "ambient", "the photos' type"); !s) return s;
  if (Status s = check(set.mask, CV_8UC1, "mask", "CV_8UC1"); !s) return s;
  if (Status s = check(set.truth.normals, CV_32FC3, "truth normals", "CV_32FC3 (x, y, z)"); !s) return s;
  if (Status s = check(set.truth.mask, CV_8UC1, "truth mask", "CV_8UC1"); !s) return s;
  if (Status s = check(set.truth.albedo, CV_32FC3, "truth albedo", "CV_32FC3"); !s) return s;
  if (Status s = check(set.truth.depth, CV_32FC1, "truth depth", "CV_32FC1"); !s) return s;
  const CameraInfo& c = set.camera;
  for (auto [name, v] : {std::pair{"exposure_s", c.exposure_s}, std::pair{"aperture", c.aperture},
                         std::pair{"focal_px", c.focal_px}, std::pair{"cx", c.cx}, std::pair{"cy", c.cy}}) {
    if (!std::isfinite(v) || v < 0) return make_error(std::string("camera ") + name + " must be a finite number >= 0");
  }
  if (c.iso < 0) return make_error("camera iso must be >= 0");
  return Status::success();
}

const char* format_name(SetFormat format) {
  switch (format) {
    case SetFormat::veneer: return kSetFormat;
    case SetFormat::diligent: return "DiLiGenT";
    case SetFormat::thesis: return "thesis";
    case SetFormat::rti: return "RTI .lp";
    case SetFormat::automatic: break;
  }
  return "automatic";
}

Expected<ImageSet> read_set(const fs::path& folder, const ReadOptions& options, const Progress& progress) {
  if (Status s = options.check(); !s) return make_error(folder.string() + ": " + s.message());
  std::error_code ec;
  if (!fs::exists(folder, ec)) return make_error(folder.string() + ": no such folder");
  if (!fs::is_directory(folder, ec)) return make_error(folder.string() + ": not a folder");
  SetFormat format = options.format;
  if (format == SetFormat::automatic) {
    if (fs::exists(folder / "set.json", ec)) {
      format = SetFormat::veneer;
    } else if (fs::exists(folder / "filenames.txt", ec)) {
      format = SetFormat::diligent;
    } else if (fs::exists(folder / "lights.txt", ec)) {
      format = SetFormat::thesis;
    } else {
      auto lp = find_lp_file(folder);
      if (!lp) return lp.error();
      format = lp->empty() ? SetFormat::thesis : SetFormat::rti;  // thesis: its reader names what is missing
    }
  }
  Expected<ImageSet> set = make_error("unknown set format");
  switch (format) {
    case SetFormat::veneer: set = read_veneer(folder, options, progress); break;
    case SetFormat::diligent: set = read_diligent(folder, options, progress); break;
    case SetFormat::thesis: set = read_thesis(folder, options, progress); break;
    case SetFormat::rti: set = read_rti(folder, options, progress); break;
    case SetFormat::automatic: break;
  }
  if (!set) return set;
  set->layout = format_name(format);
  if (!options.load_photos && format == SetFormat::veneer) return set;  // no pixels to check
  // A last check of the invariants every reader promises.
  if (Status s = validate(*set); !s) return make_error(folder.string() + ": " + s.message());
  return set;
}

}  // namespace veneer::io
