#pragma once
// The rig client: talks to veneerd over its protobuf/TCP API (Qt-free; used by
// the `veneer rig` commands and the desktop viewer).
//
//   veneer::rig::ConnectOptions o;
//   o.fingerprint = "AB:CD:...";                 // the rig's, from `veneerd --fingerprint` (or known_rigs)
//   auto rig = veneer::rig::Client::connect({"192.168.1.20", 7878}, token, o);
//   if (!rig) fail(rig.message());
//   (*rig)->on_event = [](const veneer::rig::Event& e) { ... };   // reader thread
//   auto sets = (*rig)->list_sets();
//   (*rig)->pull(sets->front().id, "out/dest");
//
// The connection is TLS 1.3; the rig's certificate is pinned by its
// fingerprint (ConnectOptions; proto/README.md, "Encryption and pinning").
// Requests block until their response arrives (or the timeout); events and
// live frames are delivered on the client's reader thread through the
// callbacks, which must return quickly. Set callbacks before issuing requests.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/io/imageset.hpp"
#include "veneer/util/expected.hpp"
#include "veneer/util/progress.hpp"

namespace veneer::rig {

constexpr uint16_t kDefaultPort = 7878;

struct Endpoint {
  std::string host = "127.0.0.1";
  uint16_t port = kDefaultPort;
  // "host:port", "host" or ":port".
  static Expected<Endpoint> parse(const std::string& text);
  std::string str() const { return host + ":" + std::to_string(port); }
  // How the known-rigs file names this rig: "host:port", "[v6]:port".
  std::string pin_name() const;
};

// A rig found on the LAN through DNS-SD (it advertises _veneer._tcp, see
// veneer/proto/discovery.hpp).
struct FoundRig {
  std::string name;       // the rig's name (TXT "name", else the instance name)
  std::string instance;   // DNS-SD instance name
  std::string host;       // "rig.local"
  std::string address;    // IPv4 or IPv6 address
  uint16_t port = 0;
  std::string version;    // veneerd's version, "" if not advertised
  uint32_t protocol = 0;  // API protocol version, 0 if not advertised
  std::string transport;    // "tls1.3", or "tcp" for a rig serving plain TCP
  std::string fingerprint;  // as the rig announces it: to show and compare, never to pin unchecked (DNS-SD is not authenticated)
  // "address:port" ("[v6]:port" for IPv6), ready for Endpoint::parse / --rig.
  std::string endpoint() const;
  // One line for people: "veneer-rig  192.168.1.20:7878  (rig.local, veneerd 0.1.0, protocol 1)".
  std::string describe() const;
};

// Browses the LAN for rigs for about `timeout_ms`. IPv4 first, one entry a
// rig and address. An error when DNS-SD is unavailable (no avahi-daemon or
// D-Bus): the message says so; an empty list when none answered.
Expected<std::vector<FoundRig>> find_rigs(int timeout_ms = 2000);

// Reads an access token file (the rig keeps it in <store>/token).
Expected<std::string> read_token_file(const std::filesystem::path& file);

// One lamp as the rig's Hue bridge reported it.
struct LampReading {
  std::string id;
  bool on = false;
  int brightness = 0;
  std::string colour_mode;  // "xy", "ct", "hs"
  double x = 0, y = 0;
  int ct = 0, hue = 0, sat = 0;
  bool reachable = true;
};

struct RigStatus {
  std::string name;
  bool simulated = false;
  bool camera_connected = false;
  std::string camera_model;
  int lamp_count = 0;
  std::vector<bool> lamps_on;        // as the bridge reported them, lamps_age_s ago
  std::vector<LampReading> lamps;
  double lamps_age_s = -1;
  std::string lamps_problem;         // empty = the lamps are usable
  bool holds_lamps = false;          // the rig holds lamps that go back to their owner at exit
  bool ready = false;                // a capture can start
  bool capturing = false;
  bool you_control = false;
  bool controller_taken = false;
  int sets_stored = 0;
  io::Role next_role = io::Role::destination;
  uint64_t free_bytes = 0;
  int clients = 0;
  uint64_t event_seq = 0;            // seq of the last event before this status; the next one is event_seq + 1
  bool plain_tcp = false;            // the rig serves plain TCP (configured so): no encryption
};

struct SetSummary {
  std::string id;
  io::Role role = io::Role::unknown;
  std::string object;
  std::string created;
  cv::Size size;
  int lights = 0;
  std::vector<std::string> warnings;
  bool has_truth = false;
  uint64_t bytes = 0;
  std::string scene;
  std::string deleted;  // sets in the rig's trash: when it was deleted (UTC, ISO 8601)
};

struct Event {
  enum class Kind {
    button_pressed, capture_started, shot_taken, set_stored, capture_failed,
    lamp_state, camera_connected, camera_lost, set_deleted, set_restored,
  };
  Kind kind = Kind::button_pressed;
  uint64_t seq = 0;
  std::string set_id;
  io::Role role = io::Role::unknown;
  std::string object;
  int k = 0, n = 0;            // shot_taken (n also for capture_started)
  double eta_s = 0;
  std::vector<std::string> warnings;
  std::string reason;          // capture_failed, camera_lost
  bool cancelled = false;
  bool long_press = false;
  std::vector<bool> lamps_on;  // lamp_state
  int brightness = 0;
  std::string camera_model;
};
const char* event_name(Event::Kind kind);
std::string describe(const Event& event);  // one line for logs and the CLI

struct LiveFrame {
  std::vector<unsigned char> jpeg;
  uint64_t seq = 0;
  double ts = 0;  // Unix time [s] when the rig took it
  int width = 0, height = 0;
};

struct CaptureOptions {
  io::Role role = io::Role::unknown;  // unknown = the rig's next role
  std::string object;         // empty = the rig decides
  double shutter_s = 0;       // 0 = the rig's configured exposure
  double aperture = 0;
  int iso = 0;
};

// How pull_set fetches a set (see Client::pull_set).
struct PullOptions {
  // truth/ of simulated sets, when present: only for tests and quality
  // measures that ask for it (issue 48: a user's sets never have it, and the
  // simulator's is as large as the photos); default off.
  bool include_truth = false;
  bool overwrite = false;     // replace whatever `folder` holds (this set's own preview is always completed)
  bool live_first = false;    // the preview set first (put in place, then on_preview), then the full files
  // live_first: called on the pulling thread once the preview set is in place
  // at the folder (return quickly: the full files wait for it).
  std::function<void(const std::filesystem::path& folder)> on_preview;
};

struct ConnectOptions {
  std::string client_name = "veneer";
  double connect_timeout_s = 5;   // TCP connect, and the TLS handshake again as long
  double request_timeout_s = 30;
  // --- encryption and pinning (proto/README.md, "Encryption and pinning") ---
  // The rig's certificate must have this fingerprint (64 hex digits, ':'
  // optional); on a match it is pinned in known_rigs. Empty: the known_rigs entry.
  std::string fingerprint;
  // The known-rigs file (tls::default_known_rigs_file() for the user's);
  // empty: none is read or written.
  std::filesystem::path known_rigs;
  // First use (no fingerprint given or known): asked whether `seen` is the
  // rig's (the caller shows it to a person); true pins it in known_rigs,
  // false refuses the rig. Called on the connecting thread, before anything
  // is sent.
  std::function<bool(const std::string& rig, const std::string& seen)> confirm_first_use;
  // With nothing above deciding, a rig reached on a loopback address
  // (127.0.0.0/8, ::1: the connection never leaves this machine) is taken
  // unpinned; any other is refused. The CLI and the viewer set it false.
  bool trust_loopback = true;
  // Plain TCP, no TLS: only for a rig configured --plain-tcp (the token and
  // the photos cross the network in clear).
  bool plain_tcp = false;
};

class Client {
 public:
  // Connects and says hello; fails with the rig's reason (wrong token, ...).
  static Expected<std::unique_ptr<Client>> connect(const Endpoint& endpoint, const std::string& token,
                                                   const ConnectOptions& options = {});
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  // Callbacks (reader thread).
  std::function<void(const Event&)> on_event;
  std::function<void(const LiveFrame&)> on_live_frame;
  std::function<void(const std::string& why)> on_disconnect;

  bool connected() const;
  const RigStatus& hello_status() const;  // the status the rig sent with its hello answer
  // The fingerprint of the rig's certificate ("" in plain TCP).
  const std::string& fingerprint() const;

  Expected<RigStatus> status();
  Expected<std::vector<SetSummary>> list_sets();
  Expected<std::string> manifest(const std::string& set_id);  // set.json text
  // Downloads a set into `folder` as a veneer-set/1 folder (with truth/ only
  // when asked and present): pull_set with {include_truth, overwrite}.
  Status pull(const std::string& set_id, const std::filesystem::path& folder, bool include_truth = false,
              bool overwrite = false, const Progress& progress = {});

  // --- live first (proto/README.md, "Live first") ---------------------------
  //
  //   veneer::rig::PullOptions o;
  //   o.live_first = true;
  //   o.on_preview = [&](const std::filesystem::path& f) { start_live(f); };  // a valid, reduced set
  //   client->pull_set(id, "sets/dest", o, progress);  // returns when the full set is in place
  //
  // Downloads set `set_id` into `folder`. With live_first, first the preview
  // set (pull_preview: set.json at ~1/4 size marked "preview_of": {"id",
  // "size"}, one reduced JPEG per lamp, a few MB) is put in place and
  // on_preview is called; then the full files are fetched and replace it in
  // place in one atomic exchange, so a reader finds either the preview set or
  // the full set, never a mix or half of one. Without live_first only the
  // full set. Resumable: the full files go to ".<name>.pull-<set id>" beside
  // `folder`, each renamed there when whole; an interrupted pull leaves them,
  // and the next pull_set of the same set into the same folder fetches only
  // the missing ones (a rig that predates resuming sends all). A rig that
  // does not serve previews (an older veneerd) gets a plain full pull
  // (on_preview is not called). `folder` may hold this set's preview (it is
  // announced at once and completed) or the set itself (announced, nothing
  // fetched); anything else there is refused unless overwrite. read_set reads
  // the preview set like any set (photos_from "jpeg", set.preview_of says
  // what it previews; the intrinsics are scaled to its size).
  Status pull_set(const std::string& set_id, const std::filesystem::path& folder, const PullOptions& options = {},
                  const Progress& progress = {});
  // Only the preview set, atomically into `folder` (an error when the rig
  // does not serve previews; nothing to do when `folder` already holds this
  // set or its preview).
  Status pull_preview(const std::string& set_id, const std::filesystem::path& folder, bool overwrite = false,
                      const Progress& progress = {});
  Status delete_set(const std::string& set_id);  // into the rig's trash
  Expected<std::vector<SetSummary>> list_trash();  // newest deletion first
  Status restore_set(const std::string& set_id);
  // Starts a capture; returns the id the set will be stored under. Progress
  // and the outcome arrive as events (capture_started, shot_taken, set_stored
  // or capture_failed).
  Expected<std::string> capture(const CaptureOptions& options = {});
  Status cancel_capture();
  Status set_lamps(const std::vector<bool>& on, int brightness = 254);
  Status start_live_view(double fps);
  Status stop_live_view();
  Status press_button(bool long_press = false);  // simulated rig only
  Status move_hand_lamp(const cv::Vec3d& position_m);  // simulated rig only

  // Waits until an event satisfying `match` arrives (events seen since the
  // last wait are kept, so none is missed between a request and the wait).
  Expected<Event> wait_event(const std::function<bool(const Event&)>& match, double timeout_s);

  void close();

  // The start of a file an interrupted pull left as <rel>.part: its size and
  // the CRC-32 of its bytes (FetchImagesRequest.resume_from).
  struct Partial {
    std::string file;
    uint64_t size = 0;
    uint32_t crc32 = 0;
  };
  struct Impl;  // public so the reader in client.cpp can name it

 private:
  Client();
  Status check_pin(const Endpoint& endpoint, const std::string& seen, bool loopback);
  Expected<std::vector<SetSummary>> list(bool trash);
  struct Fetched {
    std::vector<std::string> files;    // sent, in order
    std::vector<std::string> skipped;  // left out (the client had them)
    std::vector<std::string> resumed;  // sent from where the client's <rel>.part ended
  };
  // One fetch_images (preview = false) or fetch_preview download into `dir`,
  // each file written as <rel>.part and renamed to <rel> when whole; the files
  // in `partial` continue their <rel>.part when the rig resumes them. An
  // interrupted download keeps every <rel>.part it wrote.
  Expected<Fetched> fetch_into(const std::string& set_id, bool preview, bool include_truth,
                               const std::vector<std::string>& skip, const std::vector<Partial>& partial,
                               const std::filesystem::path& dir, const Progress& progress);
  std::unique_ptr<Impl> impl_;
};

}  // namespace veneer::rig
