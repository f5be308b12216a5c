// The fast engine's entry points (fast.hpp).
#include <chrono>

#include "index_fast.hpp"
#include "veneer/match/fast.hpp"

namespace veneer::match::fast {

bool supports(const MatchOptions& options) { return false; }

const char* default_index() { return "grid"; }

Expected<Map> compute_map(const ObjectView& destination, const ObjectView& source, const MatchOptions& options,
                          const Progress& progress) {
  return compute_map(destination, source, options, progress, nullptr);
}

Expected<Map> compute_map(const ObjectView& destination, const ObjectView& source, const MatchOptions& options,
                          const Progress& progress, Stats* stats) {
  return make_error(std::string("fast engine: method ") + method_name(options.method) + " is not served yet");
}

}  // namespace veneer::match::fast
