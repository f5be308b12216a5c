#pragma once
// The one place that knows about libcurl (http_client.cpp), used by the Hue
// client (hue_lamps.cpp) and the Hue setup commands (hue_setup.cpp): a small
// pool of concurrent HTTP requests over kept-alive connections, or one
// blocking request (perform). Answers over 4 MiB are refused. Not
// thread-safe; one owner drives it.
#include <chrono>
#include <memory>
#include <string>
#include <vector>

namespace veneerd::hw::detail {

struct HttpCall {
  std::string method;   // GET, PUT, POST
  std::string url;      // http://host:port/path
  std::string body;     // sent as application/json when not empty (or for PUT/POST)
  long timeout_ms = 2000;
};

struct HttpResult {
  bool transport_ok = false;  // false: no HTTP answer (refused, timeout, connection dropped)
  long status = 0;
  std::string body;
  std::string error;          // transport error text when !transport_ok
};

class HttpClient {
 public:
  HttpClient();
  ~HttpClient();
  HttpClient(const HttpClient&) = delete;
  HttpClient& operator=(const HttpClient&) = delete;

  // Starts a request; returns its ticket.
  int start(const HttpCall& call);
  // Waits up to `timeout` for transfers to progress; returns the finished ones.
  std::vector<std::pair<int, HttpResult>> poll(std::chrono::milliseconds timeout);
  int active() const;
  // Aborts every running transfer.
  void cancel_all();
  // One request, blocking.
  HttpResult perform(const HttpCall& call);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace veneerd::hw::detail
