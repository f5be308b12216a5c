// The emulator's HTTP/1.1 request parser: framing, limits, malformed input.
#include <gtest/gtest.h>

#include "veneerd/sim/http_request.hpp"

using veneerd::HttpRequestParser;
using State = HttpRequestParser::State;

TEST(HttpRequest, ParsesGetWithHeaders) {
  HttpRequestParser p;
  ASSERT_EQ(p.feed("GET /api/key/lights HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Thing:  v a l \r\n\r\n"), State::complete);
  auto r = p.take();
  EXPECT_EQ(r.method, "GET");
  EXPECT_EQ(r.target, "/api/key/lights");
  EXPECT_EQ(r.version, "HTTP/1.1");
  EXPECT_EQ(r.header("host"), "127.0.0.1");
  EXPECT_EQ(r.header("x-thing"), "v a l");
  EXPECT_TRUE(r.keep_alive());
  EXPECT_TRUE(r.body.empty());
  EXPECT_EQ(p.state(), State::need_more);
}

TEST(HttpRequest, BodyArrivingByteByByte) {
  const std::string req = "PUT /api/k/lights/1/state HTTP/1.1\r\nContent-Length: 11\r\nConnection: close\r\n\r\n{\"on\":true}";
  HttpRequestParser p;
  for (std::size_t i = 0; i + 1 < req.size(); ++i) ASSERT_EQ(p.feed(req.substr(i, 1)), State::need_more) << i;
  ASSERT_EQ(p.feed(req.substr(req.size() - 1)), State::complete);
  auto r = p.take();
  EXPECT_EQ(r.body, "{\"on\":true}");
  EXPECT_FALSE(r.keep_alive());
}

TEST(HttpRequest, PipelinedRequestsStayBuffered) {
  HttpRequestParser p;
  ASSERT_EQ(p.feed("GET /a HTTP/1.1\r\n\r\nPUT /b HTTP/1.1\r\nContent-Length: 2\r\n\r\nhiGET /c HTTP/1.0\r\n\r\n"),
            State::complete);
  EXPECT_EQ(p.take().target, "/a");
  ASSERT_EQ(p.state(), State::complete);
  auto b = p.take();
  EXPECT_EQ(b.target, "/b");
  EXPECT_EQ(b.body, "hi");
  ASSERT_EQ(p.state(), State::complete);
  auto c = p.take();
  EXPECT_EQ(c.target, "/c");
  EXPECT_FALSE(c.keep_alive());  // HTTP/1.0 without keep-alive
  EXPECT_EQ(p.state(), State::need_more);
}

struct BadCase {
  std::string input;
  int status;
};

TEST(HttpRequest, RejectsMalformedAndOversized) {
  veneerd::HttpLimits limits;
  const std::vector<BadCase> cases = {
      {"GARBAGE\r\n\r\n", 400},
      {"GET  /a HTTP/1.1\r\n\r\n", 400},
      {"GET a HTTP/1.1\r\n\r\n", 400},
      {"G(T /a HTTP/1.1\r\n\r\n", 400},
      {"GET /a HTTP/2.0\r\n\r\n", 505},
      {"GET /a HTTQ/1.1\r\n\r\n", 400},
      {"GET /a HTTP/1.1\r\nNoColon\r\n\r\n", 400},
      {"GET /a HTTP/1.1\r\n folded: x\r\n\r\n", 400},
      {"GET /a HTTP/1.1\r\nBad Name: x\r\n\r\n", 400},
      {"PUT /a HTTP/1.1\r\n\r\n", 411},
      {"PUT /a HTTP/1.1\r\nContent-Length: -1\r\n\r\n", 400},
      {"PUT /a HTTP/1.1\r\nContent-Length: 12abc\r\n\r\n", 400},
      {"PUT /a HTTP/1.1\r\nContent-Length: 99999999999999999999999\r\n\r\n", 400},
      {"PUT /a HTTP/1.1\r\nContent-Length: 2\r\nContent-Length: 3\r\n\r\n", 400},
      {"PUT /a HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n", 501},
      {"PUT /a HTTP/1.1\r\nContent-Length: 70000\r\n\r\n", 413},
      {"GET /" + std::string(limits.max_request_line, 'a') + " HTTP/1.1\r\n\r\n", 414},
      {"GET /a HTTP/1.1\r\nX: " + std::string(limits.max_header_bytes, 'b') + "\r\n\r\n", 431},
  };
  for (const auto& c : cases) {
    HttpRequestParser p;
    EXPECT_EQ(p.feed(c.input), State::error) << c.input.substr(0, 60);
    EXPECT_EQ(p.error_status(), c.status) << c.input.substr(0, 60) << " -> " << p.error_reason();
    EXPECT_FALSE(p.error_reason().empty());
    // An errored parser stays errored.
    EXPECT_EQ(p.feed("GET / HTTP/1.1\r\n\r\n"), State::error);
  }
}

TEST(HttpRequest, TooManyHeaders) {
  std::string req = "GET /a HTTP/1.1\r\n";
  for (int i = 0; i < 70; ++i) {
    req += 'h';
    req += std::to_string(i);
    req += ": 1\r\n";
  }
  req += "\r\n";
  HttpRequestParser p;
  EXPECT_EQ(p.feed(req), State::error);
  EXPECT_EQ(p.error_status(), 431);
}

TEST(HttpRequest, EndlessHeaderWithoutTerminatorIsCutOff) {
  HttpRequestParser p;
  ASSERT_EQ(p.feed("GET /a HTTP/1.1\r\n"), State::need_more);
  State s = State::need_more;
  for (int i = 0; i < 100 && s == State::need_more; ++i) s = p.feed(std::string(1000, 'x'));
  EXPECT_EQ(s, State::error);
  EXPECT_EQ(p.error_status(), 431);
  EXPECT_LE(p.buffered(), 200000u);
}

TEST(HttpRequest, ResponseSerialization) {
  veneerd::HttpResponse r;
  r.status = 429;
  r.body = "[]";
  std::string s = r.serialize(true);
  EXPECT_EQ(s.rfind("HTTP/1.1 429 Too Many Requests\r\n", 0), 0u);
  EXPECT_NE(s.find("Content-Length: 2\r\n"), std::string::npos);
  EXPECT_NE(s.find("Retry-After: 1\r\n"), std::string::npos);
  EXPECT_NE(s.find("Connection: keep-alive\r\n"), std::string::npos);
  EXPECT_EQ(s.substr(s.size() - 6), "\r\n\r\n[]");
}
