#pragma once
// Slows wrong-token attempts per peer and sums them up for the log.
//
// A peer is a remote address (IPv4 address, IPv6 /64). Its first
// `free_failures` wrong tokens are answered at once (a typo costs nothing);
// after that each of its hellos waits for its turn: turns are spaced by a
// delay that starts at `first_delay_s` and doubles per failure up to
// `max_delay_s`, so one address gets at most one answer per `max_delay_s`
// however many connections it opens. Hellos waiting beyond `max_waiting` are
// refused unread. A right token clears the peer's record. The log gets one
// line when a burst of failures starts and one summary when it ends (no
// failure for `burst_gap_s`) or every `summary_every_s` while it lasts.
//
// Not thread-safe: the server uses it from its I/O thread only. Times are
// passed in, so tests can drive it without waiting.
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <unordered_map>

namespace veneerd {

struct AuthThrottleOptions {
  int free_failures = 3;          // wrong tokens per peer answered without delay
  double first_delay_s = 0.1;     // spacing of the next turn after those [s]
  double max_delay_s = 1.0;       // the spacing's cap [s]: 1 attempt/s per peer at most
  int max_waiting = 8;            // hellos of one peer waiting for a turn; beyond: refused unread
  double forget_s = 600;          // a peer's record is dropped this long after its last failure [s]
  double burst_gap_s = 5;         // a burst ends after this long without a failure [s]
  double summary_every_s = 60;    // summary of a burst that goes on [s]
  size_t max_peers = 4096;        // records kept; the stalest go first
};

class AuthThrottle {
 public:
  using Clock = std::chrono::steady_clock;
  explicit AuthThrottle(AuthThrottleOptions options = {}) : opt_(options) {}

  // The peer key of a remote address as text ("192.0.2.7", "2001:db8::1",
  // "::ffff:192.0.2.7"): IPv4 as is, IPv6 cut to its /64.
  static std::string peer_key(const std::string& address);

  // When the hello of `peer` may be checked: `now` or a later turn; nullopt
  // when too many of its hellos already wait. A hello given a later turn
  // counts as waiting until left_queue() (its turn came, or it went away).
  std::optional<Clock::time_point> admit(const std::string& peer, Clock::time_point now);
  void left_queue(const std::string& peer);
  // The hello's token was wrong. True when this starts a burst (log it).
  bool failed(const std::string& peer, Clock::time_point now);
  // The token was right: the peer's record goes.
  void succeeded(const std::string& peer);

  // A summary line when a burst has ended or has gone on for a while;
  // nullopt otherwise. `next_check` is when to ask again (if a burst is open).
  std::optional<std::string> summary(Clock::time_point now, std::optional<Clock::time_point>* next_check = nullptr);

  size_t peers() const { return peers_.size(); }
  const AuthThrottleOptions& options() const { return opt_; }

 private:
  struct Peer {
    int failures = 0;
    int waiting = 0;
    Clock::time_point next_turn{};
    Clock::time_point last_failure{};
  };
  void forget_stale(Clock::time_point now);

  AuthThrottleOptions opt_;
  std::unordered_map<std::string, Peer> peers_;
  // The open burst.
  bool burst_open_ = false;
  Clock::time_point burst_start_{}, burst_last_{}, last_summary_{};
  uint64_t burst_failures_ = 0, summarised_failures_ = 0;
  std::unordered_map<std::string, uint64_t> burst_by_peer_;
};

}  // namespace veneerd
