#pragma once
// What several `veneer` commands read the same way: a transfer's map, named
// by its folder or its map.pfm (eval, inspect, repaint), and the destination
// and source sets it was made for (eval, inspect).
#include <filesystem>
#include <string>

#include <CLI/CLI.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::cli {

// --map as given: a transfer's output folder (then its map.pfm) or the file.
std::filesystem::path map_file(const std::string& map);

struct MapInputs {
  io::ImageSet dst, src;
  match::Map map;
};
// The sets at `dst` and `src` and the map `map`; the first error as its reader says it.
Expected<MapInputs> read_map_inputs(const std::string& dst, const std::string& src, const std::string& map);
// --dst, --src and --map into those strings, required or not.
void add_map_inputs(CLI::App* cmd, std::string& dst, std::string& src, std::string& map, bool required);

// The repainted photos a transfer folder holds, result_light_00.png ...
// (linear 16-bit) for `lamps` lamps, as linear BGR CV_32FC3; each reduced to
// fit `max_side` px as it is read (repaint::web_size; 0 = full size).
Expected<std::vector<cv::Mat>> read_result_photos(const std::filesystem::path& folder, size_t lamps, int max_side = 0);

}  // namespace veneer::cli
