// proto/README.md is the contract. Its limits table says the numbers the
// code uses (every row names its constant, and each constant's value must
// appear in its row), and the rig keeps its small promises to the letter,
// checked here against a rig in this process over TCP: name limits count
// characters (code points) and bytes that are not UTF-8 are refused naming
// the field; a request's response comes before the events it causes; the
// hello's status carries the current event seq; a hello with several faults
// gets the refusal the contract's order names.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>
// GCC 12 warns inside <regex> (std::function members "may be used
// uninitialized") when ASan's instrumentation meets -O3: a false positive in
// the library header, which -Werror would turn into a failed `make asan`.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <regex>
#pragma GCC diagnostic pop
#include <sstream>

#include "rig_test_util.hpp"
#include "veneer/proto/framing.hpp"
#include "veneer/proto/utf8.hpp"
#include "veneer/v1/rig.pb.h"
#include "veneerd/api.hpp"
#include "veneerd/auth_throttle.hpp"
#include "veneerd/daemon.hpp"
#include "veneerd/server.hpp"
#include "veneerd/store.hpp"

namespace {

std::vector<std::string> cells(const std::string& row) {
  std::vector<std::string> out;
  std::string cell;
  std::istringstream in(row.substr(1));
  while (std::getline(in, cell, '|')) out.push_back(cell);
  return out;
}

size_t longest_set_id() {
  size_t n = 1;
  while (veneerd::valid_set_id(std::string(n + 1, 'a'))) ++n;
  return n;
}

}  // namespace

TEST(ApiContract, LimitsTableMatchesTheCode) {
  namespace api = veneerd::api;
  const veneerd::ServerOptions server;
  const veneerd::AuthThrottleOptions auth;
  const std::map<std::string, double> code = {
      {"veneer::wire::kMaxMessageBytes", static_cast<double>(veneer::wire::kMaxMessageBytes)},
      {"veneer::wire::kProtocolVersion", veneer::wire::kProtocolVersion},
      {"veneer::wire::kDefaultPort", veneer::wire::kDefaultPort},
      {"ServerOptions::hello_timeout_s", server.hello_timeout_s},
      {"ServerOptions::max_queue_bytes", static_cast<double>(server.max_queue_bytes)},
      {"ServerOptions::live_queue_bytes", static_cast<double>(server.live_queue_bytes)},
      {"ServerOptions::fetch_queue_bytes", static_cast<double>(server.fetch_queue_bytes)},
      {"AuthThrottleOptions::free_failures", auth.free_failures},
      {"AuthThrottleOptions::first_delay_s", auth.first_delay_s},
      {"AuthThrottleOptions::max_delay_s", auth.max_delay_s},
      {"AuthThrottleOptions::max_waiting", auth.max_waiting},
      {"AuthThrottleOptions::burst_gap_s", auth.burst_gap_s},
      {"AuthThrottleOptions::summary_every_s", auth.summary_every_s},
      {"veneerd::api::kMaxTokenBytes", static_cast<double>(api::kMaxTokenBytes)},
      {"veneerd::api::kMaxClientNameChars", static_cast<double>(api::kMaxClientNameChars)},
      {"veneerd::api::kMinChunkBytes", static_cast<double>(api::kMinChunkBytes)},
      {"veneerd::api::kMaxChunkBytes", static_cast<double>(api::kMaxChunkBytes)},
      {"veneerd::api::kDefaultChunkBytes", static_cast<double>(api::kDefaultChunkBytes)},
      {"veneerd::api::kMaxSkipFiles", static_cast<double>(api::kMaxSkipFiles)},
      {"veneerd::api::kMaxSkipFileChars", static_cast<double>(api::kMaxSkipFileChars)},
      {"veneerd::api::kMinLiveFps", api::kMinLiveFps},
      {"veneerd::api::kMaxLiveFps", api::kMaxLiveFps},
      {"veneerd::api::kDefaultLiveFps", api::kDefaultLiveFps},
      {"veneerd::valid_set_id", static_cast<double>(longest_set_id())},
      {"veneerd::api::kMaxObjectChars", static_cast<double>(api::kMaxObjectChars)},
      {"veneerd::api::kMaxShutterS", api::kMaxShutterS},
      {"veneerd::api::kMaxAperture", api::kMaxAperture},
      {"veneerd::api::kMaxIso", api::kMaxIso},
      {"veneerd::api::kMaxLampsInRequest", api::kMaxLampsInRequest},
      {"veneerd::api::kMaxBrightness", api::kMaxBrightness},
      {"veneerd::api::kMaxHandLampDistanceM", api::kMaxHandLampDistanceM},
      {"veneerd::api::kMinHandLampDistanceM", api::kMinHandLampDistanceM},
  };
  std::ifstream in(VENEER_SOURCE_DIR "/proto/README.md");
  ASSERT_TRUE(in) << "proto/README.md missing";
  std::string line;
  bool in_limits = false;
  std::map<std::string, std::string> rows;  // constant -> value cell
  while (std::getline(in, line)) {
    if (line.rfind("## ", 0) == 0) in_limits = line == "## Limits";
    if (!in_limits || line.rfind("| ", 0) != 0 || line.rfind("| limit ", 0) == 0) continue;
    auto c = cells(line);
    ASSERT_GE(c.size(), 4u) << line;
    std::smatch m;
    ASSERT_TRUE(std::regex_search(c[2], m, std::regex("`([^`]+)`"))) << "no constant named in: " << line;
    rows[m[1]] = c[1];
  }
  for (const auto& [name, value] : code) {
    auto row = rows.find(name);
    ASSERT_NE(row, rows.end()) << name << " is not in proto/README.md's limits table";
    bool found = false;
    const std::regex number("[0-9]+(\\.[0-9]+)?");
    for (auto it = std::sregex_iterator(row->second.begin(), row->second.end(), number); it != std::sregex_iterator();
         ++it) {
      if (std::abs(std::stod(it->str()) - value) <= 1e-9 * std::max(1.0, std::abs(value))) found = true;
    }
    EXPECT_TRUE(found) << "proto/README.md says '" << row->second << "' for " << name << ", the code " << value;
  }
  for (const auto& [name, value] : rows) {
    EXPECT_TRUE(code.count(name)) << "the README's limit " << name << " is not checked against the code here";
  }
}

namespace {

namespace pb = veneer::v1;

std::string repeat(const std::string& s, int n) {
  std::string out;
  for (int i = 0; i < n; ++i) out += s;
  return out;
}

const std::string kE = "\xC3\xA9";           // U+00E9, 2 bytes
const std::string kEmoji = "\xF0\x9F\x93\xB7";  // U+1F4F7, 4 bytes
const std::string kNotUtf8 = "caf\xC3";       // cut short after the lead byte

veneer::Expected<veneerd::api::Request> decode_hello_name(const std::string& name) {
  pb::ClientMessage m;
  m.set_id(1);
  m.mutable_hello()->set_protocol_version(veneer::wire::kProtocolVersion);
  m.mutable_hello()->set_client_name(name);
  return veneerd::api::decode(m);
}

veneer::Expected<veneerd::api::Request> decode_object(const std::string& object) {
  pb::ClientMessage m;
  m.set_id(2);
  m.mutable_capture()->set_object(object);
  return veneerd::api::decode(m);
}

// A rig in this process on loopback (simulated, small frames).
struct Rig {
  std::filesystem::path dir = rigtest::temp_dir("contract");
  std::unique_ptr<veneerd::Daemon> daemon;
  Rig() {
    veneerd::DaemonOptions o;
    o.simulate = true;
    o.size = {64, 43};
    o.noise_sigma = 0;
    o.listen = "127.0.0.1:0";
    o.store = dir / "store";
    auto d = veneerd::Daemon::create(o);
    if (!d) {
      ADD_FAILURE() << d.message();
      return;
    }
    daemon = std::move(*d);
    if (auto st = daemon->start(); !st) ADD_FAILURE() << st.message();
  }
  ~Rig() {
    daemon.reset();
    std::filesystem::remove_all(dir);
  }
  uint16_t port() const { return daemon->port(); }
};

pb::ClientMessage hello(uint64_t id, uint32_t version, const std::string& token, const std::string& name = "contract") {
  pb::ClientMessage m;
  m.set_id(id);
  m.mutable_hello()->set_protocol_version(version);
  m.mutable_hello()->set_token(token);
  m.mutable_hello()->set_client_name(name);
  return m;
}

// The messages up to and including response `id` and, after it, up to the
// first event matching `kind` (within the timeout); the event's position and
// the response's position in what arrived.
struct Order {
  int response_at = -1;
  int event_at = -1;
};
Order order_of(rigtest::RawConnection& c, uint64_t id, pb::Event::KindCase kind, double timeout_s = 20) {
  Order o;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  for (int i = 0; (o.response_at < 0 || o.event_at < 0) && std::chrono::steady_clock::now() < deadline; ++i) {
    auto m = c.next(1);
    if (!m) continue;
    if (m->has_response() && m->response().id() == id && o.response_at < 0) o.response_at = i;
    if (m->has_event() && m->event().kind_case() == kind && o.event_at < 0) o.event_at = i;
  }
  return o;
}

}  // namespace

TEST(ApiContract, NameLimitsCountCharactersNotBytes) {
  namespace api = veneerd::api;
  // 128 two-byte characters (256 bytes) are within the limit of 128 characters.
  auto fits = decode_hello_name(repeat(kE, 128));
  EXPECT_TRUE(fits) << fits.message();
  auto over = decode_hello_name(repeat(kE, 129));
  ASSERT_FALSE(over);
  EXPECT_EQ(over.message(), "hello.client_name: 129 characters is longer than the limit of 128");
  EXPECT_TRUE(decode_hello_name(repeat(kEmoji, 128))) << "a 4-byte character is one character";

  auto object = decode_object(repeat(kE, api::kMaxObjectChars));
  EXPECT_TRUE(object) << object.message();
  auto long_object = decode_object(repeat(kE, api::kMaxObjectChars + 1));
  ASSERT_FALSE(long_object);
  EXPECT_EQ(long_object.message(), "capture.object: 65 characters is longer than the limit of 64");
  // Printable means no C0, DEL or C1 control character, counted as characters too.
  auto c1 = decode_object("lamp\xC2\x85post");  // U+0085 NEXT LINE
  ASSERT_FALSE(c1);
  EXPECT_EQ(c1.message(), "capture.object: must be printable (no control characters)");
  // Bytes that are not UTF-8 are refused by name wherever they come from.
  auto bad = decode_hello_name(kNotUtf8);
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.message(), "hello.client_name: not valid UTF-8 (every string field is UTF-8)");

  EXPECT_EQ(veneer::wire::utf8_length(repeat(kE, 3) + kEmoji), 4u);
  for (const char* invalid : {"\xC0\xAF", "\xED\xA0\x80", "\xF4\x90\x80\x80", "\x80", "\xE2\x82"})
    EXPECT_FALSE(veneer::wire::utf8_length(invalid)) << "overlong, surrogate, above U+10FFFF, stray or cut short";
}

TEST(ApiContract, StringsThatAreNotUtf8AreRefusedNamingTheField) {
  Rig rig;
  ASSERT_TRUE(rig.daemon);
  {  // Before hello: a refused hello, closed.
    rigtest::RawConnection c(rig.port());
    ASSERT_TRUE(c.send(hello(7, veneer::wire::kProtocolVersion, rig.daemon->token(), kNotUtf8)));
    auto r = c.next_response(7);
    ASSERT_TRUE(r);
    EXPECT_FALSE(r->ok());
    EXPECT_EQ(r->error(), "hello refused: hello.client_name: not valid UTF-8 (every string field is UTF-8)");
    EXPECT_TRUE(c.closed_by_peer());
  }
  {  // After hello: the request is refused, the connection stays open.
    rigtest::RawConnection c(rig.port());
    ASSERT_TRUE(c.hello(rig.daemon->token()));
    pb::ClientMessage capture;
    capture.set_id(8);
    capture.mutable_capture()->set_object(kNotUtf8);
    ASSERT_TRUE(c.send(capture));
    auto r = c.next_response(8);
    ASSERT_TRUE(r);
    EXPECT_FALSE(r->ok());
    EXPECT_EQ(r->error(), "capture.object: not valid UTF-8 (every string field is UTF-8)");
    pb::ClientMessage status;
    status.set_id(9);
    status.mutable_status();
    ASSERT_TRUE(c.send(status));
    auto s = c.next_response(9);
    ASSERT_TRUE(s) << "the connection was closed after a refused request";
    EXPECT_TRUE(s->ok());
    EXPECT_FALSE(s->status().capturing()) << "the refused capture did not start";
  }
}

TEST(ApiContract, AResponseComesBeforeTheEventsItCauses) {
  Rig rig;
  ASSERT_TRUE(rig.daemon);
  rigtest::RawConnection c(rig.port());
  ASSERT_TRUE(c.hello(rig.daemon->token()));
  auto check = [&](pb::ClientMessage m, pb::Event::KindCase kind, const char* what) {
    ASSERT_TRUE(c.send(m));
    Order o = order_of(c, m.id(), kind);
    ASSERT_GE(o.response_at, 0) << what << ": no response";
    ASSERT_GE(o.event_at, 0) << what << ": no event";
    EXPECT_LT(o.response_at, o.event_at) << what << ": the event came before the response";
  };
  pb::ClientMessage lamps;
  lamps.set_id(10);
  lamps.mutable_set_lamps()->add_on(true);
  check(lamps, pb::Event::kLampState, "set_lamps");

  pb::ClientMessage capture;
  capture.set_id(11);
  capture.mutable_capture()->set_object("contract");
  check(capture, pb::Event::kCaptureStarted, "capture");
  std::string set_id;
  for (int i = 0; i < 200 && set_id.empty(); ++i) {
    auto m = c.next(1);
    if (m && m->has_event() && m->event().has_set_stored()) set_id = m->event().set_stored().id();
    if (m && m->has_event() && m->event().has_capture_failed()) FAIL() << m->event().capture_failed().reason();
  }
  ASSERT_FALSE(set_id.empty()) << "the capture was not stored";

  pb::ClientMessage del;
  del.set_id(12);
  del.mutable_delete_set()->set_set_id(set_id);
  check(del, pb::Event::kSetDeleted, "delete_set");
  pb::ClientMessage restore;
  restore.set_id(13);
  restore.mutable_restore_set()->set_set_id(set_id);
  check(restore, pb::Event::kSetRestored, "restore_set");
  pb::ClientMessage press;
  press.set_id(14);
  press.mutable_press_button()->set_long_press(true);  // long: cancels, nothing to cancel here
  check(press, pb::Event::kButtonPressed, "press_button");
}

TEST(ApiContract, TheHellosStatusCarriesTheEventSeq) {
  Rig rig;
  ASSERT_TRUE(rig.daemon);
  rigtest::RawConnection a(rig.port());
  ASSERT_TRUE(a.hello(rig.daemon->token()));
  pb::ClientMessage lamps;
  lamps.set_id(20);
  lamps.mutable_set_lamps()->add_on(true);
  ASSERT_TRUE(a.send(lamps));
  uint64_t last = 0;
  for (int i = 0; i < 50 && last == 0; ++i) {
    auto m = a.next(1);
    if (m && m->has_event() && m->event().has_lamp_state()) last = m->event().seq();
  }
  ASSERT_GT(last, 0u);

  rigtest::RawConnection b(rig.port());
  ASSERT_TRUE(b.send(hello(21, veneer::wire::kProtocolVersion, rig.daemon->token())));
  auto r = b.next_response(21);
  ASSERT_TRUE(r && r->ok());
  EXPECT_EQ(r->status().event_seq(), last) << "the last event before the hello";
  // The next event b receives is numbered one above.
  lamps.set_id(22);
  lamps.mutable_set_lamps()->set_on(0, false);
  ASSERT_TRUE(a.send(lamps));
  std::optional<uint64_t> next;
  for (int i = 0; i < 50 && !next; ++i) {
    auto m = b.next(1);
    if (m && m->has_event()) next = m->event().seq();
  }
  ASSERT_TRUE(next);
  EXPECT_EQ(*next, r->status().event_seq() + 1);
  pb::ClientMessage status;
  status.set_id(23);
  status.mutable_status();
  ASSERT_TRUE(b.send(status));
  auto s = b.next_response(23);
  ASSERT_TRUE(s && s->ok());
  EXPECT_EQ(s->status().event_seq(), *next) << "a status request carries it too";
}

TEST(ApiContract, RefusalsOfAHelloWithSeveralFaultsComeInTheContractsOrder) {
  Rig rig;
  ASSERT_TRUE(rig.daemon);
  auto refusal = [&](const pb::ClientMessage& m) -> std::string {
    rigtest::RawConnection c(rig.port());
    if (!c.send(m)) return "(not sent)";
    auto r = c.next_response(m.id());
    if (!r) return "(no answer)";
    EXPECT_TRUE(c.closed_by_peer()) << "a refused hello closes the connection";
    return r->error();
  };
  const std::string wrong = "not-the-token";
  // (1) field limits before (2) the version.
  EXPECT_EQ(refusal(hello(30, 2, wrong, repeat(kE, 129))),
            "hello refused: hello.client_name: 129 characters is longer than the limit of 128");
  // (2) the version before (4) the token: not counted as a wrong token.
  EXPECT_EQ(refusal(hello(31, 2, wrong)), "hello: protocol version 2 is not supported (the rig speaks 1)");
  EXPECT_EQ(refusal(hello(32, 0, "")), "hello: protocol version 0 is not supported (the rig speaks 1)");
  EXPECT_EQ(rig.daemon->server().stats().wrong_tokens, 0u);
  // (4) with the right version, the token.
  EXPECT_EQ(refusal(hello(33, veneer::wire::kProtocolVersion, wrong)), "hello: wrong access token");
  EXPECT_EQ(rig.daemon->server().stats().wrong_tokens, 1u);
}

TEST(ApiContract, TheReadmeStatesTheseRules) {
  std::ifstream in(VENEER_SOURCE_DIR "/proto/README.md");
  std::stringstream text;
  text << in.rdbuf();
  const std::string readme = text.str();
  for (const char* promise : {"**Characters are Unicode code points**", "**A request's response comes before the events it causes**",
                              "**Which refusal wins**", "`RigStatus.event_seq`", "not valid UTF-8"})
    EXPECT_NE(readme.find(promise), std::string::npos) << "proto/README.md no longer says " << promise;
}
