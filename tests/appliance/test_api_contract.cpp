// proto/README.md's limits table says the numbers the code uses: every row
// names its constant, and each constant's value must appear in its row.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>
// GCC 12 warns inside <regex> (std::function members "may be used
// uninitialized") when ASan's instrumentation meets -O3: a false positive in
// the library header, which -Werror would turn into a failed `make asan`.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <regex>
#pragma GCC diagnostic pop
#include <sstream>

#include "veneer/proto/framing.hpp"
#include "veneerd/api.hpp"
#include "veneerd/auth_throttle.hpp"
#include "veneerd/server.hpp"
#include "veneerd/store.hpp"

namespace {

std::vector<std::string> cells(const std::string& row) {
  std::vector<std::string> out;
  std::string cell;
  std::istringstream in(row.substr(1));
  while (std::getline(in, cell, '|')) out.push_back(cell);
  return out;
}

size_t longest_set_id() {
  size_t n = 1;
  while (veneerd::valid_set_id(std::string(n + 1, 'a'))) ++n;
  return n;
}

}  // namespace

TEST(ApiContract, LimitsTableMatchesTheCode) {
  namespace api = veneerd::api;
  const veneerd::ServerOptions server;
  const veneerd::AuthThrottleOptions auth;
  const std::map<std::string, double> code = {
      {"veneer::wire::kMaxMessageBytes", static_cast<double>(veneer::wire::kMaxMessageBytes)},
      {"veneer::wire::kProtocolVersion", veneer::wire::kProtocolVersion},
      {"veneer::wire::kDefaultPort", veneer::wire::kDefaultPort},
      {"ServerOptions::hello_timeout_s", server.hello_timeout_s},
      {"ServerOptions::max_queue_bytes", static_cast<double>(server.max_queue_bytes)},
      {"ServerOptions::live_queue_bytes", static_cast<double>(server.live_queue_bytes)},
      {"ServerOptions::fetch_queue_bytes", static_cast<double>(server.fetch_queue_bytes)},
      {"AuthThrottleOptions::free_failures", auth.free_failures},
      {"AuthThrottleOptions::first_delay_s", auth.first_delay_s},
      {"AuthThrottleOptions::max_delay_s", auth.max_delay_s},
      {"AuthThrottleOptions::max_waiting", auth.max_waiting},
      {"AuthThrottleOptions::burst_gap_s", auth.burst_gap_s},
      {"AuthThrottleOptions::summary_every_s", auth.summary_every_s},
      {"veneerd::api::kMaxTokenBytes", static_cast<double>(api::kMaxTokenBytes)},
      {"veneerd::api::kMaxClientNameChars", static_cast<double>(api::kMaxClientNameChars)},
      {"veneerd::api::kMinChunkBytes", static_cast<double>(api::kMinChunkBytes)},
      {"veneerd::api::kMaxChunkBytes", static_cast<double>(api::kMaxChunkBytes)},
      {"veneerd::api::kDefaultChunkBytes", static_cast<double>(api::kDefaultChunkBytes)},
      {"veneerd::api::kMaxSkipFiles", static_cast<double>(api::kMaxSkipFiles)},
      {"veneerd::api::kMaxSkipFileChars", static_cast<double>(api::kMaxSkipFileChars)},
      {"veneerd::api::kMinLiveFps", api::kMinLiveFps},
      {"veneerd::api::kMaxLiveFps", api::kMaxLiveFps},
      {"veneerd::api::kDefaultLiveFps", api::kDefaultLiveFps},
      {"veneerd::valid_set_id", static_cast<double>(longest_set_id())},
      {"veneerd::api::kMaxObjectChars", static_cast<double>(api::kMaxObjectChars)},
      {"veneerd::api::kMaxShutterS", api::kMaxShutterS},
      {"veneerd::api::kMaxAperture", api::kMaxAperture},
      {"veneerd::api::kMaxIso", api::kMaxIso},
      {"veneerd::api::kMaxLampsInRequest", api::kMaxLampsInRequest},
      {"veneerd::api::kMaxBrightness", api::kMaxBrightness},
      {"veneerd::api::kMaxHandLampDistanceM", api::kMaxHandLampDistanceM},
      {"veneerd::api::kMinHandLampDistanceM", api::kMinHandLampDistanceM},
  };
  std::ifstream in(VENEER_SOURCE_DIR "/proto/README.md");
  ASSERT_TRUE(in) << "proto/README.md missing";
  std::string line;
  bool in_limits = false;
  std::map<std::string, std::string> rows;  // constant -> value cell
  while (std::getline(in, line)) {
    if (line.rfind("## ", 0) == 0) in_limits = line == "## Limits";
    if (!in_limits || line.rfind("| ", 0) != 0 || line.rfind("| limit ", 0) == 0) continue;
    auto c = cells(line);
    ASSERT_GE(c.size(), 4u) << line;
    std::smatch m;
    ASSERT_TRUE(std::regex_search(c[2], m, std::regex("`([^`]+)`"))) << "no constant named in: " << line;
    rows[m[1]] = c[1];
  }
  for (const auto& [name, value] : code) {
    auto row = rows.find(name);
    ASSERT_NE(row, rows.end()) << name << " is not in proto/README.md's limits table";
    bool found = false;
    const std::regex number("[0-9]+(\\.[0-9]+)?");
    for (auto it = std::sregex_iterator(row->second.begin(), row->second.end(), number); it != std::sregex_iterator();
         ++it) {
      if (std::abs(std::stod(it->str()) - value) <= 1e-9 * std::max(1.0, std::abs(value))) found = true;
    }
    EXPECT_TRUE(found) << "proto/README.md says '" << row->second << "' for " << name << ", the code " << value;
  }
  for (const auto& [name, value] : rows) {
    EXPECT_TRUE(code.count(name)) << "the README's limit " << name << " is not checked against the code here";
  }
}
