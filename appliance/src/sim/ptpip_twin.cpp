// The PTP/IP camera twin (see ptpip_twin.hpp): its options and its public
// face; the server is ptpip_server.cpp, the camera ptpip_camera.cpp, the codec
// ptpip_codec.cpp, the simulator adapter ptpip_sim_source.cpp, the CLI ptpip_cli.cpp.
//
// Wire format (ISO 15740 Annex / CIPA DC-005, little endian): every packet is
// u32 length (including these 8 bytes), u32 type, payload. The initiator opens
// the command connection (Init Command Request -> Ack with a connection
// number), then the event connection (Init Event Request with that number ->
// Ack). A transaction is Cmd Request [-> Start Data, Data..., End Data] ->
// Cmd Response on the command connection; events flow on the event connection.
#include "ptpip_twin_impl.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "veneer/util/log.hpp"

namespace veneerd {

using namespace ptpip;

veneer::Status PtpipTwinOptions::check() const {
  in_addr a{};
  if (inet_pton(AF_INET, host.c_str(), &a) != 1)
    return veneer::make_error("PTP/IP twin: host '" + host + "' is not an IPv4 address");
  if (!shot) return veneer::make_error("PTP/IP twin: no shot source given");
  if (exposure_times.empty() || f_numbers.empty() || isos.empty())
    return veneer::make_error("PTP/IP twin: every exposure setting needs at least one offered value");
  auto has = [](const auto& v, auto x) { return std::find(v.begin(), v.end(), x) != v.end(); };
  if (!has(exposure_times, initial.exposure_time) || !has(f_numbers, initial.f_number) || !has(isos, initial.iso))
    return veneer::make_error("PTP/IP twin: the initial exposure is not among the offered values");
  return {};
}

PtpipTwin::PtpipTwin(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

veneer::Expected<std::unique_ptr<PtpipTwin>> PtpipTwin::start(PtpipTwinOptions options) {
  if (auto s = options.check(); !s) return s.error();
  auto impl = std::make_unique<Impl>();
  impl->opt = std::move(options);
  impl->exposure = impl->opt.initial;
  // The card: DCIM/100VENER, as a camera formats it.
  Object dcim;
  dcim.handle = 1;
  dcim.format = kFormatAssociation;
  dcim.name = "DCIM";
  dcim.date = ptp_date_now();
  Object folder = dcim;
  folder.handle = 2;
  folder.parent = 1;
  folder.name = "100VENER";
  impl->card.emplace(1, dcim);
  impl->card.emplace(2, folder);
  impl->next_handle = 3;

  int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return veneer::make_error(std::string("PTP/IP twin: socket: ") + std::strerror(errno));
  int one = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(impl->opt.port);
  inet_pton(AF_INET, impl->opt.host.c_str(), &a.sin_addr);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) < 0 || ::listen(fd, 8) < 0) {
    std::string e = std::strerror(errno);
    ::close(fd);
    return veneer::make_error("PTP/IP twin: cannot listen on " + impl->opt.host + ":" + std::to_string(impl->opt.port) +
                              ": " + e);
  }
  socklen_t len = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  impl->listen_fd = fd;
  impl->port = ntohs(a.sin_port);
  if (::pipe2(impl->wake, O_CLOEXEC) < 0) {
    ::close(fd);
    return veneer::make_error(std::string("PTP/IP twin: pipe: ") + std::strerror(errno));
  }
  Impl* raw = impl.get();
  impl->acceptor = std::thread([raw] { raw->accept_loop(); });
  VLOG_INFO(kLog, "PTP/IP twin '{}' listening on {}:{}", raw->opt.model, raw->opt.host, raw->port);
  return std::unique_ptr<PtpipTwin>(new PtpipTwin(std::move(impl)));
}

PtpipTwin::~PtpipTwin() {
  Impl& m = *impl_;
  {
    std::lock_guard lock(m.mu);
    m.stopping = true;
    for (int fd : m.open_fds) ::shutdown(fd, SHUT_RDWR);
  }
  char b = 1;
  if (::write(m.wake[1], &b, 1) < 0) { /* the acceptor also stops on close below */ }
  if (m.acceptor.joinable()) m.acceptor.join();
  std::list<Impl::Worker> workers;
  {
    std::lock_guard lock(m.mu);
    for (int fd : m.open_fds) ::shutdown(fd, SHUT_RDWR);
    workers.swap(m.workers);
  }
  for (auto& w : workers) w.thread.join();
  ::close(m.listen_fd);
  ::close(m.wake[0]);
  ::close(m.wake[1]);
}

uint16_t PtpipTwin::port() const { return impl_->port; }

std::string PtpipTwin::gphoto2_port() const {
  return "ptpip:" + impl_->opt.host + ":" + std::to_string(impl_->port) + ":" + std::to_string(impl_->port);
}

PtpipExposure PtpipTwin::exposure() const {
  std::lock_guard lock(impl_->mu);
  return impl_->exposure;
}

std::vector<PtpipFile> PtpipTwin::files() const {
  std::lock_guard lock(impl_->mu);
  return impl_->files;
}

std::vector<std::string> PtpipTwin::files_on_card() const {
  std::lock_guard lock(impl_->mu);
  std::vector<std::string> out;
  for (const auto& [h, o] : impl_->card)
    if (o.format != kFormatAssociation) out.push_back(o.name);
  return out;
}

std::vector<std::pair<uint16_t, uint32_t>> PtpipTwin::property_writes() const {
  std::lock_guard lock(impl_->mu);
  return impl_->writes;
}

PtpipTwinStats PtpipTwin::stats() const {
  std::lock_guard lock(impl_->mu);
  return impl_->stats;
}

void PtpipTwin::drop_at(DropAt where, int k, bool stay_off) {
  std::lock_guard lock(impl_->mu);
  if (where == DropAt::capture) {
    impl_->drop_capture_in = std::max(k, 0);
    impl_->drop_capture_off = stay_off;
  } else {
    impl_->drop_download_in = std::max(k, 0);
    impl_->drop_download_off = stay_off;
  }
}

void PtpipTwin::drop_now() {
  std::lock_guard lock(impl_->mu);
  impl_->drop_locked(impl_->current.get(), false, "asked to");
}

void PtpipTwin::set_on(bool on) {
  std::lock_guard lock(impl_->mu);
  impl_->on = on;
  if (!on) impl_->drop_locked(impl_->current.get(), true, "switched off");
}

bool PtpipTwin::is_on() const {
  std::lock_guard lock(impl_->mu);
  return impl_->on;
}

}  // namespace veneerd
