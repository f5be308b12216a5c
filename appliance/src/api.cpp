#include "veneerd/api.hpp"

#include <cmath>

#include <google/protobuf/io/coded_stream.h>

#include "veneer/proto/utf8.hpp"
#include "veneer/v1/rig.pb.h"

namespace veneerd::api {

using veneer::make_error;
namespace pb = veneer::v1;

namespace {

bool printable(const std::string& s) {
  for (unsigned char ch : s) {
    if (ch < 0x20 || ch == 0x7f) return false;
  }
  return true;
}

// A name limit counts characters (Unicode code points), as the contract says;
// bytes that are not UTF-8 are refused (proto3 parsing refuses them first,
// this holds wherever a name comes from).
veneer::Status check_name(const std::string& field, const std::string& value, size_t max_chars) {
  const auto chars = veneer::wire::utf8_length(value);
  if (!chars) return make_error(field + ": not valid UTF-8 (every string field is UTF-8)");
  if (*chars > max_chars) {
    return make_error(field + ": " + std::to_string(*chars) + " characters is longer than the limit of " +
                      std::to_string(max_chars));
  }
  if (veneer::wire::has_control_character(value)) return make_error(field + ": must be printable (no control characters)");
  return {};
}

veneer::Expected<veneer::io::Role> decode_role(int role) {
  switch (role) {
    case pb::ROLE_UNSPECIFIED: return veneer::io::Role::unknown;
    case pb::ROLE_DESTINATION: return veneer::io::Role::destination;
    case pb::ROLE_SOURCE: return veneer::io::Role::source;
    default: return make_error("capture.role: unknown role " + std::to_string(role));
  }
}

pb::Role encode_role(veneer::io::Role role) {
  switch (role) {
    case veneer::io::Role::destination: return pb::ROLE_DESTINATION;
    case veneer::io::Role::source: return pb::ROLE_SOURCE;
    default: return pb::ROLE_UNSPECIFIED;
  }
}

veneer::Status check_set_id(const std::string& field, const std::string& id) {
  if (!valid_set_id(id)) {
    std::string shown = id.size() > 40 ? id.substr(0, 40) + "..." : id;
    if (!printable(shown)) shown = "(unprintable)";
    return make_error(field + ": '" + shown + "' is not a set id");
  }
  return {};
}

// A fetch's chunk size in bytes (0 = the default), or an error naming `field`.
veneer::Expected<size_t> check_chunk_size(const std::string& field, uint32_t requested) {
  const size_t chunk = requested == 0 ? kDefaultChunkBytes : requested;
  if (chunk < kMinChunkBytes || chunk > kMaxChunkBytes)
    return make_error(field + ": " + std::to_string(requested) + " is outside 1 KiB..4 MiB");
  return chunk;
}

}  // namespace

std::string trim_token(const std::string& token) {
  const char* space = " \t\r\n\v\f";
  size_t first = token.find_first_not_of(space);
  if (first == std::string::npos) return {};
  size_t last = token.find_last_not_of(space);
  return token.substr(first, last - first + 1);
}

bool needs_control(const Body& body) {
  return std::holds_alternative<CaptureReq>(body) || std::holds_alternative<CancelReq>(body) ||
         std::holds_alternative<SetLampsReq>(body) || std::holds_alternative<PressReq>(body) ||
         std::holds_alternative<MoveHandLampReq>(body) || std::holds_alternative<DeleteSetReq>(body) ||
         std::holds_alternative<RestoreSetReq>(body);
}

const char* request_name(const Body& body) {
  static const char* names[] = {"hello", "status", "list_sets", "get_manifest", "fetch_images", "delete_set", "capture",
                                "cancel_capture", "set_lamps", "start_live_view", "stop_live_view", "press_button",
                                "move_hand_lamp", "restore_set", "fetch_preview"};
  return names[body.index()];
}

veneer::Expected<Request> decode(const pb::ClientMessage& m) {
  Request r;
  r.id = m.id();
  switch (m.body_case()) {
    case pb::ClientMessage::kHello: {
      const auto& h = m.hello();
      if (h.token().size() > kMaxTokenBytes) {
        return make_error("hello.token: " + std::to_string(h.token().size()) + " bytes is longer than the limit of " +
                          std::to_string(kMaxTokenBytes));
      }
      if (auto s = check_name("hello.client_name", h.client_name(), kMaxClientNameChars); !s) return s.error();
      r.body = Hello{h.protocol_version(), h.token(), h.client_name()};
      return r;
    }
    case pb::ClientMessage::kStatus: r.body = StatusReq{}; return r;
    case pb::ClientMessage::kListSets: r.body = ListSetsReq{m.list_sets().trash()}; return r;
    case pb::ClientMessage::kGetManifest:
      if (auto s = check_set_id("get_manifest.set_id", m.get_manifest().set_id()); !s) return s.error();
      r.body = GetManifestReq{m.get_manifest().set_id()};
      return r;
    case pb::ClientMessage::kFetchImages: {
      const auto& f = m.fetch_images();
      if (auto s = check_set_id("fetch_images.set_id", f.set_id()); !s) return s.error();
      auto chunk = check_chunk_size("fetch_images.chunk_size", f.chunk_size());
      if (!chunk) return chunk.error();
      if (static_cast<size_t>(f.skip_files_size()) > kMaxSkipFiles) {
        return make_error("fetch_images.skip_files: " + std::to_string(f.skip_files_size()) +
                          " files is more than the limit of " + std::to_string(kMaxSkipFiles));
      }
      FetchImagesReq req{f.set_id(), f.include_truth(), *chunk, {}, {}};
      for (const auto& name : f.skip_files()) {
        if (name.empty() || name.size() > kMaxSkipFileChars || !printable(name)) {
          return make_error("fetch_images.skip_files: each must be a file name of 1.." +
                            std::to_string(kMaxSkipFileChars) + " printable characters");
        }
        req.skip_files.push_back(name);
      }
      if (static_cast<size_t>(f.resume_from_size()) > kMaxSkipFiles) {
        return make_error("fetch_images.resume_from: " + std::to_string(f.resume_from_size()) +
                          " files is more than the limit of " + std::to_string(kMaxSkipFiles));
      }
      for (const auto& from : f.resume_from()) {
        if (from.file().empty() || from.file().size() > kMaxSkipFileChars || !printable(from.file())) {
          return make_error("fetch_images.resume_from: each file must be a name of 1.." +
                            std::to_string(kMaxSkipFileChars) + " printable characters");
        }
        req.resume_from.push_back({from.file(), from.offset(), from.crc32()});
      }
      r.body = std::move(req);
      return r;
    }
    case pb::ClientMessage::kFetchPreview: {
      const auto& f = m.fetch_preview();
      if (auto s = check_set_id("fetch_preview.set_id", f.set_id()); !s) return s.error();
      auto chunk = check_chunk_size("fetch_preview.chunk_size", f.chunk_size());
      if (!chunk) return chunk.error();
      r.body = FetchPreviewReq{f.set_id(), *chunk};
      return r;
    }
    case pb::ClientMessage::kDeleteSet:
      if (auto s = check_set_id("delete_set.set_id", m.delete_set().set_id()); !s) return s.error();
      r.body = DeleteSetReq{m.delete_set().set_id()};
      return r;
    case pb::ClientMessage::kCapture: {
      const auto& c = m.capture();
      CaptureReq req;
      auto role = decode_role(c.role());
      if (!role) return role.error();
      req.capture.role = *role;
      if (auto s = check_name("capture.object", c.object(), kMaxObjectChars); !s) return s.error();
      req.capture.object = c.object();
      const auto& e = c.exposure();
      if (!std::isfinite(e.shutter_s()) || e.shutter_s() < 0 || e.shutter_s() > kMaxShutterS) {
        return make_error("capture.exposure.shutter_s: " + std::to_string(e.shutter_s()) + " is outside 0..60 s");
      }
      if (!std::isfinite(e.aperture()) || e.aperture() < 0 || e.aperture() > kMaxAperture) {
        return make_error("capture.exposure.aperture: " + std::to_string(e.aperture()) + " is outside 0..64");
      }
      if (e.iso() > kMaxIso) return make_error("capture.exposure.iso: " + std::to_string(e.iso()) + " is too high");
      req.capture.exposure.shutter_s = e.shutter_s();
      req.capture.exposure.aperture = e.aperture();
      req.capture.exposure.iso = static_cast<int>(e.iso());
      r.body = req;
      return r;
    }
    case pb::ClientMessage::kCancelCapture: r.body = CancelReq{}; return r;
    case pb::ClientMessage::kSetLamps: {
      const auto& l = m.set_lamps();
      if (l.on_size() > kMaxLampsInRequest) return make_error("set_lamps.on: " + std::to_string(l.on_size()) + " lamps is too many");
      if (l.brightness() > kMaxBrightness) {
        return make_error("set_lamps.brightness: " + std::to_string(l.brightness()) + " is outside 1..254");
      }
      SetLampsReq req;
      req.on.assign(l.on().begin(), l.on().end());
      req.brightness = static_cast<int>(l.brightness() == 0 ? kMaxBrightness : l.brightness());
      r.body = req;
      return r;
    }
    case pb::ClientMessage::kStartLiveView: {
      double fps = m.start_live_view().fps();
      if (fps == 0) fps = kDefaultLiveFps;
      if (!std::isfinite(fps) || fps < kMinLiveFps || fps > kMaxLiveFps) {
        return make_error("start_live_view.fps: " + std::to_string(fps) + " is outside 0.1..60");
      }
      r.body = StartLiveReq{fps};
      return r;
    }
    case pb::ClientMessage::kStopLiveView: r.body = StopLiveReq{}; return r;
    case pb::ClientMessage::kPressButton: r.body = PressReq{m.press_button().long_press()}; return r;
    case pb::ClientMessage::kMoveHandLamp: {
      const auto& p = m.move_hand_lamp().position();
      cv::Vec3d v(p.x(), p.y(), p.z());
      for (int i = 0; i < 3; ++i) {
        if (!std::isfinite(v[i]) || std::abs(v[i]) > kMaxHandLampDistanceM) {
          return make_error("move_hand_lamp.position: each coordinate must be within 5 m of the object");
        }
      }
      if (cv::norm(v) < kMinHandLampDistanceM) return make_error("move_hand_lamp.position: closer than 5 cm to the object");
      r.body = MoveHandLampReq{v};
      return r;
    }
    case pb::ClientMessage::kRestoreSet:
      if (auto s = check_set_id("restore_set.set_id", m.restore_set().set_id()); !s) return s.error();
      r.body = RestoreSetReq{m.restore_set().set_id()};
      return r;
    case pb::ClientMessage::BODY_NOT_SET:
      break;
  }
  return make_error("unknown or empty request (id " + std::to_string(m.id()) + ")");
}

bool encode_chunk(const ChunkHeader& h, size_t data_size, const std::function<bool(char*, size_t)>& read,
                  std::string& out) {
  using google::protobuf::io::CodedOutputStream;
  // Everything but the data through protobuf; the data field (length-delimited)
  // is appended by hand after it (field order does not matter to a parser).
  pb::ImageChunk head;
  head.set_request_id(h.request_id);
  head.set_set_id(h.set_id);
  head.set_file(h.file);
  head.set_offset(h.offset);
  head.set_file_size(h.file_size);
  head.set_last(h.last);
  head.set_end_of_set(h.end_of_set);
  constexpr uint32_t kLengthDelimited = 2;
  const uint32_t data_tag = (pb::ImageChunk::kDataFieldNumber << 3) | kLengthDelimited;
  const uint32_t chunk_tag = (pb::RigMessage::kChunkFieldNumber << 3) | kLengthDelimited;
  const size_t head_len = head.ByteSizeLong();
  const size_t data_len = data_size == 0 ? 0
                                         : CodedOutputStream::VarintSize32(data_tag) +
                                               CodedOutputStream::VarintSize64(data_size) + data_size;
  const size_t chunk_len = head_len + data_len;
  const size_t message_len =
      CodedOutputStream::VarintSize32(chunk_tag) + CodedOutputStream::VarintSize64(chunk_len) + chunk_len;
  out.resize(CodedOutputStream::VarintSize64(message_len) + message_len);
  auto* p = reinterpret_cast<uint8_t*>(out.data());
  p = CodedOutputStream::WriteVarint64ToArray(message_len, p);
  p = CodedOutputStream::WriteVarint32ToArray(chunk_tag, p);
  p = CodedOutputStream::WriteVarint64ToArray(chunk_len, p);
  p = head.SerializeWithCachedSizesToArray(p);
  if (data_size > 0) {
    p = CodedOutputStream::WriteVarint32ToArray(data_tag, p);
    p = CodedOutputStream::WriteVarint64ToArray(data_size, p);
    if (!read(reinterpret_cast<char*>(p), data_size)) {
      out.clear();
      return false;
    }
  }
  return true;
}

void encode_set(const StoredSet& s, pb::SetInfo& info) {
  pb::SetInfo* out = &info;
  out->set_id(s.id);
  out->set_role(encode_role(s.role));
  out->set_object(s.object);
  out->set_created(s.created);
  out->set_width(static_cast<uint32_t>(s.size.width));
  out->set_height(static_cast<uint32_t>(s.size.height));
  out->set_lights(static_cast<uint32_t>(s.lights));
  for (const auto& w : s.warnings) out->add_warnings(w);
  out->set_has_truth(s.has_truth);
  out->set_bytes(s.bytes);
  out->set_scene(s.scene);
  out->set_deleted(s.deleted);
}

void encode_event(const RigEvent& e, uint64_t seq, pb::RigMessage& out) {
  pb::Event* ev = out.mutable_event();
  ev->set_seq(seq);
  using K = RigEvent::Kind;
  switch (e.kind) {
    case K::button_pressed: ev->mutable_button_pressed()->set_long_press(e.long_press); break;
    case K::capture_started: {
      auto* c = ev->mutable_capture_started();
      c->set_set_id(e.set_id);
      c->set_role(encode_role(e.role));
      c->set_object(e.object);
      c->set_shots(static_cast<uint32_t>(e.n));
      break;
    }
    case K::shot_taken: {
      auto* s = ev->mutable_shot_taken();
      s->set_set_id(e.set_id);
      s->set_k(static_cast<uint32_t>(e.k));
      s->set_n(static_cast<uint32_t>(e.n));
      s->set_eta_s(e.eta_s);
      break;
    }
    case K::set_stored: {
      auto* s = ev->mutable_set_stored();
      s->set_id(e.set_id);
      for (const auto& w : e.warnings) s->add_warnings(w);
      break;
    }
    case K::capture_failed: {
      auto* f = ev->mutable_capture_failed();
      f->set_set_id(e.set_id);
      f->set_reason(e.reason);
      f->set_cancelled(e.cancelled);
      break;
    }
    case K::lamp_state: {
      auto* l = ev->mutable_lamp_state();
      for (bool on : e.lamps_on) l->add_on(on);
      l->set_brightness(static_cast<uint32_t>(e.brightness));
      break;
    }
    case K::camera_connected: ev->mutable_camera_connected()->set_model(e.camera_model); break;
    case K::camera_lost: ev->mutable_camera_lost()->set_reason(e.reason); break;
    case K::set_deleted: ev->mutable_set_deleted()->set_id(e.set_id); break;
    case K::set_restored: ev->mutable_set_restored()->set_id(e.set_id); break;
  }
}

}  // namespace veneerd::api
