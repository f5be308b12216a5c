// DNS-SD without a daemon: the record formatting that can be checked offline,
// and the degraded path (no avahi-daemon / no system D-Bus) that CI and most
// containers take. The system bus is pointed at a socket that does not exist,
// so these tests take the degraded path on any machine.
#include <cstdio>
#include <cstdlib>
#include <string>

#include <net/if.h>
#include <sys/wait.h>

#include <gtest/gtest.h>

#include "veneer/dnssd/dnssd.hpp"
#include "veneer/proto/discovery.hpp"
#include "veneer/proto/framing.hpp"
#include "veneer/rig/client.hpp"

namespace {

using namespace veneer;

constexpr const char* kNoBus = "unix:path=/nonexistent/veneer-test-no-dbus";

class NoDaemon : public ::testing::Test {
 protected:
  void SetUp() override { ::setenv("DBUS_SYSTEM_BUS_ADDRESS", kNoBus, 1); }
};

TEST(DnssdTxt, StringsAreKeyEqualsValueInKeyOrder) {
  auto s = dnssd::txt_strings({{"version", "0.1.0"}, {"name", "bench rig"}, {"proto", "1"}, {"flag", ""}});
  ASSERT_TRUE(s) << s.message();
  EXPECT_EQ(*s, (std::vector<std::string>{"flag=", "name=bench rig", "proto=1", "version=0.1.0"}));
}

TEST(DnssdTxt, BadKeysAndLongStringsAreNamed) {
  auto empty = dnssd::txt_strings({{"", "x"}});
  ASSERT_FALSE(empty);
  EXPECT_NE(empty.message().find("empty key"), std::string::npos) << empty.message();
  auto eq = dnssd::txt_strings({{"a=b", "x"}});
  ASSERT_FALSE(eq);
  EXPECT_NE(eq.message().find("'a=b'"), std::string::npos) << eq.message();
  auto longkey = dnssd::txt_strings({{"averylongkey", "x"}});
  ASSERT_FALSE(longkey);
  EXPECT_NE(longkey.message().find("'averylongkey'"), std::string::npos) << longkey.message();
  auto fits = dnssd::txt_strings({{"name", std::string(250, 'r')}});  // 5 + 250 = 255 bytes
  EXPECT_TRUE(fits) << fits.message();
  auto too_long = dnssd::txt_strings({{"name", std::string(251, 'r')}});
  ASSERT_FALSE(too_long);
  EXPECT_NE(too_long.message().find("256 bytes"), std::string::npos) << too_long.message();
}

TEST(DnssdTxt, ParseIsTheInverseWithLowerCaseKeys) {
  const dnssd::Txt txt{{"name", "rig = one"}, {"proto", "1"}, {"empty", ""}};
  auto s = dnssd::txt_strings(txt);
  ASSERT_TRUE(s);
  EXPECT_EQ(dnssd::parse_txt(*s), txt);
  // A bare key is a key with no value; '=' first is ignored; keys are case-insensitive, first wins.
  EXPECT_EQ(dnssd::parse_txt({"Name=A", "NAME=B", "bare", "=junk"}), (dnssd::Txt{{"name", "A"}, {"bare", ""}}));
}

TEST(DnssdNames, TypesAndInstanceNamesAreChecked) {
  EXPECT_TRUE(dnssd::check_service_type("_veneer._tcp"));
  EXPECT_TRUE(dnssd::check_service_type("_hue._tcp"));
  EXPECT_TRUE(dnssd::check_service_type("_a-b._udp"));
  for (const char* bad : {"", "veneer._tcp", "_veneer", "_veneer._sctp", "_._tcp", "_way-too-long-name._tcp", "_ven eer._tcp"}) {
    auto s = dnssd::check_service_type(bad);
    ASSERT_FALSE(s) << bad;
    EXPECT_NE(s.message().find(std::string("'") + bad + "'"), std::string::npos) << s.message();
  }
  EXPECT_TRUE(dnssd::check_instance_name("veneer-rig #2"));
  EXPECT_FALSE(dnssd::check_instance_name(""));
  EXPECT_FALSE(dnssd::check_instance_name(std::string(64, 'x')));
  EXPECT_FALSE(dnssd::check_instance_name("tab\there"));
}

TEST(RigTxt, TheRigsRecordReadsBackThroughTheWireFormat) {
  auto txt = wire::rig_txt("bench rig", "0.1.0");
  auto strings = dnssd::txt_strings(txt);
  ASSERT_TRUE(strings) << strings.message();
  EXPECT_EQ(*strings, (std::vector<std::string>{"name=bench rig", "proto=" + std::to_string(wire::kProtocolVersion),
                                                "transport=tcp", "version=0.1.0"}));
  auto back = wire::parse_rig_txt(dnssd::parse_txt(*strings));
  EXPECT_EQ(back.name, "bench rig");
  EXPECT_EQ(back.version, "0.1.0");
  EXPECT_EQ(back.protocol, wire::kProtocolVersion);
  EXPECT_EQ(back.transport, "tcp");
  EXPECT_EQ(back.fingerprint, "");
  // A TLS rig (the default) announces its certificate's fingerprint.
  const std::string fp = "69:7B:EE:D8:1B:05:31:38:2B:41:E9:A3:73:F0:29:D0:60:0D:DA:B2:27:55:A5:6A:B7:54:33:FA:FC:80:BE:19";
  auto tls_strings = dnssd::txt_strings(wire::rig_txt("bench rig", "0.1.0", fp));
  ASSERT_TRUE(tls_strings) << tls_strings.message();
  auto tls_back = wire::parse_rig_txt(dnssd::parse_txt(*tls_strings));
  EXPECT_EQ(tls_back.transport, "tls1.3");
  EXPECT_EQ(tls_back.fingerprint, fp);
  EXPECT_EQ(wire::parse_rig_txt({{"proto", "1x"}}).protocol, 0u);
  EXPECT_EQ(std::string(wire::kServiceType), "_veneer._tcp");
  EXPECT_TRUE(dnssd::check_service_type(wire::kServiceType));
}

// Where a listening address is reached (the advertisement follows it; the
// whole path against a real avahi-daemon is appliance/Advertise.*).
TEST(DnssdReach, WildcardsAreEveryInterfaceInTheirFamilies) {
  auto v4 = dnssd::reach_of("0.0.0.0");
  ASSERT_TRUE(v4) << v4.message();
  EXPECT_EQ(v4->interface, 0u);
  EXPECT_EQ(v4->family, dnssd::Family::ipv4);
  EXPECT_EQ(v4->describe(), "every interface, IPv4");
  auto both = dnssd::reach_of("::", true);
  ASSERT_TRUE(both) << both.message();
  EXPECT_EQ(both->interface, 0u);
  EXPECT_EQ(both->family, dnssd::Family::any);
  auto v6only = dnssd::reach_of("::", false);
  ASSERT_TRUE(v6only) << v6only.message();
  EXPECT_EQ(v6only->family, dnssd::Family::ipv6);
  auto mapped_any = dnssd::reach_of("::ffff:0.0.0.0");
  ASSERT_TRUE(mapped_any) << mapped_any.message();
  EXPECT_EQ(mapped_any->family, dnssd::Family::ipv4);
}

TEST(DnssdReach, OneAddressIsItsInterfaceAndFamily) {
  const unsigned lo = if_nametoindex("lo");
  ASSERT_NE(lo, 0u);
  auto v4 = dnssd::reach_of("127.0.0.1");
  ASSERT_TRUE(v4) << v4.message();
  EXPECT_EQ(v4->interface, lo);
  EXPECT_EQ(v4->interface_name, "lo");
  EXPECT_EQ(v4->family, dnssd::Family::ipv4);
  EXPECT_EQ(v4->describe(), "lo, IPv4");
  // An IPv4-mapped address takes IPv4 connections.
  auto mapped = dnssd::reach_of("::ffff:127.0.0.1");
  ASSERT_TRUE(mapped) << mapped.message();
  EXPECT_EQ(mapped->interface, lo);
  EXPECT_EQ(mapped->family, dnssd::Family::ipv4);
  auto v6 = dnssd::reach_of("::1");
  if (v6) {  // absent where IPv6 is switched off
    EXPECT_EQ(v6->interface, lo);
    EXPECT_EQ(v6->family, dnssd::Family::ipv6);
  }
}

TEST(DnssdReach, AddressesNoInterfaceHoldsAndNonAddressesAreNamed) {
  auto absent = dnssd::reach_of("192.0.2.254");  // documentation range: on no interface here
  ASSERT_FALSE(absent);
  EXPECT_NE(absent.message().find("192.0.2.254 is on no network interface"), std::string::npos) << absent.message();
  auto name = dnssd::reach_of("rig.local");
  ASSERT_FALSE(name);
  EXPECT_NE(name.message().find("'rig.local' is not an IP address"), std::string::npos) << name.message();
}

TEST(FoundRig, EndpointsParseBackAsTheRigsAddress) {
  rig::FoundRig r;
  r.name = "bench rig";
  r.address = "192.168.1.20";
  r.port = 7879;
  r.host = "bench.local";
  r.version = "0.1.0";
  r.protocol = 1;
  EXPECT_EQ(r.endpoint(), "192.168.1.20:7879");
  EXPECT_EQ(r.describe(), "bench rig  192.168.1.20:7879  (bench.local, veneerd 0.1.0, protocol 1)");
  auto e = rig::Endpoint::parse(r.endpoint());
  ASSERT_TRUE(e) << e.message();
  EXPECT_EQ(e->host, "192.168.1.20");
  EXPECT_EQ(e->port, 7879);
  r.address = "fd00::20";
  EXPECT_EQ(r.endpoint(), "[fd00::20]:7879");
  auto e6 = rig::Endpoint::parse(r.endpoint());
  ASSERT_TRUE(e6) << e6.message();
  EXPECT_EQ(e6->host, "fd00::20");
  EXPECT_EQ(e6->port, 7879);
}

TEST_F(NoDaemon, BrowseSaysDnssdIsUnavailable) {
  auto found = dnssd::browse("_veneer._tcp", 500);
  ASSERT_FALSE(found);
  EXPECT_EQ(found.message().rfind("DNS-SD unavailable: ", 0), 0u) << found.message();
  EXPECT_NE(found.message().find("avahi-daemon"), std::string::npos) << found.message();
  auto rigs = rig::find_rigs(500);
  ASSERT_FALSE(rigs);
  EXPECT_EQ(rigs.message(), found.message());
}

TEST_F(NoDaemon, BadTypesAreRefusedBeforeAskingAvahi) {
  auto found = dnssd::browse("veneer", 500);
  ASSERT_FALSE(found);
  EXPECT_NE(found.message().find("'veneer'"), std::string::npos) << found.message();
}

TEST_F(NoDaemon, AdvertisingFailsWithOneMessageAndBadInputIsNamed) {
  dnssd::Advertisement ad{"bench rig", "_veneer._tcp", 7878, wire::rig_txt("bench rig", "0.1.0"), {}};
  auto a = dnssd::Advertiser::start(ad);
  ASSERT_FALSE(a);
  EXPECT_EQ(a.message().rfind("DNS-SD unavailable: ", 0), 0u) << a.message();

  auto port0 = dnssd::Advertiser::start({"bench rig", "_veneer._tcp", 0, {}, {}});
  ASSERT_FALSE(port0);
  EXPECT_NE(port0.message().find("port 0"), std::string::npos) << port0.message();
  auto badkey = dnssd::Advertiser::start({"bench rig", "_veneer._tcp", 7878, {{"a=b", "c"}}, {}});
  ASSERT_FALSE(badkey);
  EXPECT_NE(badkey.message().find("'a=b'"), std::string::npos) << badkey.message();
  auto noname = dnssd::Advertiser::start({"", "_veneer._tcp", 7878, {}, {}});
  ASSERT_FALSE(noname);
  EXPECT_NE(noname.message().find("name is empty"), std::string::npos) << noname.message();
}

// `veneer rig find` without avahi-daemon: one clear line, exit 1, no crash.
TEST_F(NoDaemon, CliRigFindExplainsThatNothingCanBeFound) {
  const std::string cmd = std::string(VENEER_BIN_DIR) + "/veneer rig find --wait 0.5 2>&1";
  FILE* p = ::popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string out;
  char buf[1024];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  const int status = ::pclose(p);
  ASSERT_TRUE(WIFEXITED(status)) << out;
  EXPECT_EQ(WEXITSTATUS(status), 1) << out;
  EXPECT_EQ(out.rfind("veneer rig find: DNS-SD unavailable: ", 0), 0u) << out;
  EXPECT_NE(out.find("--rig host:port"), std::string::npos) << out;
}

}  // namespace
