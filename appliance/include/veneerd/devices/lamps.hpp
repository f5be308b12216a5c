#pragma once
// The ring of lamps. Implementations: "hue" (a Hue bridge over its v1 REST API
// with libcurl; the simulated rig points it at the bridge emulator) — the only
// one the daemon needs, since the simulated rig exercises the same HTTP path.
#include <string>
#include <vector>

#include "veneer/util/expected.hpp"

namespace veneerd {

struct LampState {
  bool on = false;
  int brightness = 254;        // 1..254 (Hue "bri")
  double x = 0.3227, y = 0.329;  // CIE xy colour (rig white by default)
  bool reachable = true;
};

class Lamps {
 public:
  virtual ~Lamps() = default;
  virtual std::string name() const = 0;
  // Number of ring positions (lamps fitted), in the rig's light order.
  virtual int count() const = 0;
  // Reads every lamp's state (to restore the owner's afterwards).
  virtual veneer::Expected<std::vector<LampState>> read() = 0;
  // Sets lamps: on[i] for ring position i, at `brightness`, rig white, no fade.
  // Returns once the bridge acknowledged and the settle time has passed.
  virtual veneer::Status set(const std::vector<bool>& on, int brightness = 254) = 0;
  // Restores saved states (owner's colours and levels).
  virtual veneer::Status restore(const std::vector<LampState>& states) = 0;
  virtual veneer::Status all_off() { return set(std::vector<bool>(count(), false)); }
};

}  // namespace veneerd
