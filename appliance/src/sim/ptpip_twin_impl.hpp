#pragma once
// PtpipTwin::Impl: the twin's state and its parts, defined in
//   ptpip_server.cpp  sockets, connections, the transaction loop
//   ptpip_camera.cpp  what the camera does: the card, capture, properties
//   ptpip_twin.cpp    the public PtpipTwin
// Private to appliance/src/sim/.
#include <atomic>
#include <list>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include "ptpip_codec.hpp"
#include "veneerd/sim/ptpip_twin.hpp"

namespace veneerd {

using ptpip::Connection;
using ptpip::Object;
using ptpip::Reply;

struct PtpipTwin::Impl {
  PtpipTwinOptions opt;
  int listen_fd = -1;
  int wake[2] = {-1, -1};
  uint16_t port = 0;
  std::thread acceptor;

  mutable std::mutex mu;  // everything below
  bool stopping = false, on = true;
  std::set<int> open_fds;  // sockets being served (only these may be shut down)
  struct Worker {
    std::thread thread;
    std::shared_ptr<std::atomic<bool>> done;
  };
  std::list<Worker> workers;
  std::shared_ptr<Connection> current;
  uint32_t next_connection = 1;
  PtpipExposure exposure;
  uint32_t enabled_streams = 0;
  std::map<uint32_t, Object> card;
  uint32_t next_handle = 1;
  std::vector<PtpipFile> files;
  std::vector<std::pair<uint16_t, uint32_t>> writes;
  PtpipTwinStats stats;
  int drop_capture_in = 0, drop_download_in = 0;  // countdowns; 0 = none
  bool drop_capture_off = false, drop_download_off = false;

  // --- sockets ------------------------------------------------------------
  void shutdown_locked(int fd);
  void drop_locked(Connection* c, bool stay_off, const char* why);
  void accept_loop();
  void serve(int fd);
  void init_fail(int fd, const char* why);
  void command_connection(int fd, const std::vector<uint8_t>& request);
  void event_connection(int fd, const std::vector<uint8_t>& request);
  bool send_event(Connection& c, uint16_t code, uint32_t tid, const std::vector<uint32_t>& params);

  // Start Data, Data..., End Data. With `stop_after` < n only that many bytes
  // go out (the unplug halfway through a download).
  static bool send_data(int fd, uint32_t tid, const uint8_t* p, size_t n, size_t stop_after = SIZE_MAX);
  static bool send_response(int fd, uint16_t code, uint32_t tid, const std::vector<uint32_t>& params);

  // The data phase the initiator sends (SetDevicePropValue).
  static std::optional<std::vector<uint8_t>> receive_data(int fd, uint32_t tid);

  // --- transactions -------------------------------------------------------
  bool transaction(Connection& c, const std::vector<uint8_t>& req);
  std::vector<uint8_t> device_info() const;

  uint16_t list_objects(uint32_t storage, uint32_t format, uint32_t parent, std::vector<uint32_t>& out);
  uint16_t object_info(uint32_t handle, std::vector<uint8_t>& data);
  bool get_object(Connection& c, uint32_t tid, uint32_t handle);
  uint16_t delete_object(uint32_t handle);
  bool capture(Connection& c, uint32_t tid, uint32_t storage, uint32_t format);

  // GetDevicePropDesc (desc = true) or GetDevicePropValue.
  uint16_t property(uint32_t code, bool desc, std::vector<uint8_t>& data) const;

  uint16_t set_property(uint16_t code, const std::vector<uint8_t>& in);
};

}  // namespace veneerd
