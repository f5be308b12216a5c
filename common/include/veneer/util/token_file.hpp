#pragma once
// The rig's access token file (`<store>/token`, a client's --token-file):
// one line, whitespace around it not part of the token (as the server trims
// what a client sends). Read by the rig and by its clients alike.
#include <filesystem>
#include <string>

#include "veneer/util/expected.hpp"

namespace veneer {

// The token, or an error naming the file: unreadable, or empty.
Expected<std::string> read_token_file(const std::filesystem::path& file);

}  // namespace veneer
