// Image sets on disk: the veneer-set/1 folder (read and written), and two
// layouts that are only read: DiLiGenT and the thesis's PPM/PFM folders.
//
// veneer-set/1 (DESIGN.md, "Image set"):
//   set.json, light_NN.png (16-bit linear RGB, NN = 0-based light index) or
//   the camera's light_NN.jpg (8-bit sRGB) with its RAW file light_NN.dng,
//   ambient.* (optional), mask.png (optional, 8-bit), truth/ (simulated sets:
//   normals.pfm xyz, mask.png 8-bit, albedo.png 16-bit, depth.pfm). A preview
//   set (a reduced copy pulled first for a live view) says "preview_of".
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
// PFM photos are used as stored (linear, 1.0 = full scale).
#include "veneer/io/imageset.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <map>
#include <set>
#include <sstream>

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <mutex>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/parallel_for.h>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgcodecs.hpp>

#include "file_util.hpp"
#include "veneer/io/image_io.hpp"
#include "veneer/io/raw.hpp"
#include "veneer/util/log.hpp"

namespace veneer {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr int kMaxSide = 1 << 16;
constexpr size_t kMaxLights = 1024;
constexpr uintmax_t kMaxManifestBytes = 16u << 20;

std::string fmt_vec(const cv::Vec3d& v) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "(%.6g, %.6g, %.6g)", v[0], v[1], v[2]);
  return buf;
}

std::string size_text(cv::Size s) { return std::to_string(s.width) + "x" + std::to_string(s.height); }

bool finite3(const cv::Vec3d& v) { return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]); }

// A direction that is finite and of unit length within kUnitTolerance; else why not.
std::string direction_problem(const cv::Vec3d& d) {
  if (!finite3(d)) return "direction " + fmt_vec(d) + " is not finite";
  double len = cv::norm(d);
  if (std::abs(len - 1.0) > kUnitTolerance) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.6g", len);
    return "direction " + fmt_vec(d) + " has length " + buf + ", expected a unit vector";
  }
  return {};
}

std::string intensity_problem(const cv::Vec3d& v) {
  if (!finite3(v)) return "intensity " + fmt_vec(v) + " is not finite";
  if (v[0] < 0 || v[1] < 0 || v[2] < 0) return "intensity " + fmt_vec(v) + " is negative";
  return {};
}

// A file named by a manifest or list must stay inside the set folder.
std::string file_name_problem(const std::string& name) {
  if (name.empty()) return "empty file name";
  if (name.find('\0') != std::string::npos) return "file name contains a NUL byte";
  fs::path p(name);
  if (p.is_absolute()) return "file name \"" + name + "\" is absolute; it must be relative to the set folder";
  for (const auto& part : p) {
    if (part == "..") return "file name \"" + name + "\" leaves the set folder";
  }
  if (!p.has_filename()) return "file name \"" + name + "\" names a folder";
  return {};
}

std::string utc_now() {
  std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

std::string light_file_name(int index, const std::string& extension = "png") {
  char buf[32];
  std::snprintf(buf, sizeof buf, "light_%02d.", index);
  return buf + extension;
}

// The developed file of photo k when the set carries the camera's (else empty).
const ImageSet::RawFile* developed_file(const ImageSet& set, size_t k) {
  return k < set.developed.size() && !set.developed[k].bytes.empty() ? &set.developed[k] : nullptr;
}

std::string raw_file_name(int index, const std::string& extension) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "light_%02d.", index);
  return buf + extension;
}

// --- manifest parsing helpers ------------------------------------------------
// Each returns an error text (empty = fine) so the caller can prefix the file.

std::string get_vec3(const json& j, const std::string& what, cv::Vec3d& out) {
  if (!j.is_array() || j.size() != 3) return what + " must be an array of 3 numbers";
  for (int i = 0; i < 3; ++i) {
    if (!j[static_cast<size_t>(i)].is_number()) return what + " must be an array of 3 numbers";
    out[i] = j[static_cast<size_t>(i)].get<double>();
  }
  if (!finite3(out)) return what + " " + fmt_vec(out) + " is not finite";
  return {};
}

std::string get_string(const json& obj, const char* key, std::string& out, bool required) {
  auto it = obj.find(key);
  if (it == obj.end() || it->is_null()) return required ? std::string("missing field \"") + key + "\"" : "";
  if (!it->is_string()) return std::string("field \"") + key + "\" must be a string";
  out = it->get<std::string>();
  return {};
}

std::string get_number(const json& obj, const char* key, double& out) {
  auto it = obj.find(key);
  if (it == obj.end() || it->is_null()) return {};
  if (!it->is_number()) return std::string("field \"") + key + "\" must be a number";
  double v = it->get<double>();
  if (!std::isfinite(v) || v < 0) return std::string("field \"") + key + "\" must be a finite number >= 0";
  out = v;
  return {};
}

std::string get_index(const json& obj, const char* key, const std::string& where, int& out) {
  auto it = obj.find(key);
  if (it == obj.end()) return where + ": missing field \"" + key + "\"";
  if (!it->is_number_integer()) return where + ": field \"" + key + "\" must be an integer";
  long long v = it->get<long long>();
  if (v < 0 || v >= static_cast<long long>(kMaxLights))
    return where + ": field \"" + key + "\" = " + std::to_string(v) + " is out of range";
  out = static_cast<int>(v);
  return {};
}

Expected<Manifest> parse_manifest_json(const json& root, const fs::path& folder) {
  Manifest m;
  ImageSet& set = m.set;
  set.origin = folder;
  if (!root.is_object()) return make_error("the manifest must be a JSON object");

  std::string format;
  if (auto e = get_string(root, "format", format, true); !e.empty()) return make_error(e);
  if (format != kSetFormat)
    return make_error("format is \"" + format.substr(0, 64) + "\", expected \"" + kSetFormat + "\"");

  if (auto e = get_string(root, "id", set.id, false); !e.empty()) return make_error(e);
  if (set.id.empty()) set.id = (folder.has_filename() ? folder : folder.parent_path()).filename().string();
  std::string role = "unknown";
  if (auto e = get_string(root, "role", role, false); !e.empty()) return make_error(e);
  auto parsed_role = parse_role(role);
  if (!parsed_role) return make_error("role \"" + role.substr(0, 64) + "\" is not destination, source or unknown");
  set.role = *parsed_role;
  if (auto e = get_string(root, "object", set.object, false); !e.empty()) return make_error(e);
  if (auto e = get_string(root, "created", set.created, false); !e.empty()) return make_error(e);
  if (auto e = get_string(root, "scene", set.scene, false); !e.empty()) return make_error(e);

  auto size = root.find("size");
  if (size == root.end()) return make_error("missing field \"size\"");
  if (!size->is_array() || size->size() != 2 || !(*size)[0].is_number_integer() || !(*size)[1].is_number_integer())
    return make_error("field \"size\" must be [width, height] in pixels");
  long long w = (*size)[0].get<long long>(), h = (*size)[1].get<long long>();
  if (w <= 0 || h <= 0 || w > kMaxSide || h > kMaxSide)
    return make_error("size [" + std::to_string(w) + ", " + std::to_string(h) + "] is not a valid image size");
  set.size = cv::Size(static_cast<int>(w), static_cast<int>(h));

  if (auto cam = root.find("camera"); cam != root.end() && !cam->is_null()) {
    if (!cam->is_object()) return make_error("field \"camera\" must be an object");
    CameraInfo& c = set.camera;
    if (auto e = get_string(*cam, "model", c.model, false); !e.empty()) return make_error("camera: " + e);
    for (auto [key, dst] : {std::pair{"exposure_s", &c.exposure_s}, std::pair{"aperture", &c.aperture},
                            std::pair{"focal_px", &c.focal_px}, std::pair{"cx", &c.cx}, std::pair{"cy", &c.cy}}) {
      if (auto e = get_number(*cam, key, *dst); !e.empty()) return make_error("camera: " + e);
    }
    if (auto iso = cam->find("iso"); iso != cam->end() && !iso->is_null()) {
      if (!iso->is_number_integer() || iso->get<long long>() < 0 || iso->get<long long>() > 10'000'000)
        return make_error("camera: field \"iso\" must be a non-negative integer");
      c.iso = static_cast<int>(iso->get<long long>());
    }
  }

  auto lights = root.find("lights");
  if (lights == root.end()) return make_error("missing field \"lights\"");
  if (!lights->is_array() || lights->empty()) return make_error("field \"lights\" must be a non-empty array");
  if (lights->size() > kMaxLights) return make_error("too many lights (" + std::to_string(lights->size()) + ")");
  std::map<int, Light> by_index;
  for (size_t i = 0; i < lights->size(); ++i) {
    const json& jl = (*lights)[i];
    const std::string where = "lights[" + std::to_string(i) + "]";
    if (!jl.is_object()) return make_error(where + " must be an object");
    Light light;
    if (auto e = get_index(jl, "index", where, light.index); !e.empty()) return make_error(e);
    const std::string lw = "light " + std::to_string(light.index);
    if (by_index.count(light.index)) return make_error("duplicate light index " + std::to_string(light.index));
    if (auto e = get_string(jl, "lamp_id", light.lamp_id, false); !e.empty()) return make_error(lw + ": " + e);
    auto dir = jl.find("direction");
    if (dir == jl.end()) return make_error(lw + ": missing field \"direction\"");
    if (auto e = get_vec3(*dir, "direction", light.direction); !e.empty()) return make_error(lw + ": " + e);
    if (auto e = direction_problem(light.direction); !e.empty()) return make_error(lw + ": " + e);
    if (auto pos = jl.find("position_m"); pos != jl.end() && !pos->is_null()) {
      cv::Vec3d p;
      if (auto e = get_vec3(*pos, "position_m", p); !e.empty()) return make_error(lw + ": " + e);
      light.position_m = p;
    }
    if (auto in = jl.find("intensity"); in != jl.end() && !in->is_null()) {
      cv::Vec3d v;
      if (auto e = get_vec3(*in, "intensity", v); !e.empty()) return make_error(lw + ": " + e);
      if (auto e = intensity_problem(v); !e.empty()) return make_error(lw + ": " + e);
      light.intensity = cv::Vec3f(static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2]));
    }
    by_index.emplace(light.index, std::move(light));
  }
  // Indices are positions in the light list: 0..n-1, each once.
  int expect = 0;
  for (auto& [index, light] : by_index) {
    if (index != expect)
      return make_error("light indices must be 0.." + std::to_string(by_index.size() - 1) + ", but light " +
                        std::to_string(expect) + " is missing");
    set.lights.push_back(light);
    ++expect;
  }

  auto images = root.find("images");
  if (images == root.end()) return make_error("missing field \"images\"");
  if (!images->is_array()) return make_error("field \"images\" must be an array");
  if (images->size() != set.lights.size())
    return make_error("lists " + std::to_string(set.lights.size()) + " lights but " + std::to_string(images->size()) +
                      " images; every light needs exactly one image");
  m.image_files.assign(set.lights.size(), fs::path());
  std::set<std::string> seen_files;
  for (size_t i = 0; i < images->size(); ++i) {
    const json& ji = (*images)[i];
    const std::string where = "images[" + std::to_string(i) + "]";
    if (!ji.is_object()) return make_error(where + " must be an object");
    int light = 0;
    if (auto e = get_index(ji, "light", where, light); !e.empty()) return make_error(e);
    if (light >= static_cast<int>(set.lights.size()))
      return make_error(where + ": light " + std::to_string(light) + " is not in the light list (" +
                        std::to_string(set.lights.size()) + " lights)");
    if (!m.image_files[static_cast<size_t>(light)].empty())
      return make_error(where + ": light " + std::to_string(light) + " has more than one image");
    std::string file;
    if (auto e = get_string(ji, "file", file, true); !e.empty()) return make_error(where + ": " + e);
    if (auto e = file_name_problem(file); !e.empty()) return make_error(where + ": " + e);
    if (!seen_files.insert(file).second) return make_error(where + ": file \"" + file + "\" is listed twice");
    m.image_files[static_cast<size_t>(light)] = file;
    std::string raw;
    if (auto e = get_string(ji, "raw", raw, false); !e.empty()) return make_error(where + ": " + e);
    if (!raw.empty()) {
      if (auto e = file_name_problem(raw); !e.empty()) return make_error(where + ": raw: " + e);
      if (!seen_files.insert(raw).second) return make_error(where + ": file \"" + raw + "\" is listed twice");
      if (m.raw_files.empty()) m.raw_files.assign(set.lights.size(), fs::path());
      m.raw_files[static_cast<size_t>(light)] = raw;
    }
  }

  for (auto [key, dst] : {std::pair{"ambient", &m.ambient_file}, std::pair{"mask", &m.mask_file},
                          std::pair{"ambient_raw", &m.ambient_raw_file}}) {
    std::string file;
    if (auto e = get_string(root, key, file, false); !e.empty()) return make_error(e);
    if (file.empty()) continue;
    if (auto e = file_name_problem(file); !e.empty()) return make_error(std::string(key) + ": " + e);
    *dst = file;
  }

  if (auto p = root.find("preview_of"); p != root.end() && !p->is_null()) {
    ImageSet::PreviewOf of;
    auto ps = p->is_object() ? p->find("size") : p->end();
    if (!p->is_object() || !get_string(*p, "id", of.id, true).empty() || ps == p->end() || !ps->is_array() ||
        ps->size() != 2 || !(*ps)[0].is_number_integer() || !(*ps)[1].is_number_integer() ||
        (*ps)[0].get<long long>() <= 0 || (*ps)[1].get<long long>() <= 0 || (*ps)[0].get<long long>() > kMaxSide ||
        (*ps)[1].get<long long>() > kMaxSide)
      return make_error("field \"preview_of\" must be {\"id\": the full set's id, \"size\": [width, height]}");
    of.size = cv::Size(static_cast<int>((*ps)[0].get<long long>()), static_cast<int>((*ps)[1].get<long long>()));
    set.preview_of = std::move(of);
  }

  if (auto warn = root.find("warnings"); warn != root.end() && !warn->is_null()) {
    if (!warn->is_array()) return make_error("field \"warnings\" must be an array of strings");
    for (const auto& w : *warn) {
      if (!w.is_string()) return make_error("field \"warnings\" must be an array of strings");
      set.warnings.push_back(w.get<std::string>());
    }
  }
  return m;
}

// --- loading pixels ------------------------------------------------------------

// One file to decode into a photo: through LibRaw when `raw`, else by its magic
// (PNG, JPEG, PFM, PNM).
struct Frame {
  fs::path file;
  bool raw = false;
};

// Decodes `frames` in parallel (one task per file, each file read and decoded
// once) into CV_32FC3; `kinds` gets each file's kind ("raw", "png", ...). The
// first error wins by list order, so the message does not depend on thread
// timing. Progress is reported from the worker threads under a lock.
Status decode_frames(const std::vector<Frame>& frames, const RawOptions& raw_options, const Progress& progress,
                     const std::string& stage, std::vector<cv::Mat>& out, std::vector<std::string>* kinds = nullptr) {
  out.assign(frames.size(), cv::Mat());
  if (kinds) kinds->assign(frames.size(), std::string());
  std::vector<std::string> errors(frames.size());
  std::atomic<size_t> done{0};
  std::mutex report_lock;
  progress.report(0.0, stage);
  tbb::parallel_for(size_t(0), frames.size(), [&](size_t i) {
    if (progress.cancelled()) {
      errors[i] = "cancelled";
      return;
    }
    const Frame& f = frames[i];
    auto mapped = io_detail::MappedFile::open(f.file);  // read in place: no copy, no fresh pages
    if (!mapped) {
      errors[i] = mapped.message();
      return;
    }
    const std::string_view bytes = mapped->bytes();
    Expected<cv::Mat> image = f.raw ? decode_raw_linear(bytes, raw_options, f.file.string())
                                    : decode_linear_image(bytes, f.file.string());
    if (!image) {
      errors[i] = image.message();
      return;
    }
    out[i] = std::move(image).value();
    if (kinds) (*kinds)[i] = f.raw ? (raw_options.half_size ? "raw-half" : "raw") : image_file_kind(bytes);
    const size_t n = ++done;
    if (progress.on_progress) {
      std::lock_guard<std::mutex> lock(report_lock);
      progress.report(static_cast<double>(n) / static_cast<double>(frames.size()), stage);
    }
  });
  for (const auto& e : errors) {
    if (!e.empty()) return make_error(e);
  }
  return Status::success();
}

Status load_images(const std::vector<fs::path>& files, std::vector<cv::Mat>& out, const Progress& progress = {},
                   const std::string& stage = "reading") {
  std::vector<Frame> frames;
  for (const auto& f : files) frames.push_back({f, false});
  return decode_frames(frames, RawOptions{}, progress, stage, out);
}

Status check_size(const fs::path& file, const cv::Mat& image, cv::Size expected, const std::string& why) {
  if (image.size() != expected)
    return make_error(file.string() + ": image is " + size_text(image.size()) + " but " + why + " is " +
                      size_text(expected));
  return Status::success();
}

Status load_truth(const fs::path& truth_dir, ImageSet& set, bool appearance) {
  std::error_code ec;
  if (!fs::is_directory(truth_dir, ec)) return Status::success();
  Truth& t = set.truth;
  const std::string why = "the set's size";
  if (fs::path f = truth_dir / "normals.pfm"; fs::exists(f, ec)) {
    auto n = read_pfm(f, true);
    if (!n) return n.error();
    if (n->channels() != 3) return make_error(f.string() + ": normals must have 3 channels (x, y, z)");
    if (Status s = check_size(f, *n, set.size, why); !s) return s;
    t.normals = std::move(n).value();
  }
  if (fs::path f = truth_dir / "mask.png"; fs::exists(f, ec)) {
    auto m = read_mask(f);
    if (!m) return m.error();
    if (Status s = check_size(f, *m, set.size, why); !s) return s;
    t.mask = std::move(m).value();
  }
  if (!appearance) return Status::success();
  if (fs::path f = truth_dir / "albedo.png"; fs::exists(f, ec)) {
    auto a = read_linear_image(f);
    if (!a) return a.error();
    if (Status s = check_size(f, *a, set.size, why); !s) return s;
    t.albedo = std::move(a).value();
  }
  if (fs::path f = truth_dir / "depth.pfm"; fs::exists(f, ec)) {
    auto d = read_pfm(f, true);
    if (!d) return d.error();
    if (d->channels() != 1) return make_error(f.string() + ": depth must have 1 channel");
    if (Status s = check_size(f, *d, set.size, why); !s) return s;
    t.depth = std::move(d).value();
  }
  return Status::success();
}

// Resizes what comes with the photos (mask, truth, intrinsics) from the
// manifest's size to the size the RAW files decoded to.
void fit_to_photos(ImageSet& set, cv::Size size) {
  if (size == set.size) return;
  const double sx = static_cast<double>(size.width) / set.size.width;
  const double sy = static_cast<double>(size.height) / set.size.height;
  auto nearest = [&](cv::Mat& m) {
    if (!m.empty()) cv::resize(m, m, size, 0, 0, cv::INTER_NEAREST);
  };
  nearest(set.mask);
  nearest(set.truth.mask);
  nearest(set.truth.normals);
  nearest(set.truth.depth);
  if (!set.truth.albedo.empty()) cv::resize(set.truth.albedo, set.truth.albedo, size, 0, 0, cv::INTER_LINEAR);
  set.camera.focal_px *= sx;
  set.camera.cx *= sx;
  set.camera.cy *= sy;
  set.size = size;
}

Expected<ImageSet> read_veneer(const fs::path& folder, const ReadOptions& options, const Progress& progress) {
  const fs::path manifest_file = folder / "set.json";
  std::error_code ec;
  if (auto bytes = fs::file_size(manifest_file, ec); !ec && bytes > kMaxManifestBytes)
    return make_error(manifest_file.string() + ": " + std::to_string(bytes) + " bytes is too large for a manifest");
  auto text = read_file_bytes(manifest_file);
  if (!text) return text.error();
  auto manifest = parse_manifest(*text, folder);
  if (!manifest) return manifest.error();
  ImageSet set = std::move(manifest->set);

  // RAW where every photo (and the ambient frame) has its RAW file, unless told otherwise.
  const bool all_raw =
      !manifest->raw_files.empty() &&
      std::all_of(manifest->raw_files.begin(), manifest->raw_files.end(), [](const fs::path& f) { return !f.empty(); }) &&
      (manifest->ambient_file.empty() || !manifest->ambient_raw_file.empty());
  if (options.photos == PhotoSource::raw && !all_raw)
    return make_error(manifest_file.string() + ": RAW photos were asked for, but not every image" +
                      std::string(manifest->ambient_file.empty() ? "" : " and the ambient frame") + " names a RAW file");
  const bool use_raw = options.photos != PhotoSource::developed && all_raw;

  // The mask (set.json's size) and the truth, with or without the photos.
  auto load_mask_and_truth = [&]() -> Status {
    if (!manifest->mask_file.empty()) {
      fs::path f = folder / manifest->mask_file;
      auto m = read_mask(f);
      if (!m) return m.error();
      if (Status s = check_size(f, *m, set.size, "set.json's size"); !s) return s;
      set.mask = std::move(m).value();
    }
    if (options.load_truth) return load_truth(folder / "truth", set, options.load_truth_appearance);
    return {};
  };
  if (!options.load_photos) {
    if (Status s = load_mask_and_truth(); !s) return s.error();
    set.photos_from = use_raw ? (options.raw.half_size ? "raw-half" : "raw") : "developed";
    return set;
  }
  std::vector<Frame> frames;
  for (size_t i = 0; i < manifest->image_files.size(); ++i)
    frames.push_back(use_raw ? Frame{folder / manifest->raw_files[i], true} : Frame{folder / manifest->image_files[i], false});
  if (!manifest->ambient_file.empty())
    frames.push_back(use_raw ? Frame{folder / manifest->ambient_raw_file, true} : Frame{folder / manifest->ambient_file, false});
  std::vector<cv::Mat> decoded;
  std::vector<std::string> kinds;
  const std::string stage = "reading " + (set.id.empty() ? folder.filename().string() : set.id);
  if (Status s = decode_frames(frames, options.raw, progress, stage, decoded, &kinds); !s) return s.error();
  if (!manifest->ambient_file.empty()) {
    set.ambient = std::move(decoded.back());
    decoded.pop_back();
  }
  set.images = std::move(decoded);
  set.photos_from = kinds.empty() ? std::string() : kinds.front();
  for (const auto& k : kinds) {
    if (k != set.photos_from) {
      set.photos_from = "mixed";
      break;
    }
  }

  // Developed photos must have set.json's size; RAW photos define it.
  const cv::Size photo_size = set.images.front().size();
  const std::string why = use_raw ? "the first RAW photo's size" : "set.json's size";
  const cv::Size expect = use_raw ? photo_size : set.size;
  for (size_t i = 0; i < frames.size(); ++i) {
    const cv::Mat& m = i < set.images.size() ? set.images[i] : set.ambient;
    if (Status s = check_size(frames[i].file, m, expect, why); !s) return s.error();
  }
  if (Status s = load_mask_and_truth(); !s) return s.error();
  if (use_raw && photo_size != set.size) {
    VLOG_INFO("ImageSet", "{}: RAW photos are {}, set.json says {}; mask, truth and intrinsics scaled to the RAW size",
              folder.string(), size_text(photo_size), size_text(set.size));
    fit_to_photos(set, photo_size);
  }
  return set;
}

// --- text lists (DiLiGenT, thesis) -----------------------------------------------

struct Line {
  int number;  // 1-based
  std::string text;
};

// Non-empty lines with '#' comments and surrounding blanks removed.
Expected<std::vector<Line>> read_lines(const fs::path& file) {
  auto bytes = read_file_bytes(file);
  if (!bytes) return bytes.error();
  if (bytes->find('\0') != std::string::npos) return make_error(file.string() + ": not a text file");
  std::vector<Line> lines;
  std::stringstream ss(*bytes);
  std::string line;
  int number = 0;
  while (std::getline(ss, line)) {
    ++number;
    if (auto hash = line.find('#'); hash != std::string::npos) line.erase(hash);
    auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos) continue;
    auto last = line.find_last_not_of(" \t\r");
    lines.push_back({number, line.substr(first, last - first + 1)});
  }
  return lines;
}

// Parses whitespace-separated numbers (strict: every token must be a number).
bool parse_numbers(const std::string& text, std::vector<double>& out) {
  out.clear();
  std::stringstream ss(text);
  std::string token;
  while (ss >> token) {
    double v = 0;
    const char* begin = token.data();
    const char* end = begin + token.size();
    if (*begin == '+') ++begin;
    auto [p, ec] = std::from_chars(begin, end, v);
    if (ec != std::errc() || p != end) return false;
    out.push_back(v);
  }
  return true;
}

// "x y z" (and optionally "r g b" when allow_rgb) per line.
Status parse_light_lines(const fs::path& file, const std::vector<Line>& lines, bool allow_rgb,
                         std::vector<Light>& lights) {
  std::vector<double> v;
  for (const Line& line : lines) {
    const std::string where = file.string() + " line " + std::to_string(line.number);
    if (!parse_numbers(line.text, v) || !(v.size() == 3 || (allow_rgb && v.size() == 6)))
      return make_error(where + ": expected \"x y z\"" + std::string(allow_rgb ? " or \"x y z r g b\"" : "") +
                        ", got \"" + line.text.substr(0, 80) + "\"");
    Light light;
    light.index = static_cast<int>(lights.size());
    light.direction = cv::Vec3d(v[0], v[1], v[2]);
    if (auto e = direction_problem(light.direction); !e.empty()) return make_error(where + ": " + e);
    if (v.size() == 6) {
      cv::Vec3d in(v[3], v[4], v[5]);
      if (auto e = intensity_problem(in); !e.empty()) return make_error(where + ": " + e);
      light.intensity = cv::Vec3f(static_cast<float>(in[0]), static_cast<float>(in[1]), static_cast<float>(in[2]));
    }
    lights.push_back(light);
  }
  return Status::success();
}

Status check_same_sizes(const std::vector<fs::path>& files, const std::vector<cv::Mat>& images) {
  for (size_t i = 1; i < images.size(); ++i) {
    if (images[i].size() != images[0].size())
      return make_error(files[i].string() + ": image is " + size_text(images[i].size()) + " but " +
                        files[0].filename().string() + " is " + size_text(images[0].size()) +
                        " (all images of a set must have the same size)");
  }
  return Status::success();
}

std::string folder_name(const fs::path& folder) {
  fs::path f = folder;
  if (!f.has_filename()) f = f.parent_path();
  return f.filename().string();
}

Expected<ImageSet> read_diligent(const fs::path& folder, const Progress& progress) {
  ImageSet set;
  set.origin = folder;
  set.id = set.object = folder_name(folder);
  const fs::path names_file = folder / "filenames.txt";
  const fs::path dirs_file = folder / "light_directions.txt";
  const fs::path ints_file = folder / "light_intensities.txt";
  auto names = read_lines(names_file);
  if (!names) return names.error();
  if (names->empty()) return make_error(names_file.string() + ": lists no images");
  if (names->size() > kMaxLights) return make_error(names_file.string() + ": too many images");
  auto dirs = read_lines(dirs_file);
  if (!dirs) return dirs.error();
  if (dirs->size() != names->size())
    return make_error(dirs_file.string() + ": has " + std::to_string(dirs->size()) + " directions but " +
                      names_file.filename().string() + " lists " + std::to_string(names->size()) + " images");
  if (Status s = parse_light_lines(dirs_file, *dirs, false, set.lights); !s) return s.error();
  std::error_code ec;
  if (fs::exists(ints_file, ec)) {
    auto ints = read_lines(ints_file);
    if (!ints) return ints.error();
    if (ints->size() != names->size())
      return make_error(ints_file.string() + ": has " + std::to_string(ints->size()) + " intensities but " +
                        names_file.filename().string() + " lists " + std::to_string(names->size()) + " images");
    std::vector<double> v;
    for (size_t i = 0; i < ints->size(); ++i) {
      const Line& line = (*ints)[i];
      const std::string where = ints_file.string() + " line " + std::to_string(line.number);
      if (!parse_numbers(line.text, v) || v.size() != 3)
        return make_error(where + ": expected \"r g b\", got \"" + line.text.substr(0, 80) + "\"");
      cv::Vec3d in(v[0], v[1], v[2]);
      if (auto e = intensity_problem(in); !e.empty()) return make_error(where + ": " + e);
      set.lights[i].intensity = cv::Vec3f(static_cast<float>(v[0]), static_cast<float>(v[1]), static_cast<float>(v[2]));
    }
  }
  std::vector<fs::path> files;
  for (const Line& line : *names) {
    if (auto e = file_name_problem(line.text); !e.empty())
      return make_error(names_file.string() + " line " + std::to_string(line.number) + ": " + e);
    files.push_back(folder / line.text);
    set.lights[files.size() - 1].lamp_id = fs::path(line.text).stem().string();
  }
  if (Status s = load_images(files, set.images, progress, "reading " + set.id); !s) return s.error();
  if (Status s = check_same_sizes(files, set.images); !s) return s.error();
  set.size = set.images[0].size();
  if (fs::path f = folder / "mask.png"; fs::exists(f, ec)) {
    auto m = read_mask(f);
    if (!m) return m.error();
    if (Status s = check_size(f, *m, set.size, "the images' size"); !s) return s.error();
    set.mask = std::move(m).value();
  }
  return set;
}

// The first existing file among folder/<stem>.<ext> for the given extensions.
fs::path find_with_ext(const fs::path& folder, const std::string& stem, std::initializer_list<const char*> exts) {
  std::error_code ec;
  for (const char* ext : exts) {
    fs::path f = folder / (stem + ext);
    if (fs::is_regular_file(f, ec)) return f;
  }
  return {};
}

Expected<ImageSet> read_thesis(const fs::path& folder, const Progress& progress) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) return make_error(folder.string() + ": not a folder");
  const fs::path lights_file = folder / "lights.txt";
  if (!fs::exists(lights_file, ec))
    return make_error(folder.string() + ": not an image set (no set.json, filenames.txt or lights.txt)");
  ImageSet set;
  set.origin = folder;
  set.id = set.object = folder_name(folder);
  auto lines = read_lines(lights_file);
  if (!lines) return lines.error();
  if (lines->empty()) return make_error(lights_file.string() + ": lists no lights");
  if (lines->size() > kMaxLights) return make_error(lights_file.string() + ": too many lights");
  if (Status s = parse_light_lines(lights_file, *lines, true, set.lights); !s) return s.error();

  std::map<long, fs::path> numbered;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    if (!entry.is_regular_file(ec)) continue;
    const fs::path& p = entry.path();
    std::string ext = p.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    if (ext != ".ppm" && ext != ".pgm" && ext != ".pfm" && ext != ".png") continue;
    std::string stem = p.stem().string();
    if (stem.empty() || stem.size() > 6 || !std::all_of(stem.begin(), stem.end(), [](char c) { return c >= '0' && c <= '9'; }))
      continue;
    long n = std::stol(stem);
    if (auto [it, fresh] = numbered.emplace(n, p); !fresh)
      return make_error(p.string() + ": two images carry number " + std::to_string(n) + " (also " +
                        it->second.filename().string() + ")");
  }
  if (ec) return make_error(folder.string() + ": cannot list folder: " + ec.message());
  if (numbered.size() != set.lights.size())
    return make_error(lights_file.string() + ": lists " + std::to_string(set.lights.size()) + " lights but the folder has " +
                      std::to_string(numbered.size()) + " numbered images (<N>.ppm, .pgm, .pfm or .png)");
  std::vector<fs::path> files;
  for (auto& [n, p] : numbered) {
    set.lights[files.size()].lamp_id = p.stem().string();
    files.push_back(p);
  }
  if (Status s = load_images(files, set.images, progress, "reading " + set.id); !s) return s.error();
  if (Status s = check_same_sizes(files, set.images); !s) return s.error();
  set.size = set.images[0].size();
  const std::string why = "the images' size";
  if (fs::path f = find_with_ext(folder, "ambient", {".ppm", ".pgm", ".pfm", ".png"}); !f.empty()) {
    auto a = read_linear_image(f);
    if (!a) return a.error();
    if (Status s = check_size(f, *a, set.size, why); !s) return s.error();
    set.ambient = std::move(a).value();
  }
  if (fs::path f = find_with_ext(folder, "mask", {".pgm", ".png", ".ppm"}); !f.empty()) {
    auto m = read_mask(f);
    if (!m) return m.error();
    if (Status s = check_size(f, *m, set.size, why); !s) return s.error();
    set.mask = std::move(m).value();
  }
  if (fs::path f = folder / "normals.pfm"; fs::is_regular_file(f, ec)) {
    auto n = read_pfm(f, true);
    if (!n) return n.error();
    if (n->channels() != 3) return make_error(f.string() + ": normals must have 3 channels (x, y, z)");
    if (Status s = check_size(f, *n, set.size, why); !s) return s.error();
    set.truth.normals = std::move(n).value();
  }
  return set;
}

// --- writing ---------------------------------------------------------------------

// Removes temporary folders left beside `target` by writers that died.
void clean_stale_temps(const fs::path& target) {
  std::error_code ec;
  fs::path parent = target.parent_path().empty() ? fs::path(".") : target.parent_path();
  for (const auto& entry : fs::directory_iterator(parent, ec)) {
    const std::string name = entry.path().filename().string();
    for (const char* kind : {"tmp", "old"}) {
      long pid = io_detail::temp_sibling_pid(target, name, kind);
      if (pid <= 0) continue;
      if (pid == static_cast<long>(::getpid())) continue;  // ours, maybe another thread's
      if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;
      std::error_code rm;
      fs::remove_all(entry.path(), rm);
      VLOG_INFO("ImageSet", "removed {} left by a writer that stopped (pid {})", entry.path().string(), pid);
    }
  }
}

// Removes a folder on scope exit unless released.
struct FolderGuard {
  fs::path path;
  ~FolderGuard() {
    if (path.empty()) return;
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

Status write_bytes(const fs::path& file, const Expected<std::string>& bytes) {
  if (!bytes) return make_error(file.string() + ": " + bytes.message());
  return io_detail::write_file_synced(file, *bytes);
}

Status write_contents(const ImageSet& set, const fs::path& dir) {
  // Encode the photos in parallel (the slow part), each written as soon as
  // it is encoded and its bytes dropped: a full-resolution PNG is ~100 MB,
  // so only those being encoded are held, not every one (the rig's capture).
  std::vector<Status> written(set.images.size(), Status::success());
  cv::parallel_for_(cv::Range(0, static_cast<int>(set.images.size())), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) {
      const size_t k = static_cast<size_t>(i);
      const ImageSet::RawFile* camera = developed_file(set, k);
      written[k] = camera ? io_detail::write_file_synced(dir / light_file_name(set.lights[k].index, camera->extension),
                                                         camera->bytes)
                          : write_bytes(dir / light_file_name(set.lights[k].index), encode_png16(set.images[k]));
    }
  });
  for (const Status& s : written) {
    if (!s) return s;  // the first by file order
  }
  for (size_t i = 0; i < set.raw.size() && i < set.lights.size(); ++i) {
    if (set.raw[i].bytes.empty()) continue;
    const fs::path f = dir / raw_file_name(set.lights[i].index, set.raw[i].extension);
    if (Status s = io_detail::write_file_synced(f, set.raw[i].bytes); !s) return s;
  }
  if (!set.ambient.empty()) {
    const ImageSet::RawFile& camera = set.ambient_developed;
    if (Status s = camera.bytes.empty() ? write_bytes(dir / "ambient.png", encode_png16(set.ambient))
                                        : io_detail::write_file_synced(dir / ("ambient." + camera.extension), camera.bytes);
        !s)
      return s;
    if (!set.ambient_raw.bytes.empty()) {
      const fs::path f = dir / ("ambient." + set.ambient_raw.extension);
      if (Status s = io_detail::write_file_synced(f, set.ambient_raw.bytes); !s) return s;
    }
  }
  if (!set.mask.empty()) {
    if (Status s = write_bytes(dir / "mask.png", encode_png8(set.mask)); !s) return s;
  }
  const Truth& t = set.truth;
  if (!t.normals.empty() || !t.mask.empty() || !t.albedo.empty() || !t.depth.empty()) {
    fs::path truth = dir / "truth";
    std::error_code ec;
    if (!fs::create_directory(truth, ec)) return make_error(truth.string() + ": cannot create folder: " + ec.message());
    if (!t.normals.empty()) {
      if (Status s = io_detail::write_file_synced(truth / "normals.pfm", encode_pfm(t.normals, true)); !s) return s;
    }
    if (!t.mask.empty()) {
      if (Status s = write_bytes(truth / "mask.png", encode_png8(t.mask)); !s) return s;
    }
    if (!t.albedo.empty()) {
      if (Status s = write_bytes(truth / "albedo.png", encode_png16(t.albedo)); !s) return s;
    }
    if (!t.depth.empty()) {
      if (Status s = io_detail::write_file_synced(truth / "depth.pfm", encode_pfm(t.depth, true)); !s) return s;
    }
    if (Status s = io_detail::fsync_dir(truth); !s) return s;
  }
  // The manifest last: a folder with a set.json has everything it names.
  if (Status s = io_detail::write_file_synced(dir / "set.json", manifest_json(set)); !s) return s;
  return io_detail::fsync_dir(dir);
}

// Puts arrays of plain values ([w, h], directions, intensities) on one line;
// nlohmann's pretty printer gives every number its own line.
std::string compact_arrays(const std::string& pretty) {
  std::string out;
  out.reserve(pretty.size());
  size_t i = 0;
  while (i < pretty.size()) {
    char c = pretty[i];
    if (c == '"') {  // copy a string literal verbatim
      size_t j = i + 1;
      while (j < pretty.size() && pretty[j] != '"') j += pretty[j] == '\\' ? 2 : 1;
      out.append(pretty, i, j + 1 - i);
      i = j + 1;
      continue;
    }
    if (c == '[') {
      // Flat if no nested array, object or string before the closing bracket.
      size_t j = i + 1;
      while (j < pretty.size() && pretty[j] != ']' && pretty[j] != '[' && pretty[j] != '{' && pretty[j] != '"') ++j;
      if (j < pretty.size() && pretty[j] == ']') {
        out.push_back('[');
        bool space = false;
        for (size_t k = i + 1; k < j; ++k) {
          char d = pretty[k];
          if (d == ' ' || d == '\n') {
            space = true;
            continue;
          }
          if (space && out.back() == ',') out.push_back(' ');
          space = false;
          out.push_back(d);
        }
        out.push_back(']');
        i = j + 1;
        continue;
      }
    }
    out.push_back(c);
    ++i;
  }
  return out;
}

}  // namespace

// --- public ----------------------------------------------------------------------

const char* role_name(Role role) {
  switch (role) {
    case Role::destination: return "destination";
    case Role::source: return "source";
    case Role::unknown: break;
  }
  return "unknown";
}

std::optional<Role> parse_role(const std::string& name) {
  if (name == "destination") return Role::destination;
  if (name == "source") return Role::source;
  if (name == "unknown" || name.empty()) return Role::unknown;
  return std::nullopt;
}

const char* photo_source_name(PhotoSource p) {
  switch (p) {
    case PhotoSource::automatic: return "auto";
    case PhotoSource::raw: return "raw";
    case PhotoSource::developed: return "developed";
  }
  return "auto";
}

Expected<PhotoSource> parse_photo_source(const std::string& name) {
  for (PhotoSource p : {PhotoSource::automatic, PhotoSource::raw, PhotoSource::developed}) {
    if (name == photo_source_name(p)) return p;
  }
  return make_error("photo source \"" + name.substr(0, 32) + "\" is not auto, raw or developed");
}

Status ReadOptions::check() const { return raw.check(); }

Expected<Manifest> parse_manifest(const std::string& text, const fs::path& folder) {
  const std::string name = (folder / "set.json").string();
  try {
    json root = json::parse(text);
    auto manifest = parse_manifest_json(root, folder);
    if (!manifest) return make_error(name + ": " + manifest.message());
    return manifest;
  } catch (const json::exception& e) {
    // e.what() reads "[json.exception.parse_error.101] parse error at line 1, ...".
    std::string what = e.what();
    if (auto close = what.find("] "); close != std::string::npos) what = what.substr(close + 2);
    return make_error(name + ": malformed JSON: " + what.substr(0, 200));
  }
}

std::string manifest_json(const ImageSet& set) {
  // ordered_json keeps the fields in DESIGN.md's order, for people reading set.json.
  nlohmann::ordered_json root;
  root["format"] = kSetFormat;
  root["id"] = set.id;
  root["role"] = role_name(set.role);
  root["object"] = set.object;
  root["created"] = set.created;
  root["size"] = {set.size.width, set.size.height};
  nlohmann::ordered_json camera;
  camera["model"] = set.camera.model;
  camera["exposure_s"] = set.camera.exposure_s;
  camera["aperture"] = set.camera.aperture;
  camera["iso"] = set.camera.iso;
  if (set.camera.focal_px > 0) {
    camera["focal_px"] = set.camera.focal_px;
    camera["cx"] = set.camera.cx;
    camera["cy"] = set.camera.cy;
  }
  root["camera"] = camera;
  nlohmann::ordered_json lights = nlohmann::ordered_json::array(), images = nlohmann::ordered_json::array();
  for (const Light& l : set.lights) {
    nlohmann::ordered_json jl;
    jl["index"] = l.index;
    jl["lamp_id"] = l.lamp_id;
    if (l.position_m) jl["position_m"] = {(*l.position_m)[0], (*l.position_m)[1], (*l.position_m)[2]};
    jl["direction"] = {l.direction[0], l.direction[1], l.direction[2]};
    jl["intensity"] = {l.intensity[0], l.intensity[1], l.intensity[2]};
    lights.push_back(jl);
    nlohmann::ordered_json image;
    image["light"] = l.index;
    const ImageSet::RawFile* camera = developed_file(set, static_cast<size_t>(l.index));
    image["file"] = camera ? light_file_name(l.index, camera->extension) : light_file_name(l.index);
    if (static_cast<size_t>(l.index) < set.raw.size() && !set.raw[static_cast<size_t>(l.index)].bytes.empty())
      image["raw"] = raw_file_name(l.index, set.raw[static_cast<size_t>(l.index)].extension);
    images.push_back(image);
  }
  root["lights"] = lights;
  root["images"] = images;
  if (set.ambient.empty()) {
    root["ambient"] = nullptr;
  } else {
    root["ambient"] = "ambient." + (set.ambient_developed.bytes.empty() ? std::string("png") : set.ambient_developed.extension);
  }
  if (!set.ambient.empty() && !set.ambient_raw.bytes.empty())
    root["ambient_raw"] = "ambient." + set.ambient_raw.extension;
  if (!set.mask.empty()) root["mask"] = "mask.png";
  if (!set.warnings.empty()) root["warnings"] = set.warnings;
  if (!set.scene.empty()) root["scene"] = set.scene;
  if (set.preview_of)
    root["preview_of"] = {{"id", set.preview_of->id}, {"size", {set.preview_of->size.width, set.preview_of->size.height}}};
  // Non-finite numbers cannot be written as JSON; validate() keeps them out.
  return compact_arrays(root.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace)) + "\n";
}

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
    if (im.type() != CV_32FC3) return make_error("image " + std::to_string(i) + ": expected CV_32FC3 (linear BGR)");
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
  if (Status s = check(set.ambient, CV_32FC3, "ambient", "CV_32FC3"); !s) return s;
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
    } else {
      format = SetFormat::thesis;
    }
  }
  Expected<ImageSet> set = make_error("unknown set format");
  switch (format) {
    case SetFormat::veneer: set = read_veneer(folder, options, progress); break;
    case SetFormat::diligent: set = read_diligent(folder, progress); break;
    case SetFormat::thesis: set = read_thesis(folder, progress); break;
    case SetFormat::automatic: break;
  }
  if (!set) return set;
  if (!options.load_photos && format == SetFormat::veneer) return set;  // no pixels to check
  // A last check of the invariants every reader promises.
  if (Status s = validate(*set); !s) return make_error(folder.string() + ": " + s.message());
  return set;
}

Status write_set(const ImageSet& set_in, const fs::path& folder_in, bool overwrite) {
  fs::path folder = folder_in;
  if (!folder.has_filename()) folder = folder.parent_path();  // "out/" -> "out"
  if (folder.empty()) return make_error("write_set: empty folder name");
  if (Status s = validate(set_in); !s) return make_error(folder.string() + ": cannot write set: " + s.message());
  std::error_code ec;
  const bool exists = fs::exists(fs::symlink_status(folder, ec));
  if (exists && !overwrite) return make_error(folder.string() + ": already exists (not overwriting it)");
  fs::path parent = folder.parent_path().empty() ? fs::path(".") : folder.parent_path();
  fs::create_directories(parent, ec);
  if (ec) return make_error(parent.string() + ": cannot create folder: " + ec.message());
  clean_stale_temps(folder);

  ImageSet set = set_in;  // shallow: cv::Mat shares pixels
  if (set.created.empty()) set.created = utc_now();
  if (set.id.empty()) set.id = folder.filename().string();

  fs::path tmp = io_detail::temp_sibling(folder);
  if (!fs::create_directory(tmp, ec)) return make_error(tmp.string() + ": cannot create temporary folder: " + ec.message());
  FolderGuard guard{tmp};
  if (Status s = write_contents(set, tmp); !s) return s;

  if (!exists) {
    // RENAME_NOREPLACE: a folder that appeared meanwhile is never replaced.
    if (::renameat2(AT_FDCWD, tmp.c_str(), AT_FDCWD, folder.c_str(), RENAME_NOREPLACE) != 0) {
      int err = errno;
      if (err == EEXIST) return make_error(folder.string() + ": already exists (not overwriting it)");
      if (err != EINVAL && err != ENOSYS) return make_error(folder.string() + ": cannot rename set into place: " + std::strerror(err));
      if (::rename(tmp.c_str(), folder.c_str()) != 0)
        return make_error(folder.string() + ": cannot rename set into place: " + std::strerror(errno));
    }
    guard.path.clear();
  } else {
    // Swap the new folder with the old one in one step, then drop the old.
    if (::renameat2(AT_FDCWD, tmp.c_str(), AT_FDCWD, folder.c_str(), RENAME_EXCHANGE) != 0) {
      int err = errno;
      if (err != EINVAL && err != ENOSYS) return make_error(folder.string() + ": cannot swap the new set into place: " + std::strerror(err));
      fs::path old = io_detail::temp_sibling(folder, "old");
      if (::rename(folder.c_str(), old.c_str()) != 0)
        return make_error(folder.string() + ": cannot move the old set aside: " + std::strerror(errno));
      if (::rename(tmp.c_str(), folder.c_str()) != 0) {
        int err2 = errno;
        (void)::rename(old.c_str(), folder.c_str());
        return make_error(folder.string() + ": cannot rename set into place: " + std::strerror(err2));
      }
      guard.path = old;
    }
    // guard.path now holds the old set (tmp after the exchange) and removes it.
  }
  return io_detail::fsync_dir(parent);
}

}  // namespace veneer
