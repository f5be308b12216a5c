#include "veneer/dnssd/dnssd.hpp"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <map>
#include <mutex>
#include <set>
#include <utility>

#include <net/if.h>

#include <avahi-client/client.h>
#include <avahi-client/lookup.h>
#include <avahi-client/publish.h>
#include <avahi-common/alternative.h>
#include <avahi-common/error.h>
#include <avahi-common/malloc.h>
#include <avahi-common/simple-watch.h>
#include <avahi-common/thread-watch.h>

namespace veneer::dnssd {

// ---- formatting --------------------------------------------------------------

Expected<std::vector<std::string>> txt_strings(const Txt& txt) {
  std::vector<std::string> out;
  for (const auto& [k, v] : txt) {
    if (k.empty()) return make_error("TXT record: an empty key");
    if (k.size() > 9) return make_error("TXT record: key '" + k + "' is longer than 9 characters");
    for (unsigned char c : k)
      if (c < 0x20 || c > 0x7e || c == '=')
        return make_error("TXT record: key '" + k + "' has a character other than printable ASCII without '='");
    std::string s = k + "=" + v;
    if (s.size() > 255)
      return make_error("TXT record: '" + k + "' is " + std::to_string(s.size()) + " bytes with its value (at most 255)");
    out.push_back(std::move(s));
  }
  return out;
}

Txt parse_txt(const std::vector<std::string>& strings) {
  Txt txt;
  for (const auto& s : strings) {
    auto eq = s.find('=');
    std::string k = s.substr(0, eq);
    if (k.empty()) continue;  // RFC 6763 6.4: a string starting with '=' is ignored
    std::transform(k.begin(), k.end(), k.begin(), [](unsigned char c) { return std::tolower(c); });
    txt.emplace(std::move(k), eq == std::string::npos ? "" : s.substr(eq + 1));
  }
  return txt;
}

Status check_service_type(const std::string& type) {
  auto bad = [&] { return make_error("DNS-SD service type '" + type + "' is not of the form _name._tcp or _name._udp"); };
  if (type.size() < 7 || type[0] != '_') return bad();
  const std::string proto = type.substr(type.size() - 5);
  if (proto != "._tcp" && proto != "._udp") return bad();
  const std::string name = type.substr(1, type.size() - 6);
  if (name.empty() || name.size() > 15) return bad();
  for (unsigned char c : name)
    if (!std::isalnum(c) && c != '-') return bad();
  return {};
}

Status check_instance_name(const std::string& name) {
  if (name.empty()) return make_error("DNS-SD instance name is empty");
  if (name.size() > 63) return make_error("DNS-SD instance name '" + name + "' is longer than 63 bytes");
  for (unsigned char c : name)
    if (c < 0x20 || c == 0x7f) return make_error("DNS-SD instance name has a control character");
  return {};
}

namespace {

// ---- owners of Avahi's C objects ------------------------------------------------
// Each handle lives in a unique_ptr whose deleter is Avahi's free function, so
// every path out of a function (errors included) frees what it made, in the
// reverse order of making it.

template <auto Free>
struct AvahiDeleter {
  template <class T>
  void operator()(T* p) const {
    if (p) Free(p);
  }
};
using SimplePoll = std::unique_ptr<AvahiSimplePoll, AvahiDeleter<avahi_simple_poll_free>>;
using Client = std::unique_ptr<AvahiClient, AvahiDeleter<avahi_client_free>>;
using ServiceBrowser = std::unique_ptr<AvahiServiceBrowser, AvahiDeleter<avahi_service_browser_free>>;
using ServiceResolver = std::unique_ptr<AvahiServiceResolver, AvahiDeleter<avahi_service_resolver_free>>;
using EntryGroup = std::unique_ptr<AvahiEntryGroup, AvahiDeleter<avahi_entry_group_free>>;
using StringList = std::unique_ptr<AvahiStringList, AvahiDeleter<avahi_string_list_free>>;
using AvahiString = std::unique_ptr<char, AvahiDeleter<avahi_free>>;

// The threaded poll must be stopped (its thread joined) before the client it
// drives is freed: Advertiser::Impl's destructor does that.
using ThreadedPoll = std::unique_ptr<AvahiThreadedPoll, AvahiDeleter<avahi_threaded_poll_free>>;

std::string unavailable(int error) {
  return std::string("DNS-SD unavailable: ") + avahi_strerror(error) +
         " (avahi-daemon and the system D-Bus must run for LAN discovery)";
}

std::vector<std::string> strings_of(AvahiStringList* l) {
  std::vector<std::string> out;
  for (; l; l = avahi_string_list_get_next(l))
    out.emplace_back(reinterpret_cast<const char*>(avahi_string_list_get_text(l)), avahi_string_list_get_size(l));
  std::reverse(out.begin(), out.end());  // Avahi keeps them last-first
  return out;
}

AvahiIfIndex avahi_interface(const Reach& r) {
  return r.interface == 0 ? AVAHI_IF_UNSPEC : static_cast<AvahiIfIndex>(r.interface);
}

AvahiProtocol avahi_protocol(Family f) {
  switch (f) {
    case Family::ipv4: return AVAHI_PROTO_INET;
    case Family::ipv6: return AVAHI_PROTO_INET6;
    case Family::any: break;
  }
  return AVAHI_PROTO_UNSPEC;
}

// ---- browse -------------------------------------------------------------------

struct BrowseState {
  AvahiClient* client = nullptr;  // borrowed from browse()
  std::map<AvahiServiceResolver*, ServiceResolver> resolving;
  bool all_for_now = false;
  std::string failure;
  std::vector<Service> found;
  std::set<std::pair<std::string, std::string>> seen;  // (name, address)
};

void on_resolved(AvahiServiceResolver* r, AvahiIfIndex iface, AvahiProtocol proto, AvahiResolverEvent event,
                 const char* name, const char* type, const char* domain, const char* host,
                 const AvahiAddress* address, uint16_t port, AvahiStringList* txt, AvahiLookupResultFlags,
                 void* user) {
  auto* st = static_cast<BrowseState*>(user);
  if (event == AVAHI_RESOLVER_FOUND && address) {
    char a[AVAHI_ADDRESS_STR_MAX];
    avahi_address_snprint(a, sizeof a, address);
    if (st->seen.emplace(name, a).second) {
      Service s;
      s.name = name;
      s.type = type;
      s.domain = domain;
      s.host = host ? host : "";
      s.address = a;
      s.ipv6 = address->proto == AVAHI_PROTO_INET6;
      s.port = port;
      char ifname[IF_NAMESIZE] = {};
      if (iface >= 0 && if_indextoname(static_cast<unsigned>(iface), ifname)) s.interface = ifname;
      s.txt = parse_txt(strings_of(txt));
      st->found.push_back(std::move(s));
    }
  }
  st->resolving.erase(r);  // frees the resolver
}

void on_browse(AvahiServiceBrowser*, AvahiIfIndex iface, AvahiProtocol proto, AvahiBrowserEvent event,
               const char* name, const char* type, const char* domain, AvahiLookupResultFlags, void* user) {
  auto* st = static_cast<BrowseState*>(user);
  switch (event) {
    case AVAHI_BROWSER_NEW:
      // Resolved to an address of the family it was announced in: a service
      // announced over IPv4 only (a server listening on IPv4) must not be
      // resolved to the host's IPv6 address, where nothing listens for it.
      if (auto* r = avahi_service_resolver_new(st->client, iface, proto, name, type, domain, proto,
                                               static_cast<AvahiLookupFlags>(0), on_resolved, st))
        st->resolving.emplace(r, ServiceResolver(r));
      break;
    case AVAHI_BROWSER_ALL_FOR_NOW:
      st->all_for_now = true;
      break;
    case AVAHI_BROWSER_FAILURE:
      st->failure = avahi_strerror(avahi_client_errno(st->client));
      break;
    default:
      break;
  }
}

}  // namespace

Expected<std::vector<Service>> browse(const std::string& type, int timeout_ms) {
  if (auto s = check_service_type(type); !s) return s.error();
  // Declared in the order they depend on each other, so they are freed in
  // reverse on every return: browser, resolvers (st), client, poll.
  SimplePoll poll(avahi_simple_poll_new());
  if (!poll) return make_error("DNS-SD: out of memory");
  int error = 0;
  Client client(avahi_client_new(avahi_simple_poll_get(poll.get()), static_cast<AvahiClientFlags>(0), nullptr,
                                 nullptr, &error));
  if (!client) return make_error(unavailable(error));
  BrowseState st;
  st.client = client.get();
  ServiceBrowser browser(avahi_service_browser_new(client.get(), AVAHI_IF_UNSPEC, AVAHI_PROTO_UNSPEC, type.c_str(),
                                                   nullptr, static_cast<AvahiLookupFlags>(0), on_browse, &st));
  if (!browser) return make_error("DNS-SD: cannot browse " + type + ": " + avahi_strerror(avahi_client_errno(client.get())));
  using clock = std::chrono::steady_clock;
  const auto deadline = clock::now() + std::chrono::milliseconds(std::max(timeout_ms, 0));
  while (st.failure.empty() && !(st.all_for_now && st.resolving.empty())) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - clock::now()).count();
    if (left <= 0) break;
    if (avahi_simple_poll_iterate(poll.get(), static_cast<int>(std::min<long long>(left, 100))) != 0) break;
  }
  if (!st.failure.empty() && st.found.empty()) return make_error("DNS-SD: browsing " + type + " failed: " + st.failure);
  std::sort(st.found.begin(), st.found.end(),
            [](const Service& a, const Service& b) { return std::tie(a.name, a.ipv6, a.address) < std::tie(b.name, b.ipv6, b.address); });
  return std::move(st.found);
}

// ---- advertise ----------------------------------------------------------------

struct Advertiser::Impl {
  // Declared in the order they are made; destroyed in reverse after the
  // destructor has stopped the poll's thread: group, client, poll.
  ThreadedPoll poll;
  Client client;
  EntryGroup group;
  Advertisement ad;
  std::vector<std::string> txt;
  mutable std::mutex mutex;  // guards ad.name against name()
  std::string failure;

  void publish(AvahiClient* c);
  ~Impl() {
    if (poll) avahi_threaded_poll_stop(poll.get());
  }
};

namespace {

void on_group(AvahiEntryGroup* g, AvahiEntryGroupState state, void* user) {
  auto* impl = static_cast<Advertiser::Impl*>(user);
  if (state == AVAHI_ENTRY_GROUP_COLLISION) {
    AvahiString alt(avahi_alternative_service_name(impl->ad.name.c_str()));
    {
      std::lock_guard lock(impl->mutex);
      impl->ad.name = alt.get();
    }
    avahi_entry_group_reset(g);
    impl->publish(avahi_entry_group_get_client(g));
  }
}

void on_client(AvahiClient* c, AvahiClientState state, void* user) {
  auto* impl = static_cast<Advertiser::Impl*>(user);
  if (state == AVAHI_CLIENT_S_RUNNING) impl->publish(c);
  else if (state == AVAHI_CLIENT_S_COLLISION || state == AVAHI_CLIENT_S_REGISTERING) {
    if (impl->group) avahi_entry_group_reset(impl->group.get());
  }
}

}  // namespace

void Advertiser::Impl::publish(AvahiClient* c) {
  if (!group) group.reset(avahi_entry_group_new(c, on_group, this));
  if (!group) {
    failure = avahi_strerror(avahi_client_errno(c));
    return;
  }
  StringList l;
  for (const auto& s : txt) l.reset(avahi_string_list_add(l.release(), s.c_str()));
  std::string name;
  {
    std::lock_guard lock(mutex);
    name = ad.name;
  }
  // Only where the server listens: an interface it is not bound to, or a
  // family it does not take, would hand browsers an address that answers nothing.
  int rc = avahi_entry_group_add_service_strlst(group.get(), avahi_interface(ad.reach), avahi_protocol(ad.reach.family),
                                                static_cast<AvahiPublishFlags>(0), name.c_str(), ad.type.c_str(),
                                                nullptr, nullptr, ad.port, l.get());
  if (rc == AVAHI_ERR_COLLISION) {
    on_group(group.get(), AVAHI_ENTRY_GROUP_COLLISION, this);
    return;
  }
  if (rc < 0 || (rc = avahi_entry_group_commit(group.get())) < 0) failure = avahi_strerror(rc);
}

Expected<std::unique_ptr<Advertiser>> Advertiser::start(const Advertisement& ad) {
  if (auto s = check_service_type(ad.type); !s) return s.error();
  if (auto s = check_instance_name(ad.name); !s) return s.error();
  if (ad.port == 0) return make_error("DNS-SD: cannot advertise port 0");
  auto txt = txt_strings(ad.txt);
  if (!txt) return txt.error();
  auto impl = std::make_unique<Impl>();
  impl->ad = ad;
  impl->txt = std::move(*txt);
  impl->poll.reset(avahi_threaded_poll_new());
  if (!impl->poll) return make_error("DNS-SD: out of memory");
  int error = 0;
  // The callback runs inside avahi_client_new for the first state (publishing
  // at once when the daemon is up), later on the poll's thread.
  impl->client.reset(avahi_client_new(avahi_threaded_poll_get(impl->poll.get()), static_cast<AvahiClientFlags>(0),
                                      on_client, impl.get(), &error));
  if (!impl->client) return make_error(unavailable(error));
  if (!impl->failure.empty()) return make_error("DNS-SD: cannot advertise " + ad.type + ": " + impl->failure);
  if (avahi_threaded_poll_start(impl->poll.get()) < 0) return make_error("DNS-SD: cannot start Avahi's poll thread");
  return std::unique_ptr<Advertiser>(new Advertiser(std::move(impl)));
}

Advertiser::Advertiser(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Advertiser::~Advertiser() = default;

std::string Advertiser::name() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->ad.name;
}

}  // namespace veneer::dnssd
