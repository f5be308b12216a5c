#pragma once
// The API server: the veneer.v1 protocol over TCP (standalone asio, one I/O
// thread). Every connection must say hello with the token before anything
// else is served. Each connection has a bounded send queue: live frames are
// dropped for a client that does not keep up, image chunks are produced only
// as fast as the client takes them, and a client whose queue still overflows
// is disconnected — a slow or vanished client never stalls the rig or others.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "veneer/util/expected.hpp"
#include "veneerd/auth_throttle.hpp"
#include "veneerd/rig.hpp"

namespace veneerd {

struct ServerOptions {
  std::string host = "127.0.0.1";
  uint16_t port = 7878;              // 0 = any free port (see Server::port())
  std::string token;                 // the access token clients must present
  // TLS 1.3 (proto/README.md, "Encryption and pinning"): the rig's PEM key and
  // self-signed certificate (veneer/proto/tls.hpp makes them). plain_tcp: no
  // TLS at all, the API in clear (only when configured so; said in the status).
  std::string tls_key_file;
  std::string tls_cert_file;
  bool plain_tcp = false;
  size_t max_queue_bytes = 32u << 20;   // a connection's send queue limit; beyond it the client is dropped
  size_t live_queue_bytes = 1u << 20;   // live frames are skipped while more than this waits to be sent
  size_t fetch_queue_bytes = 1u << 20;  // image chunks are read while less than this waits
  double hello_timeout_s = 10;       // a connection that does not say hello in time is closed
  AuthThrottleOptions auth;          // how wrong tokens are slowed and logged
  // After a download or live view ends, freed memory is handed back to the
  // system (malloc_trim) this much later, at most once per this interval [s].
  double release_memory_delay_s = 1;
};

struct ServerStats {
  uint64_t connections = 0;
  uint64_t live_frames_sent = 0;
  uint64_t live_frames_dropped = 0;
  uint64_t protocol_errors = 0;
  uint64_t wrong_tokens = 0;
  uint64_t memory_releases = 0;
  uint64_t chunk_bytes = 0;  // file bytes put into image chunks (fetch_images, fetch_preview)
  uint64_t tls_handshake_failures = 0;
};

class Server {
 public:
  // Hooks itself into the rig's event and live-frame callbacks: construct it
  // before Rig::start().
  Server(Rig& rig, ServerOptions options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  veneer::Status start();  // binds and starts the I/O thread
  void stop();
  uint16_t port() const;
  // Whether a socket bound to "::" also takes IPv4 connections (it is made so
  // when it can: "::" means every address of both families).
  bool dual_stack() const;
  ServerStats stats() const;

  struct Impl;  // public so the connection class in server.cpp can name it

 private:
  std::shared_ptr<Impl> impl_;
};

}  // namespace veneerd
