// Fuzz target: the rig API's message reader on both sides (veneerd reading
// ClientMessages, the client reading RigMessages) and the daemon's check of
// every request (veneerd::api::decode).
#include <cstddef>
#include <cstdint>

#include "veneer/proto/framing.hpp"
#include "veneer/v1/rig.pb.h"
#include "veneerd/api.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  {
    veneer::wire::FrameBuffer in(1u << 20);
    // Feed in two parts to exercise partial messages.
    in.feed(data, size / 2);
    veneer::v1::ClientMessage m;
    // A message whose only fault is a string that is not UTF-8 is skipped
    // (ReadResult::invalid, the field named); the stream goes on.
    auto drain = [&] {
      for (int i = 0; i < 1000; ++i) {
        auto r = in.next(m);
        if (r == veneer::wire::ReadResult::message) (void)veneerd::api::decode(m);
        else if (r == veneer::wire::ReadResult::invalid) (void)in.invalid().field.size();
        else break;
      }
    };
    drain();
    in.feed(data + size / 2, size - size / 2);
    drain();
  }
  {
    veneer::wire::FrameBuffer in(1u << 20);
    in.feed(data, size);
    veneer::v1::RigMessage m;
    for (int i = 0; i < 1000 && in.next(m) == veneer::wire::ReadResult::message; ++i) {
    }
  }
  return 0;
}
