// Finding the JPEG preview a DNG (or another TIFF-based RAW file) embeds
// (dng.hpp), by walking its IFDs: no LibRaw, no decoding, only the few
// hundred bytes of the tables read.
#include <cerrno>
#include <cstring>
#include <functional>
#include <set>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "veneer/io/dng.hpp"

namespace veneer::io {

namespace {

// Reads n bytes at an offset of the file, or fails.
using ReadAt = std::function<bool(uint64_t offset, size_t n, std::string& out)>;

class Tiff {
 public:
  Tiff(ReadAt read, uint64_t size) : read_(std::move(read)), size_(size) {}

  std::string error;

  bool header(uint32_t& first_ifd) {
    std::string h;
    if (!read_(0, 8, h)) return fail("shorter than a TIFF header");
    if (h.compare(0, 2, "II") == 0)
      big_ = false;
    else if (h.compare(0, 2, "MM") == 0)
      big_ = true;
    else
      return fail("not a TIFF-based file (no II/MM byte order mark)");
    if (u16(h.data() + 2) != 42) return fail("not a TIFF-based file (no 42 after the byte order)");
    first_ifd = u32(h.data() + 4);
    return true;
  }

  // One IFD's tags of interest; `next` is the next IFD's offset (0 = none).
  struct Ifd {
    uint32_t subfile = 0, width = 0, height = 0, compression = 0, samples = 1, bits = 0;
    uint64_t strip_offset = 0, strip_bytes = 0, jif_offset = 0, jif_bytes = 0;
    int strips = 0;
    std::vector<uint32_t> sub_ifds;
    uint32_t next = 0;
  };

  bool ifd(uint32_t at, Ifd& out) {
    std::string count_bytes;
    if (!read_(at, 2, count_bytes)) return fail("an IFD lies outside the file");
    const unsigned n = u16(count_bytes.data());
    if (n == 0 || n > 1000) return fail("an IFD with " + std::to_string(n) + " entries");
    std::string table;
    if (!read_(static_cast<uint64_t>(at) + 2, n * 12u + 4u, table)) return fail("an IFD runs past the end of the file");
    for (unsigned i = 0; i < n; ++i) {
      const char* e = table.data() + 12 * i;
      const unsigned tag = u16(e), type = u16(e + 2);
      const uint32_t count = u32(e + 4);
      auto value = [&](uint32_t k) -> uint32_t {  // SHORT, LONG or IFD (13) value k, inline or out of line
        const unsigned width = type == 3 ? 2 : 4;
        if (type != 3 && type != 4 && type != 13) return 0;
        if (static_cast<uint64_t>(count) * width <= 4) return width == 2 ? u16(e + 8 + 2 * k) : u32(e + 8);
        std::string v;
        if (!read_(static_cast<uint64_t>(u32(e + 8)) + static_cast<uint64_t>(k) * width, width, v)) return 0;
        return width == 2 ? u16(v.data()) : u32(v.data());
      };
      if (count == 0) continue;
      switch (tag) {
        case 254: out.subfile = value(0); break;
        case 256: out.width = value(0); break;
        case 257: out.height = value(0); break;
        case 258: out.bits = value(0); break;
        case 259: out.compression = value(0); break;
        case 273: out.strip_offset = value(0); out.strips = static_cast<int>(count); break;
        case 277: out.samples = value(0); break;
        case 279: out.strip_bytes = value(0); break;
        case 330:
          for (uint32_t k = 0; k < count && k < 16; ++k) out.sub_ifds.push_back(value(k));
          break;
        case 513: out.jif_offset = value(0); break;
        case 514: out.jif_bytes = value(0); break;
        default: break;
      }
    }
    out.next = u32(table.data() + 12 * n);
    return true;
  }

  bool read(uint64_t at, size_t n, std::string& out) { return read_(at, n, out); }
  uint64_t size() const { return size_; }

 private:
  bool fail(const std::string& what) {
    if (error.empty()) error = what;
    return false;
  }
  unsigned u16(const char* p) const {
    const auto* b = reinterpret_cast<const unsigned char*>(p);
    return big_ ? (b[0] << 8 | b[1]) : (b[1] << 8 | b[0]);
  }
  uint32_t u32(const char* p) const {
    const auto* b = reinterpret_cast<const unsigned char*>(p);
    return big_ ? (uint32_t{b[0]} << 24 | uint32_t{b[1]} << 16 | uint32_t{b[2]} << 8 | b[3])
                : (uint32_t{b[3]} << 24 | uint32_t{b[2]} << 16 | uint32_t{b[1]} << 8 | b[0]);
  }
  ReadAt read_;
  uint64_t size_ = 0;
  bool big_ = false;
};

Expected<DngPreview> find_preview(Tiff& tiff, const std::string& name) {
  uint32_t first = 0;
  if (!tiff.header(first)) return make_error(name + ": " + tiff.error);
  std::vector<uint32_t> pending_ifds;  // IFD0's chain, then SubIFDs one level down
  std::set<uint32_t> seen;
  for (uint32_t at = first; at != 0 && pending_ifds.size() < 8 && seen.insert(at).second;) {
    pending_ifds.push_back(at);
    Tiff::Ifd d;
    if (!tiff.ifd(at, d)) return make_error(name + ": " + tiff.error);
    at = d.next;
  }
  DngPreview best;
  for (size_t i = 0; i < pending_ifds.size() && i < 64; ++i) {
    Tiff::Ifd d;
    if (!tiff.ifd(pending_ifds[i], d)) return make_error(name + ": " + tiff.error);
    if (i < 8) {
      for (uint32_t s : d.sub_ifds) {
        if (s != 0 && seen.insert(s).second) pending_ifds.push_back(s);
      }
    }
    const bool reduced = (d.subfile & 1) != 0;
    const bool jpeg = d.compression == 6 || d.compression == 7;
    if (!reduced || !jpeg || d.samples != 3 || d.bits != 8) continue;
    uint64_t offset = d.strips == 1 ? d.strip_offset : 0, length = d.strips == 1 ? d.strip_bytes : 0;
    if (length == 0 && d.jif_bytes > 0) {
      offset = d.jif_offset;
      length = d.jif_bytes;
    }
    if (length < 4 || offset + length > tiff.size()) continue;
    std::string soi;
    if (!tiff.read(offset, 2, soi) || soi != "\xff\xd8") continue;
    if (static_cast<uint64_t>(d.width) * d.height > static_cast<uint64_t>(best.size.area())) {
      best.offset = offset;
      best.length = length;
      best.size = cv::Size(static_cast<int>(d.width), static_cast<int>(d.height));
    }
  }
  if (best.length == 0) return make_error(name + ": has no embedded JPEG preview");
  return best;
}

}  // namespace

Expected<DngPreview> find_dng_preview(std::string_view bytes, uint64_t file_size, const std::string& name) {
  Tiff tiff(
      [bytes](uint64_t at, size_t n, std::string& out) {
        if (at > bytes.size() || n > bytes.size() - at) return false;
        out.assign(bytes.data() + at, n);
        return true;
      },
      file_size);
  return find_preview(tiff, name);
}

Expected<DngPreview> find_dng_preview(const std::filesystem::path& file) {
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return make_error(file.string() + ": cannot open: " + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    ::close(fd);
    return make_error(file.string() + ": cannot stat");
  }
  Tiff tiff(
      [fd, &st](uint64_t at, size_t n, std::string& out) {
        if (at > static_cast<uint64_t>(st.st_size) || n > static_cast<uint64_t>(st.st_size) - at) return false;
        out.resize(n);
        size_t done = 0;
        while (done < n) {
          const ssize_t r = ::pread(fd, out.data() + done, n - done, static_cast<off_t>(at + done));
          if (r < 0 && errno == EINTR) continue;
          if (r <= 0) return false;
          done += static_cast<size_t>(r);
        }
        return true;
      },
      static_cast<uint64_t>(st.st_size));
  auto found = find_preview(tiff, file.string());
  ::close(fd);
  return found;
}

Expected<std::string> read_dng_preview(const std::filesystem::path& file) {
  auto p = find_dng_preview(file);
  if (!p) return p.error();
  const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return make_error(file.string() + ": cannot open: " + std::strerror(errno));
  std::string out(static_cast<size_t>(p->length), '\0');
  size_t done = 0;
  while (done < out.size()) {
    const ssize_t r = ::pread(fd, out.data() + done, out.size() - done, static_cast<off_t>(p->offset + done));
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) break;
    done += static_cast<size_t>(r);
  }
  ::close(fd);
  if (done != out.size()) return make_error(file.string() + ": cannot read its preview");
  return out;
}

}  // namespace veneer::io
