#pragma once
// A small HTTP/1.1 request parser with hard size limits, for the Hue bridge
// emulator (it faces a socket, so it is fuzzed: tests/fuzz/hue_http.cpp).
// Incremental: feed() bytes as they arrive; a complete request is taken with
// take(); anything malformed or oversized is an error with the status to answer.
// No chunked bodies (411/501), no pipelining guarantees beyond "leftover bytes
// stay buffered for the next request".
#include <cstddef>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace veneerd {

struct HttpRequest {
  std::string method;   // "GET", "PUT", ...
  std::string target;   // "/api/key/lights" (query string kept)
  std::string version;  // "HTTP/1.1"
  std::vector<std::pair<std::string, std::string>> headers;  // names lower-cased
  std::string body;
  // Value of the first header `name` (lower case), or empty.
  std::string header(std::string_view name) const;
  bool keep_alive() const;  // HTTP/1.1 default yes unless "Connection: close"
};

struct HttpResponse {
  int status = 200;
  std::string body;
  std::string content_type = "application/json";
  bool close = false;                 // close the connection after this answer
  std::string serialize(bool keep_alive) const;
};

const char* http_reason(int status);

struct HttpLimits {
  std::size_t max_request_line = 2048;
  std::size_t max_header_bytes = 8192;  // all header lines together
  std::size_t max_headers = 64;
  std::size_t max_body = 65536;
};

class HttpRequestParser {
 public:
  enum class State { need_more, complete, error };
  explicit HttpRequestParser(HttpLimits limits = {}) : limits_(limits) {}

  // Appends bytes and parses as far as possible.
  State feed(std::string_view bytes);
  State state() const { return state_; }
  // After complete: the request; parsing continues with leftover bytes.
  HttpRequest take();
  // After error: the status to answer (400, 411, 413, 414, 431, 501, 505) and why.
  int error_status() const { return error_status_; }
  const std::string& error_reason() const { return error_reason_; }
  std::size_t buffered() const { return buffer_.size(); }

 private:
  State parse();
  State fail(int status, std::string reason);

  HttpLimits limits_;
  std::string buffer_;
  State state_ = State::need_more;
  HttpRequest current_;
  int error_status_ = 0;
  std::string error_reason_;
  std::size_t body_length_ = 0;
  bool head_done_ = false;
};

}  // namespace veneerd
