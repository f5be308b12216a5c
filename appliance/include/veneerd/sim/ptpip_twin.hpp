#pragma once
// A PTP/IP camera twin: a small camera responder on a TCP port that speaks
// PTP/IP (ISO 15740 over TCP: a command/data connection and an event
// connection) well enough for libgphoto2's generic "PTP/IP Camera" driver to
// open it, read and set exposure properties, capture (ObjectAdded and
// CaptureComplete on the event connection), list, download and delete the
// shots, and pull live-view frames through the PTP 1.1 stream operations
// (GetStreamInfo / GetStream), the only live view libgphoto2 2.5.30 offers a
// camera without a vendor extension.
//
// Images come from a source given by the owner (a callback per capture); in
// the simulated rig that is the scene simulator rendering under the lamps the
// Hue bridge reports on (simulated_shot_source()). The twin can also play an
// unplugged camera: drop its connection at a chosen capture or download, and
// refuse new connections until it is "switched on" again.
//
// The twin speaks only PTP/IP; it has no gphoto2 type and no gphoto2
// dependency. One twin serves one initiator at a time: a new connection
// replaces the previous one, as a camera does when its host comes back.
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <memory>
#include <string>
#include <vector>

#include "veneer/util/expected.hpp"

namespace veneerd {

class SimulatedCamera;

// The twin's exposure settings in PTP units (what SetDevicePropValue sent).
struct PtpipExposure {
  uint32_t exposure_time = 333;  // ExposureTime (0x500D), 1/10000 s; 333 = 1/30 s
  uint16_t f_number = 800;       // FNumber (0x5007), 1/100; 800 = f/8
  uint16_t iso = 100;            // ExposureIndex (0x500F)
  uint16_t program = 1;          // ExposureProgramMode (0x500E): 1 = M, 2 = P, 3 = A, 4 = S
  uint16_t focus = 2;            // FocusMode (0x500A): 1 = manual, 2 = automatic
  double shutter_s() const { return exposure_time / 10000.0; }
  double aperture() const { return f_number / 100.0; }
};

// The JPEG of capture number `shot` (1-based, counted over the twin's life).
using PtpipShotSource = std::function<veneer::Expected<std::vector<unsigned char>>(const PtpipExposure&, uint64_t shot)>;
// One live-view frame as JPEG.
using PtpipPreviewSource = std::function<veneer::Expected<std::vector<unsigned char>>(const PtpipExposure&)>;

struct PtpipTwinOptions {
  std::string host = "127.0.0.1";  // IPv4 address to listen on
  uint16_t port = 0;               // 0 = any free port
  std::string manufacturer = "Veneer";
  std::string model = "Veneer PTP/IP twin";
  std::string serial = "VNR-0001";
  std::string friendly_name = "veneer-twin";  // sent in the Init Command Ack
  PtpipShotSource shot;            // required
  PtpipPreviewSource preview;      // null: no stream operations are offered (no live view)
  // Offered values (PTP units, see PtpipExposure); the first state is `initial`.
  std::vector<uint32_t> exposure_times{20, 40, 80, 167, 333, 667, 1250, 2500, 5000, 10000};
  std::vector<uint16_t> f_numbers{280, 400, 560, 800, 1100, 1600, 2200};
  std::vector<uint16_t> isos{100, 200, 400, 800, 1600, 3200};
  PtpipExposure initial;
  veneer::Status check() const;
};

// One file the twin's card has held.
struct PtpipFile {
  uint32_t handle = 0;
  std::string name;                   // "IMG_0001.JPG"
  std::vector<unsigned char> bytes;   // exactly what the twin serves
  PtpipExposure exposure;             // the settings it was taken with
  int downloads = 0;                  // complete GetObject transfers
  bool deleted = false;
};

struct PtpipTwinStats {
  uint64_t connections = 0;   // Init Command Requests accepted
  uint64_t refused = 0;       // connections refused while switched off
  uint64_t sessions = 0;      // OpenSession
  uint64_t captures = 0;      // InitiateCapture
  uint64_t downloads = 0;     // complete GetObject transfers
  uint64_t deletes = 0;       // DeleteObject of a file
  uint64_t stream_frames = 0; // GetStream
  uint64_t drops = 0;         // connections dropped on purpose
  uint64_t property_sets = 0; // SetDevicePropValue accepted
};

class PtpipTwin {
 public:
  // Listens and serves on its own threads until destroyed.
  static veneer::Expected<std::unique_ptr<PtpipTwin>> start(PtpipTwinOptions options);
  ~PtpipTwin();
  PtpipTwin(const PtpipTwin&) = delete;
  PtpipTwin& operator=(const PtpipTwin&) = delete;

  uint16_t port() const;
  // The libgphoto2 port path: "ptpip:127.0.0.1:PORT:PORT" (command and event
  // connection on the same port; libgphoto2 2.5.30 assumes 15740 for the
  // event connection unless it is named).
  std::string gphoto2_port() const;

  PtpipExposure exposure() const;
  std::vector<PtpipFile> files() const;            // every file ever captured, in order
  std::vector<std::string> files_on_card() const;  // names of the files not deleted
  // Property writes received, in order: (property code, value).
  std::vector<std::pair<uint16_t, uint32_t>> property_writes() const;
  PtpipTwinStats stats() const;

  // --- unplugging -----------------------------------------------------------
  enum class DropAt {
    capture,   // after answering InitiateCapture, before the shot's events
    download,  // halfway through GetObject's data phase
  };
  // The k-th capture / download from now (1-based) drops the connection. With
  // `stay_off` the camera then refuses connections until set_on(true).
  void drop_at(DropAt where, int k, bool stay_off = false);
  void drop_now();  // drop the current connection (if any)
  // Switched off: a new connection is answered with Init Fail and closed.
  void set_on(bool on);
  bool is_on() const;

 private:
  struct Impl;
  explicit PtpipTwin(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// A shot source that renders with the simulated camera: its exposure follows
// the twin's settings, the scene is lit by exactly the lamps the (emulated)
// bridge reports on, and the linear render is sRGB-encoded to a JPEG of
// `quality` (1..100). Live view: the simulated camera's preview frames.
PtpipShotSource simulated_shot_source(std::shared_ptr<SimulatedCamera> camera, int quality = 95);
PtpipPreviewSource simulated_preview_source(std::shared_ptr<SimulatedCamera> camera);

// `veneerd ptpip-twin --bridge HOST:PORT --key KEY --lamps 1,2,3 [--scene bull]
// [--size 1024x680] [--listen 127.0.0.1:15740]`: a twin serving simulator
// renders lit by the named bridge's lamps, until SIGINT/SIGTERM; a veneerd
// with camera {"backend": "gphoto2", "port": "ptpip:127.0.0.1:15740"} drives it.
// args[0] is the subcommand's name. Returns the exit code.
int ptpip_twin_command(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

}  // namespace veneerd
