// map.pfm in and out (map_file.hpp).
#include "veneer/match/map_file.hpp"

#include <vector>

namespace veneer::match {

Status write_map(const std::filesystem::path& file, const Map& map, io::Sync sync) {
  std::vector<cv::Mat> channels;
  cv::split(map.xy, channels);
  channels.push_back(map.distance);
  cv::Mat xyd;
  cv::merge(channels, xyd);
  return io::write_pfm(file, xyd, true, sync);
}

Expected<Map> read_map(const std::filesystem::path& file) {
  auto m = io::read_pfm(file, true);
  if (!m) return m.error();
  if (m->type() != CV_32FC3) return make_error(file.string() + ": a map has 3 channels (x, y, distance)");
  std::vector<cv::Mat> ch;
  cv::split(*m, ch);
  Map map;
  cv::merge(std::vector<cv::Mat>{ch[0], ch[1]}, map.xy);
  map.distance = ch[2];
  return map;
}

}  // namespace veneer::match
