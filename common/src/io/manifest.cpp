// The veneer-set/1 manifest (set.json): parsed and checked without touching
// the disk, and written in DESIGN.md's field order.
#include <cmath>
#include <cstdio>
#include <map>
#include <set>

#include <nlohmann/json.hpp>

#include "set_detail.hpp"
#include "veneer/io/imageset.hpp"

namespace veneer::io {
namespace fs = std::filesystem;
using nlohmann::json;
using namespace detail;

namespace {

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

}  // namespace veneer::io
