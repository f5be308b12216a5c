// The layouts other tools write, read (never written): DiLiGenT and the
// thesis's PPM/PFM folders (imageset.hpp, SetFormat). Their photos may be
// of any kind decode_photo reads; 8-bit PNG/PPM/TIFF are linear here.
#include <algorithm>
#include <map>

#include "set_detail.hpp"
#include "veneer/io/image_io.hpp"

namespace veneer::io::detail {
namespace fs = std::filesystem;

namespace {

const char* kPhotoExtensions[] = {".ppm", ".pgm", ".pfm", ".png", ".jpg", ".jpeg", ".tif", ".tiff"};

bool is_photo_extension(std::string ext) {
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return std::any_of(std::begin(kPhotoExtensions), std::end(kPhotoExtensions), [&](const char* e) { return ext == e; }) ||
         is_raw_file_name("x" + ext);
}

}  // namespace

Status load_photos(const std::vector<fs::path>& files, bool srgb8, const ReadOptions& options, const Progress& progress,
                   ImageSet& set) {
  auto raw = all_raw_by_name(files);
  if (!raw) return make_error(set.origin.string() + ": " + raw.message());
  std::vector<Frame> frames;
  for (const auto& f : files) frames.push_back({f, *raw, srgb8});
  std::vector<PhotoKind> kinds;
  if (Status s = decode_frames(frames, options.raw, options.half_floats, progress, "reading " + set.id, set.images, &kinds);
      !s)
    return s;
  if (Status s = check_same_sizes(files, set.images); !s) return s;
  set.size = set.images[0].size();
  note_photo_kinds(set, kinds, srgb8, options.raw);
  settle_camera_space(set, kinds);
  return Status::success();
}

Expected<ImageSet> read_diligent(const fs::path& folder, const ReadOptions& options, const Progress& progress) {
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
  if (Status s = load_photos(files, false, options, progress, set); !s) return s.error();
  if (fs::path f = folder / "mask.png"; fs::exists(f, ec)) {
    auto m = read_mask(f);
    if (!m) return m.error();
    if (Status s = check_size(f, *m, set.size, "the images' size"); !s) return s.error();
    set.mask = std::move(m).value();
  }
  return set;
}


Expected<ImageSet> read_thesis(const fs::path& folder, const ReadOptions& options, const Progress& progress) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) return make_error(folder.string() + ": not a folder");
  const fs::path lights_file = folder / "lights.txt";
  if (!fs::exists(lights_file, ec))
    return make_error(folder.string() + ": not an image set (no set.json, filenames.txt, lights.txt or RTI .lp file)");
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
    if (!is_photo_extension(ext)) continue;
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
                      std::to_string(numbered.size()) + " numbered images (<N>.ppm, .pgm, .pfm, .png, .jpg, .tif or a RAW file)");
  std::vector<fs::path> files;
  for (auto& [n, p] : numbered) {
    set.lights[files.size()].lamp_id = p.stem().string();
    files.push_back(p);
  }
  if (Status s = load_photos(files, false, options, progress, set); !s) return s.error();
  const std::string why = "the images' size";
  if (fs::path f = find_with_ext(folder, "ambient", {".ppm", ".pgm", ".pfm", ".png"}); !f.empty()) {
    auto a = read_linear_image(f);
    if (!a) return a.error();
    if (Status s = check_size(f, *a, set.size, why); !s) return s.error();
    set.ambient = std::move(a).value();
    if (options.half_floats) set.ambient.convertTo(set.ambient, CV_16FC3);  // as the photos
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

}  // namespace veneer::io::detail
