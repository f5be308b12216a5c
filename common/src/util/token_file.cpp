// The access token file (token_file.hpp).
#include "veneer/util/token_file.hpp"

#include <fstream>

namespace veneer {

Expected<std::string> read_token_file(const std::filesystem::path& file) {
  std::ifstream in(file);
  if (!in) return make_error(file.string() + ": cannot read the rig's access token");
  std::string token;
  std::getline(in, token);
  const char* space = " \t\r\n\v\f";
  const size_t first = token.find_first_not_of(space);
  token = first == std::string::npos ? std::string() : token.substr(first, token.find_last_not_of(space) - first + 1);
  if (token.empty()) return make_error(file.string() + ": the token file is empty");
  return token;
}

}  // namespace veneer
