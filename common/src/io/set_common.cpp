// Helpers the set readers share (set_detail.hpp): checks, the parallel photo
// decoder, the text-list parser.
#include <algorithm>
#include <atomic>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <sstream>

#include <tbb/parallel_for.h>

#include "file_util.hpp"
#include "set_detail.hpp"
#include "veneer/io/image_io.hpp"

namespace veneer::io::detail {
namespace fs = std::filesystem;

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

std::string light_file_name(int index, const std::string& extension) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "light_%02d.", index);
  return buf + extension;
}

const ImageSet::RawFile* developed_file(const ImageSet& set, size_t k) {
  return k < set.developed.size() && !set.developed[k].bytes.empty() ? &set.developed[k] : nullptr;
}

std::string raw_file_name(int index, const std::string& extension) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "light_%02d.", index);
  return buf + extension;
}

std::string folder_name(const fs::path& folder) {
  fs::path f = folder;
  if (!f.has_filename()) f = f.parent_path();
  return f.filename().string();
}

// --- loading pixels ------------------------------------------------------------

Status for_each_parallel(size_t n, const Progress& progress, const std::string& stage,
                         const std::function<Status(size_t)>& job) {
  std::vector<std::string> errors(n);
  std::atomic<size_t> done{0};
  std::mutex report_lock;
  progress.report(0.0, stage);
  tbb::parallel_for(size_t(0), n, [&](size_t i) {
    if (progress.cancelled()) {
      errors[i] = "cancelled";
      return;
    }
    if (Status s = job(i); !s) {
      errors[i] = s.message();
      return;
    }
    const size_t finished = ++done;
    if (progress.on_progress) {
      std::lock_guard<std::mutex> lock(report_lock);
      progress.report(static_cast<double>(finished) / static_cast<double>(n), stage);
    }
  });
  for (const auto& e : errors) {
    if (!e.empty()) return make_error(e);
  }
  return Status::success();
}

Status decode_frames(const std::vector<Frame>& frames, const RawOptions& raw_options, bool half,
                     const Progress& progress, const std::string& stage, std::vector<cv::Mat>& out,
                     std::vector<PhotoKind>* kinds) {
  out.assign(frames.size(), cv::Mat());
  if (kinds) kinds->assign(frames.size(), PhotoKind{});
  return for_each_parallel(frames.size(), progress, stage, [&](size_t i) -> Status {
    const Frame& f = frames[i];
    auto mapped = detail::MappedFile::open(f.file);  // read in place: no copy, no fresh pages
    if (!mapped) return mapped.error();
    PhotoKind kind;
    Expected<cv::Mat> image = decode_photo(mapped->bytes(), f, raw_options, half, kind);
    if (!image) return image.error();
    out[i] = std::move(image).value();
    if (kinds) (*kinds)[i] = kind;
    return Status::success();
  });
}

void note_photo_kinds(ImageSet& set, const std::vector<PhotoKind>& kinds, bool srgb8, const RawOptions& raw_options) {
  if (kinds.empty()) return;
  PhotoKind first = kinds.front();
  set.photos_from = first.kind;
  for (const auto& k : kinds) {
    if (k.kind != first.kind) set.photos_from = "mixed";
    if (k.kind != first.kind || k.bits != first.bits) first = {"mixed", 0};
  }
  set.photos_read = std::to_string(kinds.size()) + " files: " + describe_photos(first, srgb8, raw_options);
}

void settle_camera_space(ImageSet& set, const std::vector<PhotoKind>& kinds) {
  set.camera_to_srgb = cv::Matx33f::eye();
  if (kinds.empty()) return;
  const cv::Matx33f first = kinds.front().camera_to_srgb;
  bool same = true;
  for (const auto& k : kinds) same = same && cv::norm(k.camera_to_srgb - first, cv::NORM_INF) <= 1e-6;
  if (same) {
    set.camera_to_srgb = first;
    return;
  }
  tbb::parallel_for(size_t(0), kinds.size(), [&](size_t i) {
    cv::Mat& m = i < set.images.size() ? set.images[i] : set.ambient;
    apply_colour_matrix(m, kinds[i].camera_to_srgb);
  });
}

}  // namespace veneer::io::detail

namespace veneer::io {

void to_colour_managed(ImageSet& set) {
  if (is_identity(set.camera_to_srgb)) return;
  const size_t n = set.images.size() + (set.ambient.empty() ? 0 : 1);
  tbb::parallel_for(size_t(0), n, [&](size_t i) {
    apply_colour_matrix(i < set.images.size() ? set.images[i] : set.ambient, set.camera_to_srgb);
  });
  set.camera_to_srgb = cv::Matx33f::eye();
}

}  // namespace veneer::io

namespace veneer::io::detail {

Expected<bool> all_raw_by_name(const std::vector<fs::path>& files) {
  size_t raw = 0;
  for (const auto& f : files) raw += is_raw_file_name(f.filename().string()) ? 1 : 0;
  if (raw != 0 && raw != files.size())
    return make_error(std::to_string(raw) + " of the " + std::to_string(files.size()) +
                      " photos are camera RAW files and the others are not; a set's photos must be of one kind");
  return raw != 0;
}

Status check_size(const fs::path& file, const cv::Mat& image, cv::Size expected, const std::string& why) {
  if (image.size() != expected)
    return make_error(file.string() + ": image is " + size_text(image.size()) + " but " + why + " is " +
                      size_text(expected));
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

fs::path find_with_ext(const fs::path& folder, const std::string& stem, std::initializer_list<const char*> exts) {
  std::error_code ec;
  for (const char* ext : exts) {
    fs::path f = folder / (stem + ext);
    if (fs::is_regular_file(f, ec)) return f;
  }
  return {};
}

// --- text lists (DiLiGenT, thesis) -----------------------------------------------

Expected<std::vector<Line>> read_lines(const fs::path& file, bool comments) {
  auto bytes = read_file_bytes(file);
  if (!bytes) return bytes.error();
  if (bytes->find('\0') != std::string::npos) return make_error(file.string() + ": not a text file");
  std::vector<Line> lines;
  std::stringstream ss(*bytes);
  std::string line;
  int number = 0;
  while (std::getline(ss, line)) {
    ++number;
    if (auto hash = line.find('#'); comments && hash != std::string::npos) line.erase(hash);
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

}  // namespace veneer::io::detail
