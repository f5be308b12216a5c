#pragma once
// The edge between the wire (veneer.v1 protobuf messages) and the daemon's own
// types. Everything a client sends is checked here and refused with an error
// that says what was wrong; nothing past this file sees a protobuf type.
#include <cstdint>
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
struct ListSetsReq {};
struct GetManifestReq { std::string set_id; };
struct FetchImagesReq { std::string set_id; bool include_truth = false; size_t chunk_size = 0; };
struct DeleteSetReq { std::string set_id; };
struct CaptureReq { CaptureRequest capture; };
struct CancelReq {};
struct SetLampsReq { std::vector<bool> on; int brightness = 254; };
struct StartLiveReq { double fps = 10; };
struct StopLiveReq {};
struct PressReq { bool long_press = false; };
struct MoveHandLampReq { cv::Vec3d position; };

using Body = std::variant<Hello, StatusReq, ListSetsReq, GetManifestReq, FetchImagesReq, DeleteSetReq, CaptureReq,
                          CancelReq, SetLampsReq, StartLiveReq, StopLiveReq, PressReq, MoveHandLampReq>;

struct Request {
  uint64_t id = 0;
  Body body;
};

// Requests that need the controller role (one client at a time).
bool needs_control(const Body& body);
const char* request_name(const Body& body);

constexpr size_t kMaxChunkBytes = 4u << 20;
constexpr size_t kDefaultChunkBytes = 256u << 10;
constexpr double kMaxLiveFps = 60;

// Checks and converts one client message. The error says which field of
// which request was wrong.
veneer::Expected<Request> decode(const veneer::v1::ClientMessage& message);

// Rig -> wire.
void encode_event(const RigEvent& event, uint64_t seq, veneer::v1::RigMessage& out);
void encode_set(const StoredSet& set, veneer::v1::SetInfo& out);

}  // namespace veneerd::api
