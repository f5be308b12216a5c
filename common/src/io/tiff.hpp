#pragma once
// Walking a TIFF-based file's image directories (IFDs) without decoding
// anything: the one TIFF reader of the io module (not part of the public
// API), serving the DNG preview finder (dng_preview.cpp) and the RAW
// structure check (check_raw_structure, raw_decode.cpp). Only the bytes of
// the header, the directories and the values asked for are read, through a
// ReadAt (a mapped file's bytes, or pread on a descriptor).
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace veneer::io::detail {

// Reads n bytes at an offset of the file into out, or returns false.
using ReadAt = std::function<bool(uint64_t offset, size_t n, std::string& out)>;

// One 12-byte directory entry as stored.
struct TiffEntry {
  uint32_t tag = 0, type = 0, count = 0;
  uint32_t offset = 0;  // the value field read as a LONG: where values over 4 bytes lie
  char field[4] = {};   // the value field's bytes (values of 4 bytes or less lie here)
};

struct TiffDirectory {
  std::vector<TiffEntry> entries;
  uint32_t next = 0;  // the next directory's offset (0: none)
};

class Tiff {
 public:
  // size: the file's size (read may reach less of it, e.g. a head of the file).
  Tiff(ReadAt read, uint64_t size) : read_(std::move(read)), size_(size) {}
  // Over bytes held in memory (the whole file).
  explicit Tiff(std::string_view bytes);

  enum class Header { tiff, too_short, no_byte_order, no_42 };
  // The byte order and the first directory's offset.
  Header header(uint32_t& first_directory);

  enum class Read { ok, count_outside, entries_out_of_range, table_outside };
  // The directory at `at`: count_outside when its entry count lies past the
  // end, entries_out_of_range when it has fewer than min or more than max
  // entries (before its table is read), table_outside when its entries or
  // the next offset run past the end.
  Read directory(uint32_t at, TiffDirectory& out, unsigned* entries = nullptr, unsigned min_entries = 0,
                 unsigned max_entries = 65535);

  // Value k of a SHORT (3), LONG (4) or IFD (13) entry, inline or out of
  // line; 0 for another type or a value that cannot be read.
  uint32_t value(const TiffEntry& e, uint32_t k);
  // The bytes an entry's values take (count times the type's size; 0 for a
  // type TIFF does not define).
  static uint64_t value_bytes(const TiffEntry& e);

  bool read(uint64_t at, size_t n, std::string& out) { return read_(at, n, out); }
  uint64_t size() const { return size_; }

 private:
  uint32_t u16(const char* p) const;
  uint32_t u32(const char* p) const;
  ReadAt read_;
  uint64_t size_ = 0;
  bool big_ = false;  // MM: big-endian
};

}  // namespace veneer::io::detail
