#pragma once
// The edge between the wire (veneer.v1 protobuf messages) and the daemon's own
// types. Everything a client sends is checked here and refused with an error
// that says what was wrong; nothing past this file sees a protobuf type.
#include <cstdint>
#include <functional>
#include <string>
#include <variant>
#include <vector>

#include <opencv2/core.hpp>

#include "veneer/util/expected.hpp"
#include "veneerd/rig.hpp"
#include "veneerd/store.hpp"

namespace veneer::v1 {
class ClientMessage;
class RigMessage;
class SetInfo;
}  // namespace veneer::v1

namespace veneerd::api {

struct Hello { uint32_t protocol_version = 0; std::string token; std::string client_name; };
struct StatusReq {};
struct ListSetsReq { bool trash = false; };
struct GetManifestReq { std::string set_id; };
struct ResumeFrom {
  std::string file;
  uint64_t offset = 0;
  uint32_t crc32 = 0;  // of the file's first `offset` bytes (veneer::io::crc32)
};
struct FetchImagesReq {
  std::string set_id;
  bool include_truth = false;
  size_t chunk_size = 0;
  std::vector<std::string> skip_files;  // files the client holds whole (a resumed pull)
  std::vector<ResumeFrom> resume_from;  // files the client holds the start of (a resumed pull)
};
struct DeleteSetReq { std::string set_id; };
struct CaptureReq { CaptureRequest capture; };
struct CancelReq {};
struct SetLampsReq { std::vector<bool> on; int brightness = 254; };
struct StartLiveReq { double fps = 10; };  // kDefaultLiveFps
struct StopLiveReq {};
struct PressReq { bool long_press = false; };
struct MoveHandLampReq { cv::Vec3d position; };
struct RestoreSetReq { std::string set_id; };
struct FetchPreviewReq { std::string set_id; size_t chunk_size = 0; };  // live first: the preview set

using Body = std::variant<Hello, StatusReq, ListSetsReq, GetManifestReq, FetchImagesReq, DeleteSetReq, CaptureReq,
                          CancelReq, SetLampsReq, StartLiveReq, StopLiveReq, PressReq, MoveHandLampReq,
                          RestoreSetReq, FetchPreviewReq>;

struct Request {
  uint64_t id = 0;
  Body body;
};

// Requests that need the controller role (one client at a time).
bool needs_control(const Body& body);
const char* request_name(const Body& body);

// Limits of the requests (proto/README.md lists them; a test checks that the
// README says these numbers).
constexpr size_t kMaxTokenBytes = 256;        // hello.token, before trimming
constexpr size_t kMaxClientNameChars = 128;   // hello.client_name, printable
constexpr size_t kMinChunkBytes = 1u << 10;   // fetch_images.chunk_size
constexpr size_t kMaxChunkBytes = 4u << 20;
constexpr size_t kDefaultChunkBytes = 256u << 10;
constexpr double kMinLiveFps = 0.1;           // start_live_view.fps
constexpr double kMaxLiveFps = 60;
constexpr double kDefaultLiveFps = 10;
constexpr size_t kMaxObjectChars = 64;        // capture.object, printable
constexpr double kMaxShutterS = 60;           // capture.exposure.shutter_s
constexpr double kMaxAperture = 64;           // capture.exposure.aperture (f-number)
constexpr uint32_t kMaxIso = 409600;          // capture.exposure.iso
constexpr int kMaxLampsInRequest = 64;        // set_lamps.on
constexpr uint32_t kMaxBrightness = 254;      // set_lamps.brightness (0 = this)
constexpr double kMaxHandLampDistanceM = 5;   // move_hand_lamp.position, per coordinate
constexpr double kMinHandLampDistanceM = 0.05;
constexpr size_t kMaxSkipFiles = 4096;        // fetch_images.skip_files entries
constexpr size_t kMaxSkipFileChars = 200;     // ... each a relative path of this many characters at most

// The token as a client sent it, without surrounding whitespace (a client
// that sends the token file's bytes, newline included, is accepted).
std::string trim_token(const std::string& token);

// Checks and converts one client message. The error says which field of
// which request was wrong.
veneer::Expected<Request> decode(const veneer::v1::ClientMessage& message);

// One piece of a FetchImages stream, as the server knows it.
struct ChunkHeader {
  uint64_t request_id = 0;
  std::string set_id;
  std::string file;
  uint64_t offset = 0;
  uint64_t file_size = 0;
  bool last = false;
  bool end_of_set = false;
};
// Encodes RigMessage{chunk} length-prefixed into `out` (replacing it), with
// `data_size` bytes of data that `read(dst, n)` writes straight into place:
// a chunk of up to 4 MiB is allocated and copied once, not twice.
// False when `read` fails.
bool encode_chunk(const ChunkHeader& header, size_t data_size, const std::function<bool(char*, size_t)>& read,
                  std::string& out);

// Rig -> wire.
void encode_event(const RigEvent& event, uint64_t seq, veneer::v1::RigMessage& out);
void encode_set(const StoredSet& set, veneer::v1::SetInfo& out);

}  // namespace veneerd::api
