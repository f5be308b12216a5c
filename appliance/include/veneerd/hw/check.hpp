#pragma once
// `veneerd --check-hardware`: what the rig's hardware looks like from here —
// the camera (model and the exposure values it offers), the Hue bridge and its
// lamps, the GPIO chips and the configured lines — one line per finding, and
// a clear line for everything that is missing.
//
// validate_hardware_config(): the config sections the hardware back-ends read
// (camera, trigger, led and the shared "gpio" block), checked before anything
// is opened, so a bad config stops the daemon with one clear message.
#include <iosfwd>

#include <nlohmann/json.hpp>

#include "veneer/util/expected.hpp"

namespace veneerd {

// Returns 0 when everything the config requires was found, 1 otherwise.
int check_hardware(std::ostream& out, const nlohmann::json& config);

// The config document (the whole file); the error names the field.
veneer::Status validate_hardware_config(const nlohmann::json& config);

// One section: `kind` is "camera", "trigger" or "led". Sections whose backend
// is not a hardware one ("simulated", "none") pass.
veneer::Status validate_device_section(const std::string& kind, const nlohmann::json& section);

}  // namespace veneerd
