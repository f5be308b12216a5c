// The rig's DNS-SD advertisement against a real avahi-daemon: each test moves
// its process into a private network namespace (and mount namespace, for the
// daemon's /run), makes two interfaces with IPv4 and IPv6 addresses, starts
// its own D-Bus system bus and avahi-daemon there, runs the rig in-process on
// one listening address, and checks that every address the rig is advertised
// at -- resolved by the project's browse code and by avahi-browse -- answers
// on the advertised port, and that the rig is advertised on exactly the
// interfaces and address families it listens on.
//
// Skipped, with the reason, where namespaces cannot be made (an unprivileged
// container) or avahi-daemon, dbus-daemon or ip are not installed
// (tools/debian-packages.txt lists them). Nothing leaves the namespace: the
// addresses are the documentation ranges (192.0.2.0/24, 198.51.100.0/24,
// 2001:db8::/32) on veth pairs that exist only inside it.
#include <gtest/gtest.h>

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <set>
#include <sstream>
#include <thread>

#include <fcntl.h>
#include <sched.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/mount.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include "rig_test_util.hpp"
#include "veneer/dnssd/dnssd.hpp"
#include "veneer/proto/discovery.hpp"
#include "veneer/rig/client.hpp"
#include "veneerd/daemon.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;

namespace {

std::string find_program(const std::string& name) {
  std::string path = std::getenv("PATH") ? std::getenv("PATH") : "";
  path += ":/usr/sbin:/sbin:/usr/bin:/bin";
  std::istringstream dirs(path);
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    fs::path p = fs::path(dir) / name;
    if (!dir.empty() && ::access(p.c_str(), X_OK) == 0) return p.string();
  }
  return "";
}

std::string read_text(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

bool write_text(const fs::path& p, const std::string& text) {
  std::ofstream out(p);
  out << text;
  return static_cast<bool>(out);
}

// Starts `argv` with stdout and stderr into `log`; -1 on failure. The child
// gets SIGTERM when this process dies, so a killed test leaves no daemon behind.
pid_t spawn(const std::vector<std::string>& argv, const fs::path& log) {
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid != 0) return pid;
  ::prctl(PR_SET_PDEATHSIG, SIGTERM);
  if (::getppid() != parent) ::_exit(127);
  int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd >= 0) {
    ::dup2(fd, 1);
    ::dup2(fd, 2);
  }
  ::execv(args[0], args.data());
  ::_exit(127);
}

void stop(pid_t& pid) {
  if (pid <= 0) return;
  ::kill(pid, SIGTERM);
  int status = 0;
  for (int i = 0; i < 100 && ::waitpid(pid, &status, WNOHANG) == 0; ++i) std::this_thread::sleep_for(20ms);
  if (::waitpid(pid, &status, WNOHANG) == 0) {
    ::kill(pid, SIGKILL);
    ::waitpid(pid, &status, 0);
  }
  pid = -1;
}

template <class F>
bool wait_for(F done, std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    if (std::chrono::steady_clock::now() > end) return false;
    std::this_thread::sleep_for(20ms);
  }
  return true;
}

// One advertised address of the rig, as a browser resolved it.
struct Seen {
  std::string interface;
  bool ipv6 = false;
  std::string address;
  uint16_t port = 0;
  bool operator<(const Seen& o) const {
    return std::tie(interface, ipv6, address, port) < std::tie(o.interface, o.ipv6, o.address, o.port);
  }
};

std::string endpoint(const Seen& s) {
  return (s.ipv6 ? "[" + s.address + "]" : s.address) + ":" + std::to_string(s.port);
}

// The namespaces, interfaces, bus and avahi-daemon: made once per process
// (a process enters its namespaces once; ctest runs each test in its own).
class AvahiNamespace {
 public:
  static AvahiNamespace& instance() {
    static AvahiNamespace ns;
    return ns;
  }
  // Empty when ready; else why the tests are skipped. A failure to start what
  // is installed is a test failure (`failed`).
  const std::string& skip_reason() const { return skip_; }
  const std::string& failure() const { return failure_; }
  fs::path log(const char* name) const { return dir_ / name; }

  ~AvahiNamespace() {
    stop(avahi_);
    stop(dbus_);
    if (!dir_.empty()) fs::remove_all(dir_);
  }

 private:
  AvahiNamespace() {
    for (const char* p : {"avahi-daemon", "dbus-daemon", "ip"}) {
      if (find_program(p).empty()) {
        skip_ = std::string(p) + " is not installed (see tools/debian-packages.txt)";
        return;
      }
    }
    if (auto why = enter_namespaces(); !why.empty()) {
      skip_ = "no private network namespace here: " + why;
      return;
    }
    dir_ = rigtest::temp_dir("advertise");
    if (!make_interfaces() || !start_bus() || !start_avahi()) return;
  }

  // This process (still single-threaded) moves into new network and mount
  // namespaces; as a user without privileges, inside a new user namespace too.
  static std::string enter_namespaces() {
    const uid_t uid = ::geteuid();
    const gid_t gid = ::getegid();
    int flags = CLONE_NEWNET | CLONE_NEWNS;
    if (uid != 0) flags |= CLONE_NEWUSER;
    if (::unshare(flags) != 0) return std::string("unshare: ") + std::strerror(errno);
    if (uid != 0) {
      write_text("/proc/self/setgroups", "deny");
      if (!write_text("/proc/self/uid_map", "0 " + std::to_string(uid) + " 1") ||
          !write_text("/proc/self/gid_map", "0 " + std::to_string(gid) + " 1"))
        return "cannot map this user into the user namespace";
    }
    // Mounts made from here on stay in this namespace; avahi-daemon keeps its
    // pid file and socket in /run/avahi-daemon, so a private /run.
    if (::mount("none", "/", nullptr, MS_REC | MS_PRIVATE, nullptr) != 0)
      return std::string("cannot make mounts private: ") + std::strerror(errno);
    if (::mount("tmpfs", "/run", "tmpfs", 0, "mode=0755") != 0)
      return std::string("cannot mount a private /run: ") + std::strerror(errno);
    ::mkdir("/run/avahi-daemon", 0755);
    return "";
  }

  bool sh(const std::string& command) {
    const std::string full = command + " >>" + (dir_ / "ip.log").string() + " 2>&1";
    if (std::system(full.c_str()) == 0) return true;
    failure_ = "failed: " + command + "\n" + read_text(dir_ / "ip.log");
    return false;
  }

  // vn0: 192.0.2.1/24, 2001:db8:1::1/64; vn1: 198.51.100.1/24, 2001:db8:2::1/64
  // (each one end of a veth pair whose other end is up, unaddressed).
  bool make_interfaces() {
    const std::string ip = find_program("ip");
    bool ok = sh(ip + " link set lo up");
    const char* v4[] = {"192.0.2.1/24", "198.51.100.1/24"};
    const char* v6[] = {"2001:db8:1::1/64", "2001:db8:2::1/64"};
    for (int i = 0; i < 2 && ok; ++i) {
      const std::string n = std::to_string(i);
      ok = sh(ip + " link add vn" + n + " type veth peer name vp" + n) &&
           sh(ip + " addr add " + v4[i] + " dev vn" + n) &&
           sh(ip + " -6 addr add " + v6[i] + " dev vn" + n + " nodad") && sh(ip + " link set vp" + n + " up") &&
           sh(ip + " link set vn" + n + " up");
    }
    return ok;
  }

  bool start_bus() {
    const fs::path socket = dir_ / "system_bus";
    write_text(dir_ / "bus.conf",
               "<!DOCTYPE busconfig PUBLIC \"-//freedesktop//DTD D-Bus Bus Configuration 1.0//EN\"\n"
               " \"http://www.freedesktop.org/standards/dbus/1.0/busconfig.dtd\">\n"
               "<busconfig>\n  <type>system</type>\n  <listen>unix:path=" +
                   socket.string() +
                   "</listen>\n  <auth>EXTERNAL</auth>\n"
                   "  <policy context=\"default\">\n    <allow user=\"*\"/>\n    <allow own=\"*\"/>\n"
                   "    <allow send_destination=\"*\"/>\n    <allow receive_sender=\"*\"/>\n  </policy>\n"
                   "</busconfig>\n");
    dbus_ = spawn({find_program("dbus-daemon"), "--config-file=" + (dir_ / "bus.conf").string(), "--nofork",
                   "--nopidfile"},
                  dir_ / "dbus.log");
    if (dbus_ <= 0 || !wait_for([&] { return fs::exists(socket); }, 3s)) {
      failure_ = "dbus-daemon did not start:\n" + read_text(dir_ / "dbus.log");
      return false;
    }
    ::setenv("DBUS_SYSTEM_BUS_ADDRESS", ("unix:path=" + socket.string()).c_str(), 1);
    return true;
  }

  bool start_avahi() {
    write_text(dir_ / "avahi.conf",
               "[server]\nuse-ipv4=yes\nuse-ipv6=yes\nallow-interfaces=vn0,vn1\nenable-dbus=yes\n"
               "[wide-area]\nenable-wide-area=no\n[publish]\npublish-hinfo=no\npublish-workstation=no\n");
    avahi_ = spawn({find_program("avahi-daemon"), "-f", (dir_ / "avahi.conf").string(), "--no-drop-root",
                    "--no-chroot", "--no-rlimits", "--no-proc-title"},
                   dir_ / "avahi.log");
    if (avahi_ <= 0 ||
        !wait_for([&] { return read_text(dir_ / "avahi.log").find("Server startup complete") != std::string::npos; },
                  5s)) {
      failure_ = "avahi-daemon did not start:\n" + read_text(dir_ / "avahi.log");
      return false;
    }
    return true;
  }

  std::string skip_;
  std::string failure_;
  fs::path dir_;
  pid_t dbus_ = -1;
  pid_t avahi_ = -1;
};

class Advertise : public ::testing::Test {
 protected:
  void SetUp() override {
    auto& ns = AvahiNamespace::instance();
    if (!ns.skip_reason().empty()) GTEST_SKIP() << ns.skip_reason();
    ASSERT_TRUE(ns.failure().empty()) << ns.failure();
    dir_ = rigtest::temp_dir("advertise-rig");
  }

  void TearDown() override {
    if (daemon_) {
      const std::string name = daemon_->advertised_name();
      daemon_.reset();  // withdraws the advertisement
      // The next test in this process advertises the same name: wait until
      // this one's records are gone.
      wait_for(
          [&] {
            auto found = veneer::dnssd::browse(veneer::wire::kServiceType, 300);
            if (!found) return true;
            for (const auto& s : *found)
              if (s.name == name) return false;
            return true;
          },
          5s);
    }
    if (!dir_.empty()) fs::remove_all(dir_);
  }

  // Runs the rig listening on `listen` (port 0: any free port).
  bool start_rig(const std::string& listen) {
    veneerd::DaemonOptions o;
    o.simulate = true;
    o.size = {64, 43};
    o.noise_sigma = 0;
    o.listen = listen;
    o.store = dir_ / "store";
    auto d = veneerd::Daemon::create(o);
    if (!d) {
      ADD_FAILURE() << d.message();
      return false;
    }
    daemon_ = std::move(*d);
    if (auto s = daemon_->start(); !s) {
      ADD_FAILURE() << s.message();
      return false;
    }
    if (daemon_->advertised_name().empty()) {
      ADD_FAILURE() << "the rig on " << listen << " does not advertise";
      return false;
    }
    return true;
  }

  // The rig's addresses as the project's browse code (`veneer rig find`)
  // resolves them, once its announcement is established (Avahi probes for
  // about a second; every record of one announcement is established together).
  std::set<Seen> browse_rig() {
    std::set<Seen> seen;
    wait_for(
        [&] {
          seen.clear();
          auto found = veneer::dnssd::browse(veneer::wire::kServiceType, 500);
          if (!found) return false;
          for (const auto& s : *found) {
            if (s.name != daemon_->advertised_name()) continue;
            seen.insert({s.interface, s.ipv6, s.address, s.port});
            // The record carries the certificate's fingerprint (to show beside the first-use question).
            EXPECT_EQ(veneer::wire::parse_rig_txt(s.txt).fingerprint, daemon_->fingerprint());
          }
          return !seen.empty();
        },
        8s);
    return seen;
  }

  // The same through avahi-browse, a client nobody here wrote (its -p lines:
  // "=;iface;IPv4;name;type;domain;host;address;port;txt").
  std::set<Seen> avahi_browse_rig() {
    std::set<Seen> seen;
    const std::string prog = find_program("avahi-browse");
    if (prog.empty()) return seen;
    auto r = rigtest::run(prog + " -r -p -t " + veneer::wire::kServiceType);
    std::istringstream lines(r.out);
    std::string line;
    while (std::getline(lines, line)) {
      std::vector<std::string> f;
      std::istringstream cells(line);
      std::string c;
      while (std::getline(cells, c, ';')) f.push_back(c);
      if (f.size() < 9 || f[0] != "=" || f[3] != daemon_->advertised_name()) continue;
      seen.insert({f[1], f[2] == "IPv6", f[7], static_cast<uint16_t>(std::stoi(f[8]))});
    }
    return seen;
  }

  // Every advertised address answers on the advertised port: the rig says
  // hello back with the token.
  void expect_all_answer(const std::set<Seen>& seen, const char* who) {
    for (const auto& s : seen) {
      EXPECT_EQ(s.port, daemon_->port()) << who << ": " << endpoint(s);
      veneer::rig::ConnectOptions co;
      co.connect_timeout_s = 2;
      co.request_timeout_s = 2;
      co.fingerprint = daemon_->fingerprint();  // beyond loopback a rig is pinned
      auto c = veneer::rig::Client::connect({s.address, s.port}, daemon_->token(), co);
      EXPECT_TRUE(c) << who << " resolved the rig to " << endpoint(s) << " on " << s.interface
                     << ", which does not answer: " << c.message();
    }
  }

  // Checks where the rig listening on `listen` is advertised: exactly on
  // `expected` (interface, IPv6?) pairs, and every address answers.
  void check(const std::string& listen, const std::set<std::pair<std::string, bool>>& expected) {
    ASSERT_TRUE(start_rig(listen));
    auto ours = browse_rig();
    ASSERT_FALSE(ours.empty()) << "the rig on " << listen << " was not found:\n"
                               << read_text(AvahiNamespace::instance().log("avahi.log"));
    std::set<std::pair<std::string, bool>> where;
    for (const auto& s : ours) where.insert({s.interface, s.ipv6});
    EXPECT_EQ(where, expected) << "listening on " << listen;
    expect_all_answer(ours, "veneer::dnssd::browse");
    auto theirs = avahi_browse_rig();
    if (!find_program("avahi-browse").empty()) {
      EXPECT_FALSE(theirs.empty()) << "avahi-browse did not find the rig";
      std::set<std::pair<std::string, bool>> their_where;
      for (const auto& s : theirs) their_where.insert({s.interface, s.ipv6});
      EXPECT_EQ(their_where, expected) << "avahi-browse, listening on " << listen;
      expect_all_answer(theirs, "avahi-browse");
    }
  }

  fs::path dir_;
  std::unique_ptr<veneerd::Daemon> daemon_;
};

TEST_F(Advertise, OneIpv4AddressIsAdvertisedOnItsInterfaceOnly) {
  check("192.0.2.1:0", {{"vn0", false}});
}

TEST_F(Advertise, OneIpv6AddressIsAdvertisedOnItsInterfaceOnly) {
  check("[2001:db8:2::1]:0", {{"vn1", true}});
}

TEST_F(Advertise, EveryIpv4AddressIsAdvertisedOnEveryInterfaceOverIpv4) {
  check("0.0.0.0:0", {{"vn0", false}, {"vn1", false}});
}

TEST_F(Advertise, EveryAddressIsAdvertisedOnEveryInterfaceInBothFamilies) {
  check("[::]:0", {{"vn0", false}, {"vn0", true}, {"vn1", false}, {"vn1", true}});
}

}  // namespace
