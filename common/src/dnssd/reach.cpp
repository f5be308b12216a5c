// Where a listening socket can be reached, as DNS-SD needs it: the interface
// and address family to advertise on (getifaddrs; no Avahi here).
#include <cstring>
#include <memory>

#include <arpa/inet.h>
#include <ifaddrs.h>
#include <net/if.h>
#include <netdb.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include "veneer/dnssd/dnssd.hpp"
#include "veneer/util/enum_names.hpp"

namespace veneer::dnssd {

constexpr EnumName<Family> kFamilyNames[] = {
    {Family::any, "IPv4 and IPv6"}, {Family::ipv4, "IPv4"}, {Family::ipv6, "IPv6"}};

const char* family_name(Family family) { return name_of(kFamilyNames, family, "IPv4 and IPv6"); }

std::string Reach::describe() const {
  return (interface == 0 ? std::string("every interface") : interface_name) + ", " + family_name(family);
}

namespace {

struct AddrinfoDeleter {
  void operator()(addrinfo* a) const { freeaddrinfo(a); }
};
struct IfaddrsDeleter {
  void operator()(ifaddrs* a) const { freeifaddrs(a); }
};

// The interface holding `want` (AF_INET or AF_INET6; for IPv6, `scope` 0 or
// the scope the address named).
Expected<Reach> interface_holding(const sockaddr* want, uint32_t scope, const std::string& shown) {
  ifaddrs* raw = nullptr;
  if (::getifaddrs(&raw) != 0) {
    return make_error(std::string("cannot list the network interfaces: ") + std::strerror(errno));
  }
  std::unique_ptr<ifaddrs, IfaddrsDeleter> list(raw);
  for (const ifaddrs* a = list.get(); a; a = a->ifa_next) {
    if (!a->ifa_addr || a->ifa_addr->sa_family != want->sa_family) continue;
    bool same = false;
    if (want->sa_family == AF_INET) {
      same = reinterpret_cast<const sockaddr_in*>(a->ifa_addr)->sin_addr.s_addr ==
             reinterpret_cast<const sockaddr_in*>(want)->sin_addr.s_addr;
    } else {
      const auto* have = reinterpret_cast<const sockaddr_in6*>(a->ifa_addr);
      same = std::memcmp(&have->sin6_addr, &reinterpret_cast<const sockaddr_in6*>(want)->sin6_addr,
                         sizeof(in6_addr)) == 0 &&
             (scope == 0 || have->sin6_scope_id == 0 || have->sin6_scope_id == scope);
    }
    if (!same) continue;
    Reach r;
    r.interface = ::if_nametoindex(a->ifa_name);
    r.interface_name = a->ifa_name;
    r.family = want->sa_family == AF_INET ? Family::ipv4 : Family::ipv6;
    if (r.interface == 0) return make_error("address " + shown + ": interface " + r.interface_name + " has no index");
    return r;
  }
  return make_error("address " + shown + " is on no network interface of this machine");
}

}  // namespace

Expected<Reach> reach_of(const std::string& address, bool dual_stack) {
  addrinfo hints{};
  hints.ai_flags = AI_NUMERICHOST;
  hints.ai_family = AF_UNSPEC;
  addrinfo* raw = nullptr;
  if (int rc = ::getaddrinfo(address.c_str(), nullptr, &hints, &raw); rc != 0 || !raw) {
    return make_error("'" + address + "' is not an IP address (" + ::gai_strerror(rc) + ")");
  }
  std::unique_ptr<addrinfo, AddrinfoDeleter> info(raw);
  const sockaddr* sa = info->ai_addr;
  if (sa->sa_family == AF_INET) {
    const auto* in = reinterpret_cast<const sockaddr_in*>(sa);
    if (in->sin_addr.s_addr == htonl(INADDR_ANY)) return Reach{0, "", Family::ipv4};
    return interface_holding(sa, 0, address);
  }
  if (sa->sa_family != AF_INET6) return make_error("'" + address + "' is neither an IPv4 nor an IPv6 address");
  const auto* in6 = reinterpret_cast<const sockaddr_in6*>(sa);
  if (IN6_IS_ADDR_UNSPECIFIED(&in6->sin6_addr)) return Reach{0, "", dual_stack ? Family::any : Family::ipv6};
  if (IN6_IS_ADDR_V4MAPPED(&in6->sin6_addr)) {
    // ::ffff:a.b.c.d takes IPv4 connections to a.b.c.d.
    sockaddr_in v4{};
    v4.sin_family = AF_INET;
    std::memcpy(&v4.sin_addr, in6->sin6_addr.s6_addr + 12, 4);
    if (v4.sin_addr.s_addr == htonl(INADDR_ANY)) return Reach{0, "", Family::ipv4};
    return interface_holding(reinterpret_cast<const sockaddr*>(&v4), 0, address);
  }
  return interface_holding(sa, in6->sin6_scope_id, address);
}

}  // namespace veneer::dnssd
