// The message reader and the wire-to-domain edge: what a client sends is
// checked, never trusted.
#include <gtest/gtest.h>

#include "veneer/proto/framing.hpp"
#include "veneer/v1/rig.pb.h"
#include "veneerd/api.hpp"

namespace pb = veneer::v1;
using veneer::wire::FrameBuffer;
using veneer::wire::ReadResult;

TEST(Framing, RoundTripsMessagesSplitAnywhere) {
  std::string stream;
  for (int i = 1; i <= 3; ++i) {
    pb::ClientMessage m;
    m.set_id(i);
    m.mutable_get_manifest()->set_set_id("set-" + std::to_string(i));
    ASSERT_TRUE(veneer::wire::append_delimited(m, stream));
  }
  // Feed one byte at a time: every prefix is either "need more" or a whole message.
  FrameBuffer in;
  std::vector<uint64_t> ids;
  for (char ch : stream) {
    in.feed(&ch, 1);
    pb::ClientMessage m;
    auto r = in.next(m);
    ASSERT_NE(r, ReadResult::error);
    if (r == ReadResult::message) ids.push_back(m.id());
  }
  EXPECT_EQ(ids, (std::vector<uint64_t>{1, 2, 3}));
  EXPECT_EQ(in.buffered(), 0u);
}

TEST(Framing, RefusesA4GiBLengthPrefixBeforeReadingIt) {
  // varint(2^32) = 80 80 80 80 10: refused at once, without waiting for 4 GiB.
  const unsigned char prefix[] = {0x80, 0x80, 0x80, 0x80, 0x10};
  FrameBuffer in;
  in.feed(prefix, sizeof prefix);
  pb::ClientMessage m;
  EXPECT_EQ(in.next(m), ReadResult::error);
  EXPECT_NE(in.error().find("exceeds the limit"), std::string::npos) << in.error();
}

TEST(Framing, RefusesJustOverTheLimitAndOverlongPrefixes) {
  FrameBuffer small(100);
  std::string bytes;
  pb::ClientMessage m;
  m.mutable_hello()->set_token(std::string(200, 'x'));
  veneer::wire::append_delimited(m, bytes);
  small.feed(bytes.data(), 3);  // prefix only
  pb::ClientMessage out;
  EXPECT_EQ(small.next(out), ReadResult::error);

  const unsigned char overlong[] = {0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x01};
  FrameBuffer in;
  in.feed(overlong, sizeof overlong);
  EXPECT_EQ(in.next(out), ReadResult::error);
}

// proto3 refuses a string field that is not UTF-8; the reader names the
// field, skips that message and goes on with the next.
TEST(Framing, AStringThatIsNotUtf8IsNamedAndSkipped) {
  std::string stream;
  pb::ClientMessage bad;
  bad.set_id(41);
  bad.mutable_capture()->set_object("caf\xC3");  // cut short: not UTF-8
  ASSERT_TRUE(veneer::wire::append_delimited(bad, stream));
  pb::ClientMessage good;
  good.set_id(42);
  good.mutable_status();
  ASSERT_TRUE(veneer::wire::append_delimited(good, stream));
  FrameBuffer in;
  in.feed(stream.data(), stream.size());
  pb::ClientMessage m;
  ASSERT_EQ(in.next(m), ReadResult::invalid);
  EXPECT_EQ(in.invalid().field, "capture.object");
  EXPECT_EQ(in.invalid().id, 41u);
  ASSERT_EQ(in.next(m), ReadResult::message) << in.error();
  EXPECT_EQ(m.id(), 42u);
  EXPECT_EQ(in.buffered(), 0u);
}

TEST(Framing, GarbageIsAnErrorNotACrash) {
  // A length of 5 followed by bytes that are not a ClientMessage (field 0 is invalid).
  const unsigned char garbage[] = {0x05, 0x00, 0xff, 0xff, 0xff, 0xff};
  FrameBuffer in;
  in.feed(garbage, sizeof garbage);
  pb::ClientMessage m;
  EXPECT_EQ(in.next(m), ReadResult::error);
  EXPECT_EQ(in.next(m), ReadResult::error);  // stays broken
}

TEST(Api, DecodesEveryRequestKind) {
  pb::ClientMessage m;
  m.set_id(7);
  m.mutable_capture()->set_role(pb::ROLE_SOURCE);
  m.mutable_capture()->set_object("stone");
  m.mutable_capture()->mutable_exposure()->set_shutter_s(0.25);
  auto r = veneerd::api::decode(m);
  ASSERT_TRUE(r) << r.message();
  EXPECT_EQ(r->id, 7u);
  auto* c = std::get_if<veneerd::api::CaptureReq>(&r->body);
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(c->capture.role, veneer::io::Role::source);
  EXPECT_EQ(c->capture.object, "stone");
  EXPECT_DOUBLE_EQ(c->capture.exposure.shutter_s, 0.25);
  EXPECT_TRUE(veneerd::api::needs_control(r->body));

  pb::ClientMessage s;
  s.mutable_status();
  auto rs = veneerd::api::decode(s);
  ASSERT_TRUE(rs);
  EXPECT_FALSE(veneerd::api::needs_control(rs->body));
}

TEST(Api, RefusesBadFieldsNamingThem) {
  struct Case {
    std::function<void(pb::ClientMessage&)> fill;
    std::string field;
  };
  std::vector<Case> cases = {
      {[](pb::ClientMessage& m) { m.mutable_fetch_images()->set_set_id("../../etc"); }, "fetch_images.set_id"},
      {[](pb::ClientMessage& m) { m.mutable_get_manifest()->set_set_id(""); }, "get_manifest.set_id"},
      {[](pb::ClientMessage& m) { m.mutable_delete_set()->set_set_id(".hidden"); }, "delete_set.set_id"},
      {[](pb::ClientMessage& m) { m.mutable_fetch_images()->set_set_id("a"); m.mutable_fetch_images()->set_chunk_size(1u << 30); }, "chunk_size"},
      {[](pb::ClientMessage& m) { m.mutable_capture()->mutable_exposure()->set_shutter_s(-1); }, "shutter_s"},
      {[](pb::ClientMessage& m) { m.mutable_capture()->mutable_exposure()->set_aperture(std::nan("")); }, "aperture"},
      {[](pb::ClientMessage& m) { m.mutable_capture()->set_role(static_cast<pb::Role>(9)); }, "capture.role"},
      {[](pb::ClientMessage& m) { m.mutable_capture()->set_object(std::string("a\nb")); }, "capture.object"},
      {[](pb::ClientMessage& m) { m.mutable_set_lamps()->set_brightness(999); }, "brightness"},
      {[](pb::ClientMessage& m) { for (int i = 0; i < 100; ++i) m.mutable_set_lamps()->add_on(true); }, "set_lamps.on"},
      {[](pb::ClientMessage& m) { m.mutable_start_live_view()->set_fps(1000); }, "fps"},
      {[](pb::ClientMessage& m) { m.mutable_move_hand_lamp()->mutable_position()->set_x(1e9); }, "position"},
      {[](pb::ClientMessage& m) { m.mutable_hello()->set_token(std::string(1000, 't')); }, "hello.token"},
      {[](pb::ClientMessage&) {}, "unknown or empty request"},
  };
  for (const auto& c : cases) {
    pb::ClientMessage m;
    m.set_id(3);
    c.fill(m);
    auto r = veneerd::api::decode(m);
    ASSERT_FALSE(r) << c.field;
    EXPECT_NE(r.message().find(c.field), std::string::npos) << r.message();
  }
}

TEST(Api, UnknownFieldsFromANewerClientAreAnEmptyRequest) {
  // Field 99 (length-delimited) is unknown to this version: parses, then refused.
  std::string raw;
  raw.push_back(0x08);  // id = 5
  raw.push_back(0x05);
  raw += std::string("\x9a\x06\x02hi", 5);  // field 99, wire type 2, "hi"
  pb::ClientMessage m;
  ASSERT_TRUE(m.ParseFromString(raw));
  auto r = veneerd::api::decode(m);
  ASSERT_FALSE(r);
  EXPECT_NE(r.message().find("unknown"), std::string::npos);
}

TEST(Api, ATooLongClientNameIsRefusedAsTooLongWithTheLimit) {
  pb::ClientMessage m;
  m.set_id(1);
  m.mutable_hello()->set_protocol_version(veneer::wire::kProtocolVersion);
  m.mutable_hello()->set_client_name(std::string(veneerd::api::kMaxClientNameChars + 1, 'n'));
  auto r = veneerd::api::decode(m);
  ASSERT_FALSE(r);
  EXPECT_NE(r.message().find("hello.client_name: 129 characters is longer than the limit of 128"), std::string::npos)
      << r.message();
  m.mutable_hello()->set_client_name(std::string(veneerd::api::kMaxClientNameChars, 'n'));
  EXPECT_TRUE(veneerd::api::decode(m));
  m.mutable_hello()->set_client_name("tab\there");
  r = veneerd::api::decode(m);
  ASSERT_FALSE(r);
  EXPECT_NE(r.message().find("printable"), std::string::npos) << r.message();
}

TEST(Api, TokensLoseSurroundingWhitespaceOnly) {
  using veneerd::api::trim_token;
  EXPECT_EQ(trim_token("abc\n"), "abc");
  EXPECT_EQ(trim_token("\r\n \tabc def\r\n"), "abc def");
  EXPECT_EQ(trim_token(" \n\t"), "");
  EXPECT_EQ(trim_token("abc"), "abc");
}

// The chunk written by hand around its data reads back as protobuf's own.
TEST(Api, EncodedChunksParseAsTheGeneratedMessage) {
  for (size_t size : {size_t{0}, size_t{1}, size_t{127}, size_t{128}, size_t{70000}, veneerd::api::kMaxChunkBytes}) {
    veneerd::api::ChunkHeader h;
    h.request_id = 300;
    h.set_id = "20261122-081530-destination-bull";
    h.file = "truth/normals.pfm";
    h.offset = 1ull << 33;
    h.file_size = (1ull << 33) + size;
    h.last = true;
    h.end_of_set = size % 2 == 0;
    std::string data(size, '\0');
    for (size_t i = 0; i < size; ++i) data[i] = static_cast<char>(i * 7 + 1);
    std::string out;
    ASSERT_TRUE(veneerd::api::encode_chunk(h, size, [&](char* dst, size_t n) {
      std::copy(data.begin(), data.begin() + static_cast<std::ptrdiff_t>(n), dst);
      return true;
    }, out));
    FrameBuffer in;
    in.feed(out.data(), out.size());
    pb::RigMessage m;
    ASSERT_EQ(in.next(m), ReadResult::message) << in.error();
    EXPECT_EQ(in.buffered(), 0u);
    ASSERT_TRUE(m.has_chunk());
    const auto& c = m.chunk();
    EXPECT_EQ(c.request_id(), 300u);
    EXPECT_EQ(c.set_id(), h.set_id);
    EXPECT_EQ(c.file(), h.file);
    EXPECT_EQ(c.offset(), h.offset);
    EXPECT_EQ(c.file_size(), h.file_size);
    EXPECT_TRUE(c.last());
    EXPECT_EQ(c.end_of_set(), h.end_of_set);
    EXPECT_TRUE(c.data() == data) << size;
    // Same size as protobuf's own encoding of it.
    pb::RigMessage ref;
    *ref.mutable_chunk() = c;
    EXPECT_EQ(veneer::wire::encode_delimited(ref).size(), out.size()) << size;
  }
  veneerd::api::ChunkHeader h;
  std::string out = "x";
  EXPECT_FALSE(veneerd::api::encode_chunk(h, 10, [](char*, size_t) { return false; }, out));
  EXPECT_TRUE(out.empty());
}
