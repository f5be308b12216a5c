#pragma once
// The ring of lamps. Implementations: "hue" (a Hue bridge over its v1 REST API
// with libcurl; the simulated rig points it at the bridge emulator) — the only
// one the daemon needs, since the simulated rig exercises the same HTTP path.
//
// The lamps are shared with their owner: the Hue app, a wall switch, a scene
// or a motion sensor may switch or colour any of them at any time, before or
// during a set. So nothing here trusts a record of what was last commanded:
// every decision starts from a reading of the bridge, and ensure() proves the
// result by reading it back.
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "veneer/util/expected.hpp"

namespace veneerd {

// Which of the colour settings a lamp shows (Hue "colormode").
enum class ColourMode { xy, ct, hs };
const char* colour_mode_name(ColourMode mode);

struct LampState {
  bool on = false;
  int brightness = 254;          // 1..254 (Hue "bri")
  ColourMode mode = ColourMode::xy;
  double x = 0.3227, y = 0.329;  // CIE xy (mode xy; the bridge reports it for every mode)
  int ct = 366;                  // colour temperature [mired] 153..500 (mode ct)
  int hue = 8418;                // 0..65535 (mode hs)
  int sat = 140;                 // 0..254 (mode hs)
  bool reachable = true;
  bool has_xy = true;            // false: a white lamp (colour temperature or dimming only)
  bool has_ct = true;            // false: a dimmable white lamp, or a colour lamp without ct
};

// The rig's own light: full white, xy mode (ct 167 mired on a lamp without xy).
LampState rig_white(int brightness = 254);
// Same brightness and colour in the lamp's mode (xy within 0.01, ct within 5
// mired, hue within 500 and sat within 5: what bridges' rounding leaves).
bool same_colour(const LampState& a, const LampState& b);
// What a photo would see: both off, or both on with the same brightness and colour.
bool same_light(const LampState& a, const LampState& b);
// "on, bri 200, ct 370 mired" / "off" / "unreachable, off".
std::string describe(const LampState& s);
// {"on", "bri", "colormode", "xy", "ct", "hue", "sat", "reachable"}, the Hue
// bridge's own spelling; from_json accepts what to_json writes.
nlohmann::json to_json(const LampState& s);
veneer::Expected<LampState> lamp_state_from_json(const nlohmann::json& j);

class Lamps {
 public:
  virtual ~Lamps() = default;
  virtual std::string name() const = 0;
  // Number of ring positions (lamps fitted), in the rig's light order.
  virtual int count() const = 0;
  // "lamp 3 (Hue id 5)": how errors and logs name ring position i.
  virtual std::string label(int i) const { return "lamp " + std::to_string(i + 1); }
  // Reads every lamp's state as the bridge reports it now.
  virtual veneer::Expected<std::vector<LampState>> read() = 0;
  // Takes the lamps from `now` (a reading just taken) to `want`: commands each
  // lamp whose state differs and returns once the bridge acknowledged and the
  // settle time passed. A lamp to be switched off that shows another colour
  // than want's is given want's brightness and colour first (a lamp that is
  // off cannot take them), so it comes back as its owner left it.
  virtual veneer::Status command(const std::vector<LampState>& now, const std::vector<LampState>& want) = 0;
  // How long a bridge may take to show a commanded change in its readings
  // before the difference counts as another client's doing [ms].
  virtual int confirm_ms() const { return 1000; }

  // Brings the lamps to `want` and proves it: commands what differs from a
  // fresh reading (or from `now`, when the caller has just read), reads back,
  // and repeats while the bridge still shows a difference (another client
  // switching a lamp), `attempts` times in all. Returns the reading that
  // matched; an error names each lamp that still differs, or one unreachable.
  // Lamps that are on are compared with their colour (another app may
  // recolour a lit lamp); lamps that are off only by being off.
  veneer::Expected<std::vector<LampState>> ensure(const std::vector<LampState>& want,
                                                  std::optional<std::vector<LampState>> now = std::nullopt,
                                                  int attempts = 3);
  // Lamps on[i] at `brightness`, rig white; the others off. Proven as ensure().
  veneer::Status set(const std::vector<bool>& on, int brightness = 254);
  // The owner's states back (on/off, brightness, colour mode and values). Proven.
  veneer::Status restore(const std::vector<LampState>& states);
  veneer::Status all_off() { return set(std::vector<bool>(count(), false)); }

  // The lamps whose reading differs from `want` as a photo would see it
  // (unreachable lamps count as different); empty when all match.
  std::vector<int> differing(const std::vector<LampState>& reading, const std::vector<LampState>& want) const;
};

}  // namespace veneerd
