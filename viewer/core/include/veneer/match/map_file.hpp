#pragma once
// The correspondence map's file (DESIGN.md: map.pfm).
#include <filesystem>

#include "veneer/io/image_io.hpp"
#include "veneer/match/matcher.hpp"
#include "veneer/util/expected.hpp"

namespace veneer::match {

// map.pfm (x, y, distance; -1 unmapped) in and out.
Status write_map(const std::filesystem::path& file, const Map& map, io::Sync sync = io::Sync::each);
Expected<Map> read_map(const std::filesystem::path& file);

}  // namespace veneer::match
