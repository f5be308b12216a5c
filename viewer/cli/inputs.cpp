#include "inputs.hpp"

#include <cstdio>

#include <opencv2/imgproc.hpp>

#include "veneer/io/image_io.hpp"
#include "veneer/match/map_file.hpp"
#include "veneer/repaint/web_export.hpp"

namespace veneer::cli {

std::filesystem::path map_file(const std::string& map) {
  std::filesystem::path file = map;
  if (std::filesystem::is_directory(file)) file /= "map.pfm";
  return file;
}

Expected<MapInputs> read_map_inputs(const std::string& dst, const std::string& src, const std::string& map) {
  auto d = io::read_set(dst);
  if (!d) return d.error();
  auto s = io::read_set(src);
  if (!s) return s.error();
  auto m = match::read_map(map_file(map));
  if (!m) return m.error();
  return MapInputs{std::move(d).value(), std::move(s).value(), std::move(m).value()};
}

void add_map_inputs(CLI::App* cmd, std::string& dst, std::string& src, std::string& map, bool required) {
  for (CLI::Option* o : {cmd->add_option("--dst", dst, "destination image set"),
                         cmd->add_option("--src", src, "source image set"),
                         cmd->add_option("--map", map, "transfer output folder (or its map.pfm)")})
    o->required(required);
}

Expected<std::vector<cv::Mat>> read_result_photos(const std::filesystem::path& folder, size_t lamps, int max_side) {
  std::vector<cv::Mat> photos;
  for (size_t i = 0; i < lamps; ++i) {
    char name[48];
    std::snprintf(name, sizeof name, "result_light_%02zu.png", i);
    auto photo = io::read_linear_image(folder / name);
    if (!photo) return photo.error();
    const cv::Size to = repaint::web_size(photo->size(), max_side);
    if (to == photo->size()) {
      photos.push_back(std::move(photo).value());
    } else {
      cv::Mat small;
      cv::resize(*photo, small, to, 0, 0, cv::INTER_AREA);
      photos.push_back(small);
    }
  }
  return photos;
}

}  // namespace veneer::cli
