// Fuzz target: metrics.json text -> parse_transfer_options (what `veneer rig
// live --map` reads from a transfer folder; no files touched). Every refusal
// says why; options that parse pass their own check and come back equal from
// transfer_options_json.
#include <cstdint>
#include <cstdlib>
#include <string>

#include "veneer/pipeline/transfer.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  auto options = veneer::pipeline::parse_transfer_options(text, "/fuzz/metrics.json");
  if (!options) {
    if (options.message().empty()) std::abort();
    return 0;
  }
  if (!options->check()) std::abort();
  auto again = veneer::pipeline::parse_transfer_options(veneer::pipeline::transfer_options_json(*options), "again");
  if (!again || !(again->match == options->match) || again->scale != options->scale ||
      again->blend != options->blend || again->blend_guide != options->blend_guide ||
      again->truth_normals != options->truth_normals)
    std::abort();
  return 0;
}
