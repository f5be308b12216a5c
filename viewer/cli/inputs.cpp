#include "inputs.hpp"

#include "veneer/match/map_file.hpp"

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

}  // namespace veneer::cli
