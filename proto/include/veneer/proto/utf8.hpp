#pragma once
// UTF-8 as the rig API counts it (proto/README.md): string fields are UTF-8
// (proto3 refuses anything else when parsing), and every limit on a name
// counts characters, i.e. Unicode code points, not bytes.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace google::protobuf {
class Descriptor;
}

namespace veneer::wire {

// The number of code points in `s`, or nullopt when `s` is not valid UTF-8
// (RFC 3629: no overlong forms, no surrogates, nothing above U+10FFFF, no
// sequence cut short).
std::optional<size_t> utf8_length(std::string_view s);

// Whether valid UTF-8 `s` holds a control character: C0 (U+0000..U+001F),
// DEL (U+007F) or C1 (U+0080..U+009F).
bool has_control_character(std::string_view s);

// The first string field of a serialised message of `type` whose bytes are
// not valid UTF-8: its path as the API names fields ("hello.client_name",
// "capture.object"), and the message's top-level `id` field when it has one.
// nullopt when every string field is valid or the bytes do not parse as
// fields at all (that is then some other fault).
struct InvalidUtf8 {
  std::string field;
  uint64_t id = 0;
};
std::optional<InvalidUtf8> find_invalid_utf8(const google::protobuf::Descriptor& type, std::string_view bytes);

}  // namespace veneer::wire
