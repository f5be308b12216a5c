#include "veneer/proto/utf8.hpp"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/wire_format_lite.h>

namespace veneer::wire {

namespace {

// Decodes the code point at s[i], advancing i; -1 when the bytes there are
// not a valid UTF-8 sequence.
long next_code_point(std::string_view s, size_t& i) {
  const auto byte = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
  const unsigned char b0 = byte(i);
  if (b0 < 0x80) {
    ++i;
    return b0;
  }
  int len = 0;
  long cp = 0, min = 0;
  if ((b0 & 0xE0) == 0xC0) {
    len = 2, cp = b0 & 0x1F, min = 0x80;
  } else if ((b0 & 0xF0) == 0xE0) {
    len = 3, cp = b0 & 0x0F, min = 0x800;
  } else if ((b0 & 0xF8) == 0xF0) {
    len = 4, cp = b0 & 0x07, min = 0x10000;
  } else {
    return -1;  // a continuation byte first, or 0xF8..0xFF
  }
  if (i + static_cast<size_t>(len) > s.size()) return -1;
  for (int k = 1; k < len; ++k) {
    const unsigned char b = byte(i + static_cast<size_t>(k));
    if ((b & 0xC0) != 0x80) return -1;
    cp = (cp << 6) | (b & 0x3F);
  }
  if (cp < min || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return -1;
  i += static_cast<size_t>(len);
  return cp;
}

namespace wfl = google::protobuf::internal;
using google::protobuf::FieldDescriptor;

// Walks the fields of one message; `prefix` names where it sits.
bool walk(const google::protobuf::Descriptor& type, std::string_view bytes, const std::string& prefix, int depth,
          InvalidUtf8& out, bool top) {
  google::protobuf::io::CodedInputStream in(reinterpret_cast<const uint8_t*>(bytes.data()),
                                            static_cast<int>(bytes.size()));
  while (uint32_t tag = in.ReadTag()) {
    const FieldDescriptor* f = type.FindFieldByNumber(static_cast<int>(wfl::WireFormatLite::GetTagFieldNumber(tag)));
    switch (wfl::WireFormatLite::GetTagWireType(tag)) {
      case wfl::WireFormatLite::WIRETYPE_VARINT: {
        uint64_t v = 0;
        if (!in.ReadVarint64(&v)) return false;
        if (top && f && f->name() == "id") out.id = v;
        break;
      }
      case wfl::WireFormatLite::WIRETYPE_FIXED64: {
        uint64_t v = 0;
        if (!in.ReadLittleEndian64(&v)) return false;
        break;
      }
      case wfl::WireFormatLite::WIRETYPE_FIXED32: {
        uint32_t v = 0;
        if (!in.ReadLittleEndian32(&v)) return false;
        break;
      }
      case wfl::WireFormatLite::WIRETYPE_LENGTH_DELIMITED: {
        uint32_t len = 0;
        std::string value;
        if (!in.ReadVarint32(&len) || !in.ReadString(&value, static_cast<int>(len))) return false;
        if (!f) break;
        if (f->type() == FieldDescriptor::TYPE_STRING && !utf8_length(value)) {
          if (out.field.empty()) out.field = prefix + f->name();
        } else if (f->type() == FieldDescriptor::TYPE_MESSAGE && depth < 16 && out.field.empty()) {
          if (!walk(*f->message_type(), value, prefix + f->name() + ".", depth + 1, out, false)) return false;
        }
        break;
      }
      default:
        return false;  // groups: not in this API
    }
  }
  return in.ConsumedEntireMessage();
}

}  // namespace

std::optional<size_t> utf8_length(std::string_view s) {
  size_t n = 0;
  for (size_t i = 0; i < s.size(); ++n) {
    if (next_code_point(s, i) < 0) return std::nullopt;
  }
  return n;
}

bool has_control_character(std::string_view s) {
  for (size_t i = 0; i < s.size();) {
    const long cp = next_code_point(s, i);
    if (cp < 0) return false;  // not UTF-8: utf8_length says so
    if (cp < 0x20 || (cp >= 0x7F && cp <= 0x9F)) return true;
  }
  return false;
}

std::optional<InvalidUtf8> find_invalid_utf8(const google::protobuf::Descriptor& type, std::string_view bytes) {
  InvalidUtf8 out;
  if (!walk(type, bytes, "", 0, out, true) || out.field.empty()) return std::nullopt;
  return out;
}

}  // namespace veneer::wire
