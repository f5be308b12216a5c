#include "veneerd/sim/http_request.hpp"

#include <algorithm>
#include <cctype>
#include <charconv>

namespace veneerd {

namespace {

std::string lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

// RFC 9110 token characters (method, header names).
bool is_tchar(char c) {
  if (std::isalnum(static_cast<unsigned char>(c))) return true;
  switch (c) {
    case '!': case '#': case '$': case '%': case '&': case '\'': case '*': case '+':
    case '-': case '.': case '^': case '_': case '`': case '|': case '~':
      return true;
    default:
      return false;
  }
}

bool is_token(std::string_view s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), is_tchar);
}

// Visible ASCII only in the request target (no spaces, no controls).
bool is_target(std::string_view s) {
  if (s.empty() || s.front() != '/') return false;
  return std::all_of(s.begin(), s.end(), [](char c) {
    auto u = static_cast<unsigned char>(c);
    return u > 0x20 && u < 0x7f;
  });
}

bool has_ctl(std::string_view s) {
  return std::any_of(s.begin(), s.end(), [](char c) {
    auto u = static_cast<unsigned char>(c);
    return (u < 0x20 && c != '\t') || u == 0x7f;
  });
}

}  // namespace

std::string HttpRequest::header(std::string_view name) const {
  for (const auto& [n, v] : headers)
    if (n == name) return v;
  return {};
}

bool HttpRequest::keep_alive() const {
  std::string connection = lower(header("connection"));
  if (version == "HTTP/1.0") return connection.find("keep-alive") != std::string::npos;
  return connection.find("close") == std::string::npos;
}

const char* http_reason(int status) {
  switch (status) {
    case 200: return "OK";
    case 400: return "Bad Request";
    case 403: return "Forbidden";
    case 404: return "Not Found";
    case 405: return "Method Not Allowed";
    case 408: return "Request Timeout";
    case 411: return "Length Required";
    case 413: return "Content Too Large";
    case 414: return "URI Too Long";
    case 429: return "Too Many Requests";
    case 431: return "Request Header Fields Too Large";
    case 500: return "Internal Server Error";
    case 501: return "Not Implemented";
    case 503: return "Service Unavailable";
    case 505: return "HTTP Version Not Supported";
    default: return "Unknown";
  }
}

std::string HttpResponse::serialize(bool keep_alive) const {
  std::string out = "HTTP/1.1 " + std::to_string(status) + " " + http_reason(status) + "\r\n";
  out += "Content-Type: " + content_type + "\r\n";
  out += "Content-Length: " + std::to_string(body.size()) + "\r\n";
  if (status == 429 || status == 503) out += "Retry-After: 1\r\n";
  out += (keep_alive && !close) ? "Connection: keep-alive\r\n" : "Connection: close\r\n";
  out += "\r\n";
  out += body;
  return out;
}

HttpRequestParser::State HttpRequestParser::fail(int status, std::string reason) {
  state_ = State::error;
  error_status_ = status;
  error_reason_ = std::move(reason);
  return state_;
}

HttpRequestParser::State HttpRequestParser::feed(std::string_view bytes) {
  if (state_ == State::error) return state_;
  // Never buffer more than one maximal request (plus a little pipelining slack).
  const std::size_t cap = limits_.max_request_line + limits_.max_header_bytes + limits_.max_body + 4096;
  if (buffer_.size() + bytes.size() > cap) {
    // Take what fits; parse() reports the precise limit that was exceeded.
    buffer_.append(bytes.substr(0, cap - std::min(cap, buffer_.size())));
    State s = parse();
    if (s == State::need_more) return fail(413, "request larger than " + std::to_string(cap) + " bytes");
    return s;
  }
  buffer_.append(bytes);
  if (state_ == State::complete) return state_;  // caller must take() first
  return parse();
}

HttpRequest HttpRequestParser::take() {
  HttpRequest out = std::move(current_);
  current_ = HttpRequest{};
  head_done_ = false;
  body_length_ = 0;
  state_ = State::need_more;
  if (!buffer_.empty()) parse();
  return out;
}

HttpRequestParser::State HttpRequestParser::parse() {
  if (!head_done_) {
    // Tolerate empty lines before the request line (RFC 9112 2.2).
    while (buffer_.size() >= 2 && buffer_[0] == '\r' && buffer_[1] == '\n') buffer_.erase(0, 2);

    std::size_t line_end = buffer_.find("\r\n");
    if (line_end == std::string::npos) {
      if (buffer_.size() > limits_.max_request_line) return fail(414, "request line too long");
      return state_ = State::need_more;
    }
    if (line_end > limits_.max_request_line) return fail(414, "request line too long");

    std::size_t head_end = buffer_.find("\r\n\r\n");
    if (head_end == std::string::npos) {
      if (buffer_.size() - line_end > limits_.max_header_bytes + 2) return fail(431, "headers too large");
      return state_ = State::need_more;
    }
    if (head_end - line_end > limits_.max_header_bytes) return fail(431, "headers too large");

    std::string_view head(buffer_.data(), head_end);
    std::string_view line = head.substr(0, line_end);
    std::size_t sp1 = line.find(' ');
    std::size_t sp2 = sp1 == std::string_view::npos ? sp1 : line.find(' ', sp1 + 1);
    if (sp1 == std::string_view::npos || sp2 == std::string_view::npos ||
        line.find(' ', sp2 + 1) != std::string_view::npos)
      return fail(400, "malformed request line");
    std::string_view method = line.substr(0, sp1);
    std::string_view target = line.substr(sp1 + 1, sp2 - sp1 - 1);
    std::string_view version = line.substr(sp2 + 1);
    if (!is_token(method)) return fail(400, "malformed method");
    if (!is_target(target)) return fail(400, "malformed request target");
    if (version != "HTTP/1.1" && version != "HTTP/1.0") {
      if (version.size() == 8 && version.substr(0, 5) == "HTTP/") return fail(505, "unsupported HTTP version");
      return fail(400, "malformed HTTP version");
    }
    current_.method = std::string(method);
    current_.target = std::string(target);
    current_.version = std::string(version);

    // Header lines.
    std::size_t pos = line_end + 2;
    bool have_length = false;
    while (pos <= head.size()) {
      std::size_t end = head.find("\r\n", pos);
      if (end == std::string_view::npos) end = head.size();
      std::string_view h = head.substr(pos, end - pos);
      pos = end + 2;
      if (h.empty()) continue;
      if (h.front() == ' ' || h.front() == '\t') return fail(400, "obsolete header folding");
      std::size_t colon = h.find(':');
      if (colon == std::string_view::npos) return fail(400, "header without ':'");
      std::string_view name = h.substr(0, colon);
      if (!is_token(name)) return fail(400, "malformed header name");
      std::string_view value = trim(h.substr(colon + 1));
      if (has_ctl(value)) return fail(400, "control character in header value");
      if (current_.headers.size() >= limits_.max_headers) return fail(431, "too many headers");
      std::string lname = lower(name);
      if (lname == "content-length") {
        std::size_t n = 0;
        auto [ptr, ec] = std::from_chars(value.data(), value.data() + value.size(), n);
        if (value.empty() || ec != std::errc() || ptr != value.data() + value.size())
          return fail(400, "malformed Content-Length");
        if (have_length && n != body_length_) return fail(400, "conflicting Content-Length");
        have_length = true;
        body_length_ = n;
      } else if (lname == "transfer-encoding") {
        return fail(501, "Transfer-Encoding not supported");
      }
      current_.headers.emplace_back(std::move(lname), std::string(value));
    }
    if (body_length_ > limits_.max_body) return fail(413, "body larger than " + std::to_string(limits_.max_body));
    if (!have_length && (current_.method == "PUT" || current_.method == "POST"))
      return fail(411, "Content-Length required");
    buffer_.erase(0, head_end + 4);
    head_done_ = true;
  }
  if (buffer_.size() < body_length_) return state_ = State::need_more;
  current_.body = buffer_.substr(0, body_length_);
  buffer_.erase(0, body_length_);
  return state_ = State::complete;
}

}  // namespace veneerd
