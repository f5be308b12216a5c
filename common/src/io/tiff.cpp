// The io module's TIFF directory reader (tiff.hpp).
#include "tiff.hpp"

#include <cstring>

namespace veneer::io::detail {

Tiff::Tiff(std::string_view bytes)
    : Tiff(
          [bytes](uint64_t at, size_t n, std::string& out) {
            if (at > bytes.size() || n > bytes.size() - at) return false;
            out.assign(bytes.data() + at, n);
            return true;
          },
          bytes.size()) {}

uint32_t Tiff::u16(const char* p) const {
  const auto* b = reinterpret_cast<const unsigned char*>(p);
  return big_ ? (uint32_t{b[0]} << 8 | b[1]) : (uint32_t{b[1]} << 8 | b[0]);
}

uint32_t Tiff::u32(const char* p) const {
  const auto* b = reinterpret_cast<const unsigned char*>(p);
  return big_ ? (uint32_t{b[0]} << 24 | uint32_t{b[1]} << 16 | uint32_t{b[2]} << 8 | b[3])
              : (uint32_t{b[3]} << 24 | uint32_t{b[2]} << 16 | uint32_t{b[1]} << 8 | b[0]);
}

Tiff::Header Tiff::header(uint32_t& first_directory) {
  std::string h;
  if (!read_(0, 8, h)) return Header::too_short;
  if (h.compare(0, 2, "II") == 0)
    big_ = false;
  else if (h.compare(0, 2, "MM") == 0)
    big_ = true;
  else
    return Header::no_byte_order;
  if (u16(h.data() + 2) != 42) return Header::no_42;
  first_directory = u32(h.data() + 4);
  return Header::tiff;
}

Tiff::Read Tiff::directory(uint32_t at, TiffDirectory& out, unsigned* entries, unsigned min_entries,
                           unsigned max_entries) {
  std::string count_bytes;
  if (!read_(at, 2, count_bytes)) return Read::count_outside;
  const unsigned n = u16(count_bytes.data());
  if (entries) *entries = n;
  if (n < min_entries || n > max_entries) return Read::entries_out_of_range;
  std::string table;
  if (!read_(static_cast<uint64_t>(at) + 2, n * 12u + 4u, table)) return Read::table_outside;
  out.entries.resize(n);
  for (unsigned i = 0; i < n; ++i) {
    const char* e = table.data() + 12 * i;
    TiffEntry& t = out.entries[i];
    t.tag = u16(e);
    t.type = u16(e + 2);
    t.count = u32(e + 4);
    t.offset = u32(e + 8);
    std::memcpy(t.field, e + 8, 4);
  }
  out.next = u32(table.data() + 12 * n);
  return Read::ok;
}

uint32_t Tiff::value(const TiffEntry& e, uint32_t k) {
  if (e.type != 3 && e.type != 4 && e.type != 13) return 0;
  const unsigned width = e.type == 3 ? 2 : 4;
  if (static_cast<uint64_t>(e.count) * width <= 4) return width == 2 ? u16(e.field + 2 * k) : u32(e.field);
  std::string v;
  if (!read_(static_cast<uint64_t>(e.offset) + static_cast<uint64_t>(k) * width, width, v)) return 0;
  return width == 2 ? u16(v.data()) : u32(v.data());
}

uint64_t Tiff::value_bytes(const TiffEntry& e) {
  // Bytes per value of TIFF's field types 1..13 (0: not a TIFF type).
  static constexpr uint32_t kTypeBytes[14] = {0, 1, 1, 2, 4, 8, 1, 1, 2, 4, 8, 4, 8, 4};
  return e.type < 14 ? static_cast<uint64_t>(kTypeBytes[e.type]) * e.count : 0;
}

}  // namespace veneer::io::detail
