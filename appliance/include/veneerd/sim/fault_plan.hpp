#pragma once
// The fault plan of the simulated rig (issue 43): which faults the device
// twins, the set store and a soak's clients take, at random from a seed or on
// a schedule. `veneerd --simulate --faults SPEC` hands one plan to the Hue
// bridge emulator, the camera twin and the store; `veneer_soak` reads the
// client.* faults from the same SPEC.
//
//   SPEC  = ITEM { "," ITEM }                 e.g. "bridge.503=0.02,camera.gone=0.01,store.eio=0.01,seed=7"
//   ITEM  = FAULT "=" P      each opportunity of FAULT takes it with probability P (0..1)
//         | FAULT "@" N      the N-th opportunity (1-based) takes it (repeatable: "camera.gone@3,camera.gone@9")
//         | PARAM "=" VALUE  a fault's size (below)
//         | "seed=" N        the random draws' seed (default 1); each fault draws from its own stream
// or the same as one JSON object: {"bridge.503": 0.02, "camera.gone@": [3, 9], "seed": 7}.
//
// fault             opportunity               what happens
// bridge.429        a request to the bridge   answered 429 (Hue's rate limit)
// bridge.503        a request to the bridge   answered 503
// bridge.timeout    a request to the bridge   answered only after bridge.timeout_ms (default 2500,
//                                             beyond the rig's 2000 ms per command)
// bridge.drop       a request to the bridge   its connection closed without an answer
// lamp.unreachable  a request to the bridge   a lamp (drawn) reports "reachable": false for lamp.unreachable_ms (1500)
// camera.gone       a shot                    the camera is unplugged (USB drop) before the shot and
//                                             plugged in again camera.gone_ms (800) later
// clock.step        a shot                    the wall clock steps by clock.step_s (3600) forward or back
// store.enospc      a file of a set written   half the file is written, then ENOSPC
// store.eio         a file of a set written   half the file is written, then EIO
// store.slow        a file of a set written   the write takes store.slow_ms (300) longer (a slow SD card)
// client.vanish     a soak's pull             the client hangs up mid-pull (then pulls again: resumes)
// client.stall      a soak's pull             a second client asks for the set and stops reading for
//                                             client.stall_ms (3000), then hangs up
//
// A plan is shared (std::shared_ptr) by the threads that draw from it; draw()
// and counts() are thread-safe.
#include <array>
#include <cstdint>
#include <map>
#include <mutex>
#include <random>
#include <string>
#include <vector>

#include "veneer/util/expected.hpp"

namespace veneerd {

enum class Fault {
  bridge_429, bridge_503, bridge_timeout, bridge_drop, lamp_unreachable,
  camera_gone, clock_step,
  store_enospc, store_eio, store_slow,
  client_vanish, client_stall,
};
inline constexpr int kFaultCount = 12;

// "bridge.429", ... (the SPEC's names).
const char* fault_name(Fault fault);

// The sizes of the faults (SPEC parameters of the same names).
struct FaultSizes {
  int bridge_timeout_ms = 2500;    // bridge.timeout_ms
  int lamp_unreachable_ms = 1500;  // lamp.unreachable_ms
  int camera_gone_ms = 800;        // camera.gone_ms
  int clock_step_s = 3600;         // clock.step_s
  int store_slow_ms = 300;         // store.slow_ms
  int client_stall_ms = 3000;      // client.stall_ms
};

class FaultPlan {
 public:
  FaultPlan() = default;
  // Parses a SPEC (text or JSON object); an error names the item that is wrong.
  static veneer::Expected<FaultPlan> parse(const std::string& spec);

  // Whether this opportunity of `fault` takes it (counts the opportunity).
  bool draw(Fault fault);
  // A number in [0, n) from `fault`'s stream (which lamp, which direction).
  uint32_t pick(Fault fault, uint32_t n);
  // Whether the plan can ever inject `fault` (a rate above 0 or a schedule).
  bool has(Fault fault) const;
  bool empty() const;

  const FaultSizes& sizes() const { return sizes_; }
  uint64_t seed() const { return seed_; }
  // The plan as a canonical SPEC (rates, schedules, sizes that differ from the defaults, seed).
  std::string spec() const;

  struct Count {
    uint64_t opportunities = 0;
    uint64_t taken = 0;
  };
  Count count(Fault fault) const;
  // {"bridge.503": {"opportunities": 3400, "taken": 61}, ...} for the faults the plan has.
  std::string counts_json() const;

  FaultPlan(const FaultPlan& other);
  FaultPlan& operator=(const FaultPlan& other);

 private:
  struct Entry {
    double rate = 0;
    std::vector<uint64_t> at;  // scheduled opportunities (1-based), sorted
    Count count;
    std::mt19937_64 rng;
  };
  void seed_streams();
  std::array<Entry, kFaultCount> entries_{};
  FaultSizes sizes_;
  uint64_t seed_ = 1;
  mutable std::mutex mutex_;
};

}  // namespace veneerd
