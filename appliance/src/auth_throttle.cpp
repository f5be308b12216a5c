#include "veneerd/auth_throttle.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include <asio/ip/address.hpp>

namespace veneerd {

namespace {
double secs(AuthThrottle::Clock::duration d) { return std::chrono::duration<double>(d).count(); }
AuthThrottle::Clock::duration span(double s) {
  return std::chrono::duration_cast<AuthThrottle::Clock::duration>(std::chrono::duration<double>(s));
}
}  // namespace

std::string AuthThrottle::peer_key(const std::string& address) {
  std::error_code ec;
  auto a = asio::ip::make_address(address, ec);
  if (ec) return address;
  if (a.is_v4()) return a.to_string();
  auto v6 = a.to_v6();
  if (v6.is_v4_mapped()) return asio::ip::make_address_v4(asio::ip::v4_mapped, v6).to_string();
  auto bytes = v6.to_bytes();
  std::fill(bytes.begin() + 8, bytes.end(), 0);
  return asio::ip::address_v6(bytes).to_string() + "/64";
}

std::optional<AuthThrottle::Clock::time_point> AuthThrottle::admit(const std::string& peer, Clock::time_point now) {
  auto it = peers_.find(peer);
  if (it != peers_.end() && it->second.waiting == 0 && secs(now - it->second.last_failure) > opt_.forget_s) {
    peers_.erase(it);  // forgiven
    it = peers_.end();
  }
  if (it == peers_.end() || it->second.failures < opt_.free_failures) return now;
  Peer& p = it->second;
  const int over = p.failures - opt_.free_failures + 1;  // the turn after this one
  const double delay = std::min(opt_.first_delay_s * std::ldexp(1.0, std::min(over, 30)), opt_.max_delay_s);
  const Clock::time_point turn = std::max(now, p.next_turn);
  if (turn > now) {
    if (p.waiting >= opt_.max_waiting) return std::nullopt;
    ++p.waiting;
  }
  p.next_turn = turn + span(delay);
  return turn;
}

void AuthThrottle::left_queue(const std::string& peer) {
  auto it = peers_.find(peer);
  if (it != peers_.end() && it->second.waiting > 0) --it->second.waiting;
}

bool AuthThrottle::failed(const std::string& peer, Clock::time_point now) {
  Peer& p = peers_[peer];
  ++p.failures;
  p.last_failure = now;
  // The last free failure: the next attempt's turn is first_delay_s away.
  if (p.failures == opt_.free_failures) p.next_turn = std::max(p.next_turn, now + span(opt_.first_delay_s));
  if (peers_.size() > opt_.max_peers) forget_stale(now);
  ++burst_failures_;
  ++burst_by_peer_[peer];
  const bool first = !burst_open_;
  if (first) {
    burst_open_ = true;
    burst_start_ = now;
    last_summary_ = now;
    summarised_failures_ = 1;  // the first line told of it
  }
  burst_last_ = now;
  return first;
}

void AuthThrottle::succeeded(const std::string& peer) {
  auto it = peers_.find(peer);
  if (it != peers_.end() && it->second.waiting == 0) peers_.erase(it);
  else if (it != peers_.end()) it->second.failures = 0;
}

void AuthThrottle::forget_stale(Clock::time_point now) {
  for (auto it = peers_.begin(); it != peers_.end();) {
    if (it->second.waiting == 0 && secs(now - it->second.last_failure) > opt_.forget_s) it = peers_.erase(it);
    else ++it;
  }
  if (peers_.size() <= opt_.max_peers) return;
  // Still too many: drop the tenth that failed longest ago.
  std::vector<Clock::time_point> times;
  times.reserve(peers_.size());
  for (const auto& [key, p] : peers_) times.push_back(p.last_failure);
  auto cut = times.begin() + static_cast<std::ptrdiff_t>(times.size() / 10);
  std::nth_element(times.begin(), cut, times.end());
  for (auto it = peers_.begin(); it != peers_.end();) {
    if (it->second.waiting == 0 && it->second.last_failure <= *cut) it = peers_.erase(it);
    else ++it;
  }
}

std::optional<std::string> AuthThrottle::summary(Clock::time_point now, std::optional<Clock::time_point>* next_check) {
  if (next_check) next_check->reset();
  if (!burst_open_) return std::nullopt;
  const bool ended = secs(now - burst_last_) >= opt_.burst_gap_s;
  const bool due = secs(now - last_summary_) >= opt_.summary_every_s;
  std::optional<std::string> line;
  if ((ended || due) && burst_failures_ > summarised_failures_) {
    std::string most;
    uint64_t most_n = 0;
    for (const auto& [key, n] : burst_by_peer_) {
      if (n > most_n) {
        most = key;
        most_n = n;
      }
    }
    char buf[512];
    std::snprintf(buf, sizeof buf,
                  "wrong access token: %llu attempts in %.1f s from %zu address(es), most from %s (%llu)%s; "
                  "an address gets %d answers at once, then one per %.3g s doubling to one per %.3g s",
                  static_cast<unsigned long long>(burst_failures_), secs(burst_last_ - burst_start_),
                  burst_by_peer_.size(), most.c_str(), static_cast<unsigned long long>(most_n),
                  ended ? "" : ", still going", opt_.free_failures, opt_.first_delay_s, opt_.max_delay_s);
    line = buf;
    summarised_failures_ = burst_failures_;
  }
  if (due) last_summary_ = now;
  if (ended) {
    burst_open_ = false;
    burst_failures_ = 0;
    summarised_failures_ = 0;
    burst_by_peer_.clear();
    return line;
  }
  if (next_check) *next_check = std::min(burst_last_ + span(opt_.burst_gap_s), last_summary_ + span(opt_.summary_every_s));
  return line;
}

}  // namespace veneerd
