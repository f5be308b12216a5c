#pragma once
// Helpers for the rig tests: run the real veneerd binary on loopback, run the
// `veneer` CLI, and talk raw bytes to the API.
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <arpa/inet.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include <openssl/ssl.h>

#include "veneer/proto/framing.hpp"
#include "veneer/proto/tls.hpp"
#include "veneer/v1/rig.pb.h"

namespace rigtest {

namespace fs = std::filesystem;

inline fs::path temp_dir(const std::string& name) {
  fs::path p = fs::temp_directory_path() /
               ("veneer-rigtest-" + name + "-" + std::to_string(::getpid()) + "-" + std::to_string(std::random_device{}()));
  fs::remove_all(p);
  fs::create_directories(p);
  return p;
}

// The real daemon in its own process.
class DaemonProcess {
 public:
  // Starts build/bin/veneerd --simulate --listen 127.0.0.1:0 --store STORE [extra...]
  // (without --simulate when extra has a --config).
  static std::unique_ptr<DaemonProcess> start(const fs::path& store, std::vector<std::string> extra = {}) {
    int out[2];
    if (::pipe(out) != 0) return nullptr;
    std::vector<std::string> args = {VENEER_BIN_DIR "/veneerd"};
    bool configured = false;
    for (const auto& e : extra) configured = configured || e == "--config";
    if (!configured) args.push_back("--simulate");
    for (const char* a : {"--listen", "127.0.0.1:0", "--store"}) args.push_back(a);
    args.push_back(store.string());
    args.insert(args.end(), extra.begin(), extra.end());
    fs::path log = store.parent_path() / (store.filename().string() + ".log");
    pid_t pid = ::fork();
    if (pid == 0) {
      ::dup2(out[1], 1);
      FILE* err = std::fopen(log.c_str(), "a");
      if (err) ::dup2(::fileno(err), 2);
      ::close(out[0]);
      std::vector<char*> argv;
      for (auto& a : args) argv.push_back(a.data());
      argv.push_back(nullptr);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    ::close(out[1]);
    auto d = std::unique_ptr<DaemonProcess>(new DaemonProcess());
    d->pid_ = pid;
    d->log_ = log;
    // First stdout line: "veneerd: listening on 127.0.0.1:<port>, ..."
    std::string line;
    auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (line.find('\n') == std::string::npos && std::chrono::steady_clock::now() < deadline) {
      pollfd p{out[0], POLLIN, 0};
      if (::poll(&p, 1, 200) <= 0) continue;
      char buf[256];
      ssize_t n = ::read(out[0], buf, sizeof buf);
      if (n <= 0) break;
      line.append(buf, static_cast<size_t>(n));
    }
    ::close(out[0]);
    auto at = line.find("listening on 127.0.0.1:");
    if (at == std::string::npos) return d;  // port stays 0: the test fails with the log
    d->port_ = static_cast<uint16_t>(std::stoi(line.substr(at + 23)));
    return d;
  }

  ~DaemonProcess() { stop(SIGTERM); }

  uint16_t port() const { return port_; }
  pid_t pid() const { return pid_; }
  // The daemon's CPU time so far (user + system, from /proc/<pid>/stat) [s].
  double cpu_seconds() const {
    FILE* f = std::fopen(("/proc/" + std::to_string(pid_) + "/stat").c_str(), "r");
    if (!f) return -1;
    char buf[1024];
    size_t n = std::fread(buf, 1, sizeof buf - 1, f);
    std::fclose(f);
    buf[n] = 0;
    // Fields after the command name (which may hold spaces) start after the last ')'.
    const char* p = std::strrchr(buf, ')');
    if (!p) return -1;
    unsigned long long utime = 0, stime = 0;
    // state ppid pgrp session tty tpgid flags minflt cminflt majflt cmajflt utime stime
    if (std::sscanf(p + 2, "%*c %*d %*d %*d %*d %*d %*u %*u %*u %*u %*u %llu %llu", &utime, &stime) != 2) return -1;
    return static_cast<double>(utime + stime) / static_cast<double>(::sysconf(_SC_CLK_TCK));
  }
  // The daemon's resident memory (VmRSS from /proc/<pid>/status; or another
  // field of it, e.g. "RssAnon") [MiB].
  double rss_mib(const char* field = "VmRSS") const {
    FILE* f = std::fopen(("/proc/" + std::to_string(pid_) + "/status").c_str(), "r");
    if (!f) return -1;
    char line[256];
    double kib = -1;
    const std::string prefix = std::string(field) + ":";
    while (std::fgets(line, sizeof line, f)) {
      if (std::strncmp(line, prefix.c_str(), prefix.size()) == 0 &&
          std::sscanf(line + prefix.size(), "%lf", &kib) == 1) {
        break;
      }
    }
    std::fclose(f);
    return kib / 1024.0;
  }
  // The whole log (stderr) so far.
  std::string full_log() const {
    FILE* f = std::fopen(log_.c_str(), "r");
    if (!f) return "";
    std::string s;
    char buf[4096];
    size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) s.append(buf, n);
    std::fclose(f);
    return s;
  }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  bool alive() const { return pid_ > 0 && ::waitpid(pid_, nullptr, WNOHANG) == 0; }
  // The log's last 6000 characters (for failure messages).
  std::string log() const {
    std::string s = full_log();
    return s.size() > 6000 ? s.substr(s.size() - 6000) : s;
  }
  // Stops the daemon; SIGKILL simulates a crash / power cut.
  void stop(int sig) {
    if (pid_ <= 0) return;
    ::kill(pid_, sig);
    int status = 0;
    for (int i = 0; i < 100; ++i) {
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, &status, 0);
    pid_ = -1;
  }

 private:
  DaemonProcess() = default;
  pid_t pid_ = -1;
  uint16_t port_ = 0;
  fs::path log_;
};

// Runs a command through the shell; returns its exit code and stdout.
struct RunResult {
  int code = -1;
  std::string out;
};
inline RunResult run(const std::string& command) {
  RunResult r;
  FILE* p = ::popen((command + " 2>&1").c_str(), "r");
  if (!p) return r;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) r.out.append(buf, n);
  int status = ::pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

inline std::string veneer_cli() { return VENEER_BIN_DIR "/veneer"; }

// The fingerprint of the certificate of the rig with store `store` (kept in
// <store>.tls/; "" when there is none).
inline std::string rig_fingerprint(const fs::path& store) {
  auto fp = veneer::tls::fingerprint_of_cert_file(store.string() + ".tls/cert.pem");
  return fp ? *fp : std::string();
}

// `veneer rig` arguments for the rig at `address` with its store `store`:
// the token file, the certificate's fingerprint and a known-rigs file beside
// the store (never the user's own).
inline std::string cli_rig_args(const std::string& address, const fs::path& store) {
  return " rig --rig " + address + " --token-file " + (store / "token").string() + " --fingerprint " +
         rig_fingerprint(store) + " --known-rigs " + (store.parent_path() / "known_rigs").string();
}

// A raw connection speaking (or mis-speaking) the protocol: inside TLS 1.3
// (the rig's default; the certificate is not checked here) or, with
// tls = false, in plain TCP (a rig started --plain-tcp).
class RawConnection {
 public:
  // `from`: the local loopback address to connect from (127.0.0.<from>; 0 =
  // the kernel's choice), so one test can play several peers.
  explicit RawConnection(uint16_t port, int from = 0, bool tls = true) {
    fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (from > 0) {
      sockaddr_in local{};
      local.sin_family = AF_INET;
      local.sin_addr.s_addr = htonl(INADDR_LOOPBACK - 1 + static_cast<uint32_t>(from));
      if (::bind(fd_, reinterpret_cast<sockaddr*>(&local), sizeof local) != 0) {
        ::close(fd_);
        fd_ = -1;
        return;
      }
    }
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
      ::close(fd_);
      fd_ = -1;
      return;
    }
    if (!tls) return;
    ::signal(SIGPIPE, SIG_IGN);  // SSL_write to a peer that closed: an error, not the end of the test
    static SSL_CTX* ctx = [] {
      SSL_CTX* c = SSL_CTX_new(TLS_client_method());
      SSL_CTX_set_min_proto_version(c, TLS1_3_VERSION);
      return c;
    }();
    ssl_ = SSL_new(ctx);
    SSL_set_fd(ssl_, fd_);
    if (SSL_connect(ssl_) != 1) close();
  }
  ~RawConnection() { close(); }
  RawConnection(const RawConnection&) = delete;
  RawConnection& operator=(const RawConnection&) = delete;
  bool ok() const { return fd_ >= 0; }
  void close() {
    if (ssl_) SSL_free(ssl_);
    ssl_ = nullptr;
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }
  bool send_bytes(const std::string& bytes) {
    if (fd_ < 0) return false;
    if (ssl_) return bytes.empty() || SSL_write(ssl_, bytes.data(), static_cast<int>(bytes.size())) == static_cast<int>(bytes.size());
    return ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(bytes.size());
  }
  bool send(const veneer::v1::ClientMessage& m) { return send_bytes(veneer::wire::encode_delimited(m)); }
  bool hello(const std::string& token, uint64_t id = 1) {
    veneer::v1::ClientMessage m;
    m.set_id(id);
    m.mutable_hello()->set_protocol_version(veneer::wire::kProtocolVersion);
    m.mutable_hello()->set_token(token);
    if (!send(m)) return false;
    auto r = next_response(id);
    return r && r->ok();
  }
  // The next message, or nullopt on timeout / closed connection.
  std::optional<veneer::v1::RigMessage> next(double timeout_s = 10) {
    auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    for (;;) {
      veneer::v1::RigMessage m;
      auto r = in_.next(m);
      if (r == veneer::wire::ReadResult::message) return m;
      if (r != veneer::wire::ReadResult::need_more) return std::nullopt;  // broken, or not UTF-8
      auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0 || fd_ < 0) return std::nullopt;
      if (!readable(static_cast<int>(left.count()))) return std::nullopt;
      char buf[65536];
      ssize_t n = receive(buf, sizeof buf);
      if (n <= 0) {
        closed_ = true;
        return std::nullopt;
      }
      in_.feed(buf, static_cast<size_t>(n));
    }
  }
  std::optional<veneer::v1::Response> next_response(uint64_t id, double timeout_s = 10) {
    for (;;) {
      auto m = next(timeout_s);
      if (!m) return std::nullopt;
      if (m->has_response() && m->response().id() == id) return m->response();
    }
  }
  // True when the peer closed the connection within the timeout.
  bool closed_by_peer(double timeout_s = 5) {
    auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (!closed_ && std::chrono::steady_clock::now() < deadline) {
      if (fd_ < 0) return true;
      if (!readable(100)) continue;
      char buf[65536];
      ssize_t n = receive(buf, sizeof buf);
      if (n <= 0) closed_ = true;
    }
    return closed_;
  }

 private:
  // Whether a read would not block (TLS: bytes already decrypted count).
  bool readable(int timeout_ms) {
    if (ssl_ && SSL_pending(ssl_) > 0) return true;
    pollfd p{fd_, POLLIN, 0};
    return ::poll(&p, 1, timeout_ms) > 0;
  }
  // One read: bytes, 0 at the end of the stream, < 0 on an error.
  ssize_t receive(char* buf, size_t size) {
    if (!ssl_) return ::recv(fd_, buf, size, 0);
    int n = SSL_read(ssl_, buf, static_cast<int>(size));
    return n > 0 ? n : (SSL_get_error(ssl_, n) == SSL_ERROR_ZERO_RETURN ? 0 : -1);
  }

  int fd_ = -1;
  SSL* ssl_ = nullptr;
  bool closed_ = false;
  veneer::wire::FrameBuffer in_;
};

}  // namespace rigtest
