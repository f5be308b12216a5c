// Issue 43: the rig API encrypted and authenticated. The rig's identity (key
// and self-signed certificate), fingerprints and the known-rigs file; then
// the real veneerd on loopback: TLS 1.3 only, a client refuses a certificate
// other than the pinned one naming both fingerprints (and sends nothing), a
// client without the token gets nothing but the refusal, plain TCP only when
// configured and said so in the status and the log.
#include <gtest/gtest.h>

#include <sys/stat.h>

#include <fstream>

#include <openssl/ssl.h>

#include "rig_test_util.hpp"
#include "veneer/proto/tls.hpp"
#include "veneer/rig/client.hpp"

namespace fs = std::filesystem;
namespace tls = veneer::tls;
using rigtest::DaemonProcess;

namespace {

const std::vector<std::string> kSmall = {"--size", "64x43", "--noise", "0"};
const std::string kOther = "AA:BB:CC:DD:EE:FF:00:11:22:33:44:55:66:77:88:99:AA:BB:CC:DD:EE:FF:00:11:22:33:44:55:66:77:88:99";

unsigned mode_of(const fs::path& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0 ? (st.st_mode & 0777) : 0;
}

std::string read_all(const fs::path& p) {
  std::ifstream in(p);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

}  // namespace

TEST(Tls, FingerprintsAreParsedAndWrittenOneWay) {
  const std::string canonical = "69:7B:EE:D8:1B:05:31:38:2B:41:E9:A3:73:F0:29:D0:60:0D:DA:B2:27:55:A5:6A:B7:54:33:FA:FC:80:BE:19";
  auto a = tls::parse_fingerprint("697beed81b0531382b41e9a373f029d0600ddab22755a56ab75433fafc80be19");
  ASSERT_TRUE(a) << a.message();
  EXPECT_EQ(*a, canonical);
  auto b = tls::parse_fingerprint(canonical);
  ASSERT_TRUE(b);
  EXPECT_EQ(*b, canonical);
  auto short_one = tls::parse_fingerprint(canonical.substr(0, 94));  // the last digit missing
  ASSERT_FALSE(short_one);
  EXPECT_NE(short_one.message().find("63 hex digits, expected 64"), std::string::npos) << short_one.message();
  auto bad = tls::parse_fingerprint("zz" + canonical.substr(2));
  ASSERT_FALSE(bad);
  EXPECT_NE(bad.message().find("'z' is not a hex digit"), std::string::npos) << bad.message();
  // SHA-256 of "abc" (FIPS 180-2's example), as pairs.
  const unsigned char abc[] = {'a', 'b', 'c'};
  EXPECT_EQ(tls::fingerprint_of_der(abc, 3),
            "BA:78:16:BF:8F:01:CF:EA:41:41:40:DE:5D:AE:22:23:B0:03:61:A3:96:17:7A:9C:B4:10:FF:61:F2:00:15:AD");
}

TEST(Tls, TheIdentityIsMadeOnceKeptAndNeverReplacedSilently) {
  fs::path dir = rigtest::temp_dir("tls-identity");
  auto first = tls::ensure_identity(dir / "k.pem", dir / "c.pem", "shelf rig");
  ASSERT_TRUE(first) << first.message();
  EXPECT_TRUE(first->created);
  EXPECT_EQ(mode_of(dir / "k.pem"), 0600u);
  EXPECT_EQ(mode_of(dir / "c.pem"), 0600u);
  for (const auto& e : fs::directory_iterator(dir)) {  // no temporary left beside them
    EXPECT_TRUE(e.path().filename() == "k.pem" || e.path().filename() == "c.pem") << e.path();
  }
  auto again = tls::ensure_identity(dir / "k.pem", dir / "c.pem", "shelf rig");
  ASSERT_TRUE(again) << again.message();
  EXPECT_FALSE(again->created);
  EXPECT_EQ(again->fingerprint, first->fingerprint);
  auto from_file = tls::fingerprint_of_cert_file(dir / "c.pem");
  ASSERT_TRUE(from_file);
  EXPECT_EQ(*from_file, first->fingerprint);

  // A certificate without its key: an error naming both, nothing made.
  fs::remove(dir / "k.pem");
  auto orphan = tls::ensure_identity(dir / "k.pem", dir / "c.pem", "shelf rig");
  ASSERT_FALSE(orphan);
  EXPECT_NE(orphan.message().find((dir / "k.pem").string()), std::string::npos) << orphan.message();
  EXPECT_FALSE(fs::exists(dir / "k.pem"));
  // Another rig's certificate beside this key: refused, not replaced.
  auto other = tls::ensure_identity(dir / "k2.pem", dir / "c2.pem", "other");
  ASSERT_TRUE(other);
  fs::copy_file(dir / "c.pem", dir / "c3.pem");
  auto mismatch = tls::ensure_identity(dir / "k2.pem", dir / "c3.pem", "other");
  ASSERT_FALSE(mismatch);
  EXPECT_NE(mismatch.message().find("does not belong to the key"), std::string::npos) << mismatch.message();
  fs::remove_all(dir);
}

TEST(Tls, TheKnownRigsFileKeepsOneLinePerRig) {
  fs::path dir = rigtest::temp_dir("tls-known");
  const fs::path file = dir / "sub" / "known_rigs";
  auto none = tls::known_fingerprint(file, "10.0.0.2:7878");
  ASSERT_TRUE(none);
  EXPECT_EQ(*none, "");
  ASSERT_TRUE(tls::remember_fingerprint(file, "10.0.0.2:7878", kOther).ok());
  const std::string fp2 = "11" + kOther.substr(2);
  ASSERT_TRUE(tls::remember_fingerprint(file, "[fe80::1]:7878", fp2).ok());
  ASSERT_TRUE(tls::remember_fingerprint(file, "10.0.0.2:7878", fp2).ok());  // replaced, not added
  EXPECT_EQ(*tls::known_fingerprint(file, "10.0.0.2:7878"), fp2);
  EXPECT_EQ(*tls::known_fingerprint(file, "[fe80::1]:7878"), fp2);
  const std::string text = read_all(file);
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 3) << text;  // the comment and two rigs
  EXPECT_FALSE(tls::remember_fingerprint(file, "a rig", kOther).ok());
  // A malformed line of the rig asked for is an error naming the file and line.
  std::ofstream(file, std::ios::app) << "10.0.0.3:7878 nonsense\n";
  auto broken = tls::known_fingerprint(file, "10.0.0.3:7878");
  ASSERT_FALSE(broken);
  EXPECT_NE(broken.message().find(file.string() + ":4"), std::string::npos) << broken.message();
  fs::remove_all(dir);
}

// (1) A certificate other than the pinned one: the client stops before the
// hello, naming both fingerprints; the rig never sees a hello.
TEST(Tls, AChangedCertificateIsRefusedNamingBothFingerprints) {
  fs::path dir = rigtest::temp_dir("tls-changed");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, kSmall);
  ASSERT_TRUE(d && d->port()) << (d ? d->log() : "");
  const std::string seen = rigtest::rig_fingerprint(store);
  ASSERT_FALSE(seen.empty());
  auto token = veneer::rig::read_token_file(store / "token");
  ASSERT_TRUE(token);

  veneer::rig::ConnectOptions o;
  o.fingerprint = kOther;
  auto c = veneer::rig::Client::connect({"127.0.0.1", d->port()}, *token, o);
  ASSERT_FALSE(c);
  EXPECT_NE(c.message().find("expected fingerprint " + kOther), std::string::npos) << c.message();
  EXPECT_NE(c.message().find("the rig presented " + seen), std::string::npos) << c.message();

  // Pinned in the known-rigs file: the same.
  const fs::path known = dir / "known_rigs";
  ASSERT_TRUE(tls::remember_fingerprint(known, "127.0.0.1:" + std::to_string(d->port()), kOther).ok());
  veneer::rig::ConnectOptions k;
  k.known_rigs = known;
  bool asked = false;
  k.confirm_first_use = [&](const std::string&, const std::string&) { return asked = true; };
  c = veneer::rig::Client::connect({"127.0.0.1", d->port()}, *token, k);
  ASSERT_FALSE(c);
  EXPECT_NE(c.message().find(kOther), std::string::npos) << c.message();
  EXPECT_NE(c.message().find(seen), std::string::npos) << c.message();
  EXPECT_NE(c.message().find("pinned in " + known.string()), std::string::npos) << c.message();
  EXPECT_FALSE(asked) << "a changed certificate is refused, never asked about";
  EXPECT_EQ(*tls::known_fingerprint(known, "127.0.0.1:" + std::to_string(d->port())), kOther);

  // Nothing reached the rig's API: no hello was made.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_EQ(d->full_log().find("hello from"), std::string::npos) << d->log();

  // The right one connects; the client says which it saw.
  o.fingerprint = seen;
  c = veneer::rig::Client::connect({"127.0.0.1", d->port()}, *token, o);
  ASSERT_TRUE(c) << c.message();
  EXPECT_EQ((*c)->fingerprint(), seen);
  EXPECT_FALSE((*c)->hello_status().plain_tcp);
  fs::remove_all(dir);
}

TEST(Tls, FirstUseIsAskedAndPinnedAndNothingUnpinnedLeavesLoopbackTrust) {
  fs::path dir = rigtest::temp_dir("tls-first");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, kSmall);
  ASSERT_TRUE(d && d->port()) << (d ? d->log() : "");
  const std::string seen = rigtest::rig_fingerprint(store);
  auto token = veneer::rig::read_token_file(store / "token");
  ASSERT_TRUE(token);
  const std::string rig = "127.0.0.1:" + std::to_string(d->port());

  veneer::rig::ConnectOptions o;
  o.trust_loopback = false;
  auto c = veneer::rig::Client::connect({"127.0.0.1", d->port()}, *token, o);
  ASSERT_FALSE(c);
  EXPECT_NE(c.message().find(seen + " is not pinned"), std::string::npos) << c.message();

  o.known_rigs = dir / "known_rigs";
  std::string asked_rig, asked_fp;
  o.confirm_first_use = [&](const std::string& r, const std::string& f) {
    asked_rig = r;
    asked_fp = f;
    return false;
  };
  c = veneer::rig::Client::connect({"127.0.0.1", d->port()}, *token, o);
  ASSERT_FALSE(c);
  EXPECT_EQ(asked_rig, rig);
  EXPECT_EQ(asked_fp, seen);
  EXPECT_FALSE(fs::exists(o.known_rigs));

  o.confirm_first_use = [&](const std::string&, const std::string&) { return true; };
  c = veneer::rig::Client::connect({"127.0.0.1", d->port()}, *token, o);
  ASSERT_TRUE(c) << c.message();
  EXPECT_EQ(*tls::known_fingerprint(o.known_rigs, rig), seen);
  // The library's default (nothing pinned, nobody to ask) takes a rig on loopback only.
  c = veneer::rig::Client::connect({"127.0.0.1", d->port()}, *token);
  EXPECT_TRUE(c) << c.message();
  fs::remove_all(dir);
}

// (2) Without the token: the refusal and nothing else, then the end.
TEST(Tls, AClientWithoutTheTokenGetsNothingButTheRefusal) {
  fs::path dir = rigtest::temp_dir("tls-token");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, kSmall);
  ASSERT_TRUE(d && d->port()) << (d ? d->log() : "");
  namespace pb = veneer::v1;
  auto only_refusal = [&](const pb::ClientMessage& first, const pb::ClientMessage& second, const std::string& error) {
    rigtest::RawConnection c(d->port());
    ASSERT_TRUE(c.ok());
    ASSERT_TRUE(c.send(first));
    c.send(second);  // pipelined behind it: must not be served
    auto m = c.next(5);
    ASSERT_TRUE(m);
    ASSERT_TRUE(m->has_response());
    EXPECT_FALSE(m->response().ok());
    EXPECT_EQ(m->response().error(), error);
    EXPECT_FALSE(m->response().has_status());
    EXPECT_FALSE(m->response().has_sets());
    EXPECT_FALSE(c.next(1)) << "a second message after the refusal";
    EXPECT_TRUE(c.closed_by_peer(5));
  };
  pb::ClientMessage no_token;
  no_token.set_id(1);
  no_token.mutable_hello()->set_protocol_version(veneer::wire::kProtocolVersion);
  pb::ClientMessage list;
  list.set_id(2);
  list.mutable_list_sets();
  only_refusal(no_token, list, "hello: no access token given");
  pb::ClientMessage wrong = no_token;
  wrong.mutable_hello()->set_token(std::string(64, '0'));
  only_refusal(wrong, list, "hello: wrong access token");
  pb::ClientMessage status_first;
  status_first.set_id(7);
  status_first.mutable_status();
  only_refusal(status_first, list, "the first request must be a hello with the protocol version and token");

  // The library client too: no token, no connection, the rig's reason.
  auto c = veneer::rig::Client::connect({"127.0.0.1", d->port()}, "");
  ASSERT_FALSE(c);
  EXPECT_NE(c.message().find("hello: no access token given"), std::string::npos) << c.message();
  fs::remove_all(dir);
}

// TLS 1.3 only: a client offering at most TLS 1.2 gets no connection, nor
// does a client speaking the protocol in clear to a TLS rig.
TEST(Tls, TheRigSpeaksTls13AndNothingElse) {
  fs::path dir = rigtest::temp_dir("tls-version");
  fs::path store = dir / "store";
  auto d = DaemonProcess::start(store, kSmall);
  ASSERT_TRUE(d && d->port()) << (d ? d->log() : "");
  {
    SSL_CTX* ctx = SSL_CTX_new(TLS_client_method());
    SSL_CTX_set_max_proto_version(ctx, TLS1_2_VERSION);
    int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(d->port());
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    SSL* ssl = SSL_new(ctx);
    SSL_set_fd(ssl, fd);
    EXPECT_NE(SSL_connect(ssl), 1) << "a TLS 1.2 handshake succeeded";
    SSL_free(ssl);
    ::close(fd);
    SSL_CTX_free(ctx);
  }
  {  // The protocol in clear: no answer, the connection closed.
    rigtest::RawConnection plain(d->port(), 0, /*tls=*/false);
    ASSERT_TRUE(plain.ok());
    veneer::v1::ClientMessage m;
    m.set_id(1);
    m.mutable_hello()->set_protocol_version(veneer::wire::kProtocolVersion);
    m.mutable_hello()->set_token(*veneer::rig::read_token_file(store / "token"));
    plain.send(m);
    EXPECT_FALSE(plain.next(3));
    EXPECT_TRUE(plain.closed_by_peer(5));
  }
  veneer::rig::ConnectOptions o;
  o.plain_tcp = true;
  auto c = veneer::rig::Client::connect({"127.0.0.1", d->port()}, *veneer::rig::read_token_file(store / "token"), o);
  ASSERT_FALSE(c);
  EXPECT_NE(c.message().find("connect without --plain-tcp"), std::string::npos) << c.message();
  EXPECT_EQ(d->full_log().find("hello from"), std::string::npos) << d->log();
  fs::remove_all(dir);
}

TEST(Tls, PlainTcpOnlyWhenConfiguredAndSaidSo) {
  fs::path dir = rigtest::temp_dir("tls-plain");
  fs::path store = dir / "store";
  auto extra = kSmall;
  extra.push_back("--plain-tcp");
  auto d = DaemonProcess::start(store, extra);
  ASSERT_TRUE(d && d->port()) << (d ? d->log() : "");
  auto token = veneer::rig::read_token_file(store / "token");
  ASSERT_TRUE(token);
  EXPECT_FALSE(fs::exists(store.string() + ".tls")) << "no key is made for a plain rig";
  veneer::rig::ConnectOptions o;
  o.plain_tcp = true;
  auto c = veneer::rig::Client::connect({"127.0.0.1", d->port()}, *token, o);
  ASSERT_TRUE(c) << c.message();
  EXPECT_TRUE((*c)->hello_status().plain_tcp);
  EXPECT_EQ((*c)->fingerprint(), "");
  auto s = (*c)->status();
  ASSERT_TRUE(s);
  EXPECT_TRUE(s->plain_tcp);
  EXPECT_NE(d->full_log().find("PLAIN TCP"), std::string::npos) << d->log();
  // A TLS client is not downgraded: it fails.
  auto t = veneer::rig::Client::connect({"127.0.0.1", d->port()}, *token);
  ASSERT_FALSE(t);
  EXPECT_NE(t.message().find("TLS 1.3 handshake failed"), std::string::npos) << t.message();
  fs::remove_all(dir);
}
