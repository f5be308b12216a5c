// Fuzz target: the Hue bridge emulator's HTTP/1.1 request parser and request
// handler (what a socket feeds it), plus the lamps backend's parser of the
// bridge's JSON answers. The first byte picks the chunk size the bytes arrive in.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "veneerd/sim/hue_emulator.hpp"
#include "veneerd/hw/hue_lamps.hpp"
#include "veneerd/sim/http_request.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static veneerd::HueBridgeEmulator* bridge = [] {
    veneerd::HueEmulatorOptions o;
    o.apply_delay_ms = 0;
    o.enforce_limits = false;
    return new veneerd::HueBridgeEmulator(o);  // never started: handle() needs no socket
  }();
  if (size == 0) return 0;
  std::size_t chunk = 1 + data[0] % 64;
  std::string_view bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  veneerd::HttpRequestParser parser;
  for (std::size_t pos = 0; pos < bytes.size(); pos += chunk) {
    auto state = parser.feed(bytes.substr(pos, chunk));
    while (state == veneerd::HttpRequestParser::State::complete) {
      veneerd::HttpRequest request = parser.take();
      veneerd::HttpResponse response = bridge->handle(request);
      (void)response.serialize(request.keep_alive());
      (void)veneerd::hw::parse_hue_results(response.body);
      state = parser.state();
    }
    if (state == veneerd::HttpRequestParser::State::error) break;
  }
  (void)veneerd::hw::parse_hue_results(std::string(bytes));
  return 0;
}
