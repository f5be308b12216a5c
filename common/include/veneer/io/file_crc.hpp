#pragma once
// CRC-32 (the one of zlib, PNG and gzip: polynomial 0xEDB88320, reflected,
// initial and final XOR 0xFFFFFFFF) over the first bytes of a file. A resumed
// pull names the bytes it already holds of a file by their count and this
// CRC, so the rig continues the file only when they are the rig's own.
#include <cstdint>
#include <filesystem>
#include <string_view>

#include "veneer/util/expected.hpp"

namespace veneer::io {

uint32_t crc32(std::string_view bytes, uint32_t crc = 0);

// The CRC-32 of `length` bytes of `path` starting at `offset`; an error when
// the file cannot be read or is shorter.
Expected<uint32_t> file_crc32(const std::filesystem::path& path, uint64_t offset, uint64_t length);

}  // namespace veneer::io
