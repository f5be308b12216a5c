#include "veneerd/sim/fault_plan.hpp"

#include <algorithm>
#include <cmath>
#include <optional>
#include <sstream>

#include <nlohmann/json.hpp>

namespace veneerd {

using veneer::make_error;
using json = nlohmann::json;

namespace {

constexpr const char* kNames[kFaultCount] = {
    "bridge.429",   "bridge.503",   "bridge.timeout", "bridge.drop", "lamp.unreachable", "camera.gone",
    "clock.step",   "store.enospc", "store.eio",      "store.slow",  "client.vanish",    "client.stall",
};

struct SizeField {
  const char* name;
  int FaultSizes::*field;
  int min, max;
};
constexpr SizeField kSizes[] = {
    {"bridge.timeout_ms", &FaultSizes::bridge_timeout_ms, 1, 60000},
    {"lamp.unreachable_ms", &FaultSizes::lamp_unreachable_ms, 1, 600000},
    {"camera.gone_ms", &FaultSizes::camera_gone_ms, 1, 600000},
    {"clock.step_s", &FaultSizes::clock_step_s, 1, 10 * 365 * 86400},
    {"store.slow_ms", &FaultSizes::store_slow_ms, 1, 60000},
    {"client.stall_ms", &FaultSizes::client_stall_ms, 1, 600000},
};

int fault_index(const std::string& name) {
  for (int i = 0; i < kFaultCount; ++i)
    if (name == kNames[i]) return i;
  return -1;
}

std::string known_names() {
  std::string out;
  for (const char* n : kNames) out += (out.empty() ? "" : ", ") + std::string(n);
  for (const auto& s : kSizes) out += ", " + std::string(s.name);
  return out + ", seed";
}

// A whole number from `text`, or nullopt.
std::optional<long long> whole(const std::string& text) {
  if (text.empty() || text.size() > 18 || text.find_first_not_of("0123456789") != std::string::npos) return std::nullopt;
  return std::stoll(text);
}

}  // namespace

const char* fault_name(Fault fault) { return kNames[static_cast<int>(fault)]; }

FaultPlan::FaultPlan(const FaultPlan& other) { *this = other; }

FaultPlan& FaultPlan::operator=(const FaultPlan& other) {
  if (this == &other) return *this;
  std::scoped_lock lock(mutex_, other.mutex_);
  entries_ = other.entries_;
  sizes_ = other.sizes_;
  seed_ = other.seed_;
  return *this;
}

void FaultPlan::seed_streams() {
  // One stream per fault, so one site's draws do not shift another's.
  for (int i = 0; i < kFaultCount; ++i) {
    std::seed_seq seq{static_cast<uint32_t>(seed_), static_cast<uint32_t>(seed_ >> 32), static_cast<uint32_t>(i)};
    entries_[i].rng.seed(seq);
  }
}

veneer::Expected<FaultPlan> FaultPlan::parse(const std::string& spec) {
  FaultPlan plan;
  auto bad = [](const std::string& item, const std::string& why) {
    return make_error("--faults: '" + item + "': " + why);
  };
  // Applies one item: key (with "@" for a schedule) and its value as text.
  auto apply = [&](const std::string& item, const std::string& key, const std::string& value,
                   bool scheduled) -> veneer::Status {
    if (scheduled) {
      const int i = fault_index(key);
      if (i < 0) return bad(item, "no fault named '" + key + "' (known: " + known_names() + ")");
      auto n = whole(value);
      if (!n || *n < 1) return bad(item, "a schedule takes an opportunity number 1, 2, ...");
      plan.entries_[i].at.push_back(static_cast<uint64_t>(*n));
      std::sort(plan.entries_[i].at.begin(), plan.entries_[i].at.end());
      return {};
    }
    if (key == "seed") {
      auto n = whole(value);
      if (!n) return bad(item, "the seed is a whole number");
      plan.seed_ = static_cast<uint64_t>(*n);
      return {};
    }
    for (const auto& s : kSizes) {
      if (key != s.name) continue;
      auto n = whole(value);
      if (!n || *n < s.min || *n > s.max)
        return bad(item, "must be a whole number " + std::to_string(s.min) + ".." + std::to_string(s.max));
      plan.sizes_.*(s.field) = static_cast<int>(*n);
      return {};
    }
    const int i = fault_index(key);
    if (i < 0) return bad(item, "no fault named '" + key + "' (known: " + known_names() + ")");
    double p = -1;
    try {
      size_t used = 0;
      p = std::stod(value, &used);
      if (used != value.size()) p = -1;
    } catch (...) {
      p = -1;
    }
    if (!(p >= 0 && p <= 1)) return bad(item, "a rate is a probability 0..1");
    plan.entries_[i].rate = p;
    return {};
  };

  const auto first = spec.find_first_not_of(" \t\r\n");
  if (first != std::string::npos && spec[first] == '{') {
    json doc = json::parse(spec, nullptr, false);
    if (doc.is_discarded() || !doc.is_object()) return make_error("--faults: not a JSON object");
    for (const auto& [key, value] : doc.items()) {
      const bool scheduled = !key.empty() && key.back() == '@';
      const std::string name = scheduled ? key.substr(0, key.size() - 1) : key;
      if (scheduled) {
        if (!value.is_array()) return bad(key, "a schedule is an array of opportunity numbers");
        for (const auto& v : value) {
          if (!v.is_number_unsigned()) return bad(key, "a schedule is an array of opportunity numbers");
          if (auto s = apply(key, name, std::to_string(v.get<uint64_t>()), true); !s) return s.error();
        }
        continue;
      }
      if (!value.is_number()) return bad(key, "the value must be a number");
      std::ostringstream text;
      text.precision(17);
      if (value.is_number_integer()) {
        text << value.get<long long>();
      } else {
        text << value.get<double>();
      }
      if (auto s = apply(key, name, text.str(), false); !s) return s.error();
    }
  } else {
    std::istringstream in(spec);
    std::string item;
    while (std::getline(in, item, ',')) {
      item.erase(0, item.find_first_not_of(" \t"));
      item.erase(item.find_last_not_of(" \t") + 1);
      if (item.empty()) continue;
      const auto at = item.find_first_of("=@");
      if (at == std::string::npos || at == 0 || at + 1 >= item.size())
        return bad(item, "expected NAME=VALUE or NAME@N");
      if (auto s = apply(item, item.substr(0, at), item.substr(at + 1), item[at] == '@'); !s) return s.error();
    }
  }
  plan.seed_streams();
  return plan;
}

bool FaultPlan::draw(Fault fault) {
  std::lock_guard lock(mutex_);
  Entry& e = entries_[static_cast<int>(fault)];
  const uint64_t n = ++e.count.opportunities;
  bool take = std::binary_search(e.at.begin(), e.at.end(), n);
  if (e.rate > 0) {
    // Drawn at every opportunity (taken or not by a schedule), so the stream
    // stays in step with the opportunities.
    const bool random = std::uniform_real_distribution<double>(0.0, 1.0)(e.rng) < e.rate;
    take = take || random;
  }
  if (take) ++e.count.taken;
  return take;
}

uint32_t FaultPlan::pick(Fault fault, uint32_t n) {
  if (n <= 1) return 0;
  std::lock_guard lock(mutex_);
  return std::uniform_int_distribution<uint32_t>(0, n - 1)(entries_[static_cast<int>(fault)].rng);
}

bool FaultPlan::has(Fault fault) const {
  std::lock_guard lock(mutex_);
  const Entry& e = entries_[static_cast<int>(fault)];
  return e.rate > 0 || !e.at.empty();
}

bool FaultPlan::empty() const {
  for (int i = 0; i < kFaultCount; ++i)
    if (has(static_cast<Fault>(i))) return false;
  return true;
}

FaultPlan::Count FaultPlan::count(Fault fault) const {
  std::lock_guard lock(mutex_);
  return entries_[static_cast<int>(fault)].count;
}

std::string FaultPlan::spec() const {
  std::lock_guard lock(mutex_);
  std::string out;
  auto add = [&](const std::string& item) { out += (out.empty() ? "" : ",") + item; };
  for (int i = 0; i < kFaultCount; ++i) {
    const Entry& e = entries_[i];
    if (e.rate > 0) {
      std::ostringstream r;
      r << e.rate;
      add(std::string(kNames[i]) + "=" + r.str());
    }
    for (uint64_t n : e.at) add(std::string(kNames[i]) + "@" + std::to_string(n));
  }
  const FaultSizes defaults;
  for (const auto& s : kSizes)
    if (sizes_.*(s.field) != defaults.*(s.field)) add(std::string(s.name) + "=" + std::to_string(sizes_.*(s.field)));
  add("seed=" + std::to_string(seed_));
  return out;
}

std::string FaultPlan::counts_json() const {
  json out = json::object();
  for (int i = 0; i < kFaultCount; ++i) {
    if (!has(static_cast<Fault>(i))) continue;
    const Count c = count(static_cast<Fault>(i));
    out[kNames[i]] = {{"opportunities", c.opportunities}, {"taken", c.taken}};
  }
  return out.dump();
}

}  // namespace veneerd
