#include "veneer/proto/framing.hpp"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>
#include <google/protobuf/message.h>
#include <google/protobuf/util/delimited_message_util.h>

namespace veneer::wire {

namespace pbio = google::protobuf::io;

bool append_delimited(const google::protobuf::MessageLite& message, std::string& out) {
  pbio::StringOutputStream stream(&out);
  return google::protobuf::util::SerializeDelimitedToZeroCopyStream(message, &stream);
}

std::string encode_delimited(const google::protobuf::MessageLite& message) {
  std::string out;
  if (!append_delimited(message, out)) out.clear();
  return out;
}

void FrameBuffer::feed(const void* data, size_t size) {
  // Drop consumed bytes now and then so the buffer does not grow forever.
  if (start_ > 0 && (start_ >= buf_.size() / 2 || start_ > (1u << 20))) {
    buf_.erase(0, start_);
    start_ = 0;
  }
  buf_.append(static_cast<const char*>(data), size);
}

ReadResult FrameBuffer::next(google::protobuf::MessageLite& out) {
  if (!error_.empty()) return ReadResult::error;
  const size_t avail = buf_.size() - start_;
  const auto* p = reinterpret_cast<const uint8_t*>(buf_.data() + start_);
  // Is the varint prefix complete? (Its value is read by protobuf below.)
  size_t prefix_len = 0;
  while (prefix_len < avail && (p[prefix_len] & 0x80) != 0) {
    if (++prefix_len >= 5) {
      error_ = "length prefix longer than 5 bytes";
      return ReadResult::error;
    }
  }
  if (prefix_len >= avail) return ReadResult::need_more;
  ++prefix_len;

  uint64_t length = 0;
  {
    pbio::CodedInputStream coded(p, static_cast<int>(prefix_len));
    if (!coded.ReadVarint64(&length)) {
      error_ = "unreadable length prefix";
      return ReadResult::error;
    }
  }
  if (length > max_) {
    error_ = "message of " + std::to_string(length) + " bytes exceeds the limit of " +
             std::to_string(max_) + " bytes";
    return ReadResult::error;
  }
  if (avail - prefix_len < length) return ReadResult::need_more;

  const size_t total = prefix_len + static_cast<size_t>(length);
  pbio::ArrayInputStream stream(p, static_cast<int>(total));
  bool clean_eof = false;
  if (!google::protobuf::util::ParseDelimitedFromZeroCopyStream(&out, &stream, &clean_eof)) {
    // proto3 refuses a string field that is not UTF-8: when that is the only
    // fault, say which field, skip the message and keep the stream.
    const auto* full = dynamic_cast<const google::protobuf::Message*>(&out);
    const std::string_view body(reinterpret_cast<const char*>(p) + prefix_len, static_cast<size_t>(length));
    if (auto bad = full ? find_invalid_utf8(*full->GetDescriptor(), body) : std::nullopt) {
      invalid_ = std::move(*bad);
      consume(total);
      return ReadResult::invalid;
    }
    error_ = "unparsable message of " + std::to_string(length) + " bytes";
    return ReadResult::error;
  }
  consume(total);
  return ReadResult::message;
}

void FrameBuffer::consume(size_t bytes) {
  start_ += bytes;
  if (start_ == buf_.size()) {
    buf_.clear();
    start_ = 0;
  }
}

}  // namespace veneer::wire
