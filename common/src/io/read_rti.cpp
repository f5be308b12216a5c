// The RTI community's capture folder, as RTIBuilder and Relight read it: the
// photos and one light-position file (*.lp):
//
//   N                                   the number of photos, on the first line
//   <file> <x> <y> <z>                  N lines: a photo and its light direction
//
// Relight (src/lp.cpp parses it; src/sphere.cpp writes the directions it finds
// on the reflective spheres) and RTIBuilder use the rig frame's axes: x to the
// right, y up (Relight flips the image's downward y when it writes one), z out
// of the picture toward the camera, the vector pointing from the object
// toward the lamp. So the directions are used as they are, normalised
// (RTIBuilder writes unit vectors; Relight does not promise it).
//
// <file> is often a path on the machine that made the file (RTIBuilder
// writes absolute Windows paths into assembly-files/*.lp, with the photos in
// jpeg-exports/): a photo is looked for under its name inside the set folder,
// then by its base name beside the .lp, in the set folder and in
// jpeg-exports/. The photos are developed pictures: 8-bit JPEG, PNG and TIFF
// files are sRGB and linearised; 16-bit ones are linear; RAW files go
// through LibRaw. A mask.png beside the photos is used as the object mask.
#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

#include "set_detail.hpp"
#include "veneer/io/image_io.hpp"

namespace veneer::io::detail {
namespace fs = std::filesystem;

namespace {

// The part after the last '/' or '\' (a Windows path read on Linux is one name).
std::string base_name(const std::string& path) {
  const size_t slash = path.find_last_of("/\\");
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

std::vector<fs::path> lp_files_in(const fs::path& folder) {
  std::vector<fs::path> found;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    if (!entry.is_regular_file(ec)) continue;
    std::string ext = entry.path().extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
    if (ext == ".lp") found.push_back(entry.path());
  }
  std::sort(found.begin(), found.end());
  return found;
}

// Where a photo named in the .lp is (see the top of the file); empty if nowhere.
fs::path locate_photo(const fs::path& folder, const fs::path& lp_dir, const std::string& name) {
  std::error_code ec;
  if (file_name_problem(name).empty() && name.find('\\') == std::string::npos) {
    if (fs::path f = folder / name; fs::is_regular_file(f, ec)) return f;
  }
  const std::string base = base_name(name);
  if (!file_name_problem(base).empty()) return {};
  for (const fs::path& dir : {lp_dir, folder, folder / "jpeg-exports"}) {
    if (fs::path f = dir / base; fs::is_regular_file(f, ec)) return f;
  }
  return {};
}

}  // namespace

Expected<fs::path> find_lp_file(const fs::path& folder) {
  for (const fs::path& dir : {folder, folder / "assembly-files"}) {
    std::vector<fs::path> lps = lp_files_in(dir);
    if (lps.size() == 1) return lps.front();
    if (lps.size() > 1) {
      std::string names;
      for (const auto& p : lps) names += (names.empty() ? "" : ", ") + p.filename().string();
      return make_error(dir.string() + ": holds " + std::to_string(lps.size()) + " RTI light files (" + names +
                        "); keep the one that belongs to the photos");
    }
  }
  return fs::path();
}

Expected<ImageSet> read_rti(const fs::path& folder, const ReadOptions& options, const Progress& progress) {
  auto lp = find_lp_file(folder);
  if (!lp) return lp.error();
  if (lp->empty()) return make_error(folder.string() + ": no RTI light file (*.lp) in the folder or its assembly-files/");
  const fs::path& lp_file = *lp;
  ImageSet set;
  set.origin = folder;
  set.id = set.object = folder_name(folder);

  // No comments: a '#' is a legal character of a file name here.
  auto read = read_lines(lp_file, false);
  if (!read) return read.error();
  const std::vector<Line>& lines = *read;
  if (lines.empty()) return make_error(lp_file.string() + ": empty light file");
  std::vector<double> count;
  if (!parse_numbers(lines[0].text, count) || count.size() != 1 || count[0] != std::floor(count[0]) || count[0] < 1 ||
      count[0] > static_cast<double>(kMaxLights))
    return make_error(lp_file.string() + " line " + std::to_string(lines[0].number) +
                      ": expected the number of photos (1.." + std::to_string(kMaxLights) + "), got \"" +
                      lines[0].text.substr(0, 80) + "\"");
  const size_t n = static_cast<size_t>(count[0]);
  if (lines.size() - 1 != n)
    return make_error(lp_file.string() + ": says " + std::to_string(n) + " photos on its first line but lists " +
                      std::to_string(lines.size() - 1));

  std::vector<fs::path> files;
  std::set<fs::path> seen;
  bool normalised = false;
  for (size_t i = 1; i < lines.size(); ++i) {
    const Line& line = lines[i];
    const std::string where = lp_file.string() + " line " + std::to_string(line.number);
    // The last three fields are the direction; everything before is the file
    // (a Windows path may hold spaces).
    std::string text = line.text;
    std::vector<std::string> fields;
    for (int k = 0; k < 3; ++k) {
      const auto end = text.find_last_not_of(" \t");
      const auto space = end == std::string::npos ? std::string::npos : text.find_last_of(" \t", end);
      if (space == std::string::npos) break;
      fields.insert(fields.begin(), text.substr(space + 1, end - space));
      text.erase(space);
    }
    const auto name_end = text.find_last_not_of(" \t");
    std::vector<double> v;
    if (fields.size() != 3 || name_end == std::string::npos || !parse_numbers(fields[0] + " " + fields[1] + " " + fields[2], v))
      return make_error(where + ": expected \"<file> <x> <y> <z>\", got \"" + line.text.substr(0, 80) + "\"");
    const std::string name = text.substr(0, name_end + 1);
    cv::Vec3d d(v[0], v[1], v[2]);
    const double len = cv::norm(d);
    if (!finite3(d) || len < 1e-4) return make_error(where + ": light direction " + fmt_vec(d) + " is zero or not finite");
    if (std::abs(len - 1.0) > 1e-3) normalised = true;
    Light light;
    light.index = static_cast<int>(i - 1);
    light.direction = d / len;
    fs::path file = locate_photo(folder, lp_file.parent_path(), name);
    if (file.empty())
      return make_error(where + ": photo \"" + name.substr(0, 120) + "\" not found (looked for \"" + base_name(name) +
                        "\" beside the .lp, in the set folder and in jpeg-exports/)");
    if (!seen.insert(file).second) return make_error(where + ": photo \"" + file.filename().string() + "\" is listed twice");
    light.lamp_id = file.stem().string();
    set.lights.push_back(light);
    files.push_back(file);
  }
  if (normalised) set.warnings.push_back(lp_file.filename().string() + ": light directions were not unit vectors; normalised");
  if (Status s = load_photos(files, true, options, progress, set); !s) return s.error();
  std::error_code ec;
  if (fs::path f = folder / "mask.png"; fs::exists(f, ec)) {
    auto m = read_mask(f);
    if (!m) return m.error();
    if (Status s = check_size(f, *m, set.size, "the photos' size"); !s) return s.error();
    set.mask = std::move(m).value();
  }
  set.photos_read += "; lights from " + fs::relative(lp_file, folder, ec).string();
  return set;
}

}  // namespace veneer::io::detail
