// The board image's example configs load with the daemon's parser and pass
// the hardware validation; the unit file has what systemd needs.
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "veneerd/config.hpp"
#include "veneerd/hw/check.hpp"

namespace veneerd {
namespace {

const std::string board = std::string(VENEER_SOURCE_DIR) + "/firmware/board/";

std::string read(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(Board, ExampleConfigsLoad) {
  for (const char* name : {"veneerd.example.json", "veneerd.uvc.example.json"}) {
    auto c = load_config(board + name);
    ASSERT_TRUE(c.ok()) << name << ": " << c.message();
    auto doc = nlohmann::json::parse(read(board + name));
    auto v = validate_hardware_config(doc);
    EXPECT_TRUE(v.ok()) << name << ": " << v.message();
    EXPECT_EQ(c->lamp_ids.size(), 7u) << name;
  }
}

TEST(Board, ServiceUnitIsNotifyWithWatchdog) {
  std::string unit = read(board + "veneerd.service");
  for (const char* line : {"Type=notify", "WatchdogSec=", "Restart=on-failure", "User=veneer"})
    EXPECT_NE(unit.find(line), std::string::npos) << line;
}

TEST(Board, UdevRulesCoverCameraAndGpio) {
  std::string rules = read(board + "60-veneer.rules");
  for (const char* v : {"04a9", "04b0", "054c", "gpiochip*", "GROUP=\"gpio\"", "GROUP=\"plugdev\""})
    EXPECT_NE(rules.find(v), std::string::npos) << v;
}

}  // namespace
}  // namespace veneerd
