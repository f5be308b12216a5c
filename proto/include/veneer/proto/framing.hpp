#pragma once
// Framing of the rig API: protobuf's delimited format (a varint byte count,
// then the message), read with a size limit that is checked before anything
// is allocated for the message.
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include <google/protobuf/message_lite.h>

#include "veneer/proto/utf8.hpp"

namespace veneer::wire {

constexpr uint32_t kProtocolVersion = 1;
constexpr uint16_t kDefaultPort = 7878;
// Largest message either side accepts. Image chunks and live frames stay far
// below it; anything announcing more is refused unread.
constexpr size_t kMaxMessageBytes = 16u << 20;

// Appends `message`, length-prefixed, to `out`. False if it cannot be
// serialised (e.g. larger than 2 GiB).
bool append_delimited(const google::protobuf::MessageLite& message, std::string& out);
std::string encode_delimited(const google::protobuf::MessageLite& message);

enum class ReadResult {
  message,    // one message parsed
  need_more,  // the buffer holds only part of a message
  invalid,    // a whole message whose only fault is a string field that is not
              // UTF-8 (proto3 refuses it): skipped, `invalid()` names the field;
              // the stream goes on with the next message
  error,      // the stream is broken (bad prefix, too large, unparsable): close it
};

// Accumulates bytes from a stream and takes whole messages off its front.
class FrameBuffer {
 public:
  explicit FrameBuffer(size_t max_message_bytes = kMaxMessageBytes) : max_(max_message_bytes) {}

  void feed(const void* data, size_t size);
  // Parses the next message into `out`. On error, `error()` says what was
  // wrong; the buffer is then unusable.
  ReadResult next(google::protobuf::MessageLite& out);
  const std::string& error() const { return error_; }
  // After ReadResult::invalid: the field that is not UTF-8, and the message's id.
  const InvalidUtf8& invalid() const { return invalid_; }
  size_t buffered() const { return buf_.size() - start_; }

 private:
  void consume(size_t bytes);
  std::string buf_;
  size_t start_ = 0;
  size_t max_;
  std::string error_;
  InvalidUtf8 invalid_;
};

}  // namespace veneer::wire
