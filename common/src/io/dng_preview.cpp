// Finding the JPEG preview a DNG (or another TIFF-based RAW file) embeds
// (dng.hpp), by walking its IFDs (tiff.hpp, the walker the RAW structure
// check shares): no LibRaw, no decoding, only the few hundred bytes of the
// tables read.
#include <cerrno>
#include <cstring>
#include <set>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "tiff.hpp"
#include "veneer/io/dng.hpp"

namespace veneer::io {

namespace {

using detail::Tiff;

// The tags of one IFD a preview is found by; `next` is the next IFD's offset (0 = none).
struct Ifd {
  uint32_t subfile = 0, width = 0, height = 0, compression = 0, samples = 1, bits = 0;
  uint64_t strip_offset = 0, strip_bytes = 0, jif_offset = 0, jif_bytes = 0;
  int strips = 0;
  std::vector<uint32_t> sub_ifds;
  uint32_t next = 0;
};

// The IFD at `at`, or an error saying what is wrong with it.
std::string read_ifd(Tiff& tiff, uint32_t at, Ifd& out) {
  detail::TiffDirectory d;
  unsigned n = 0;
  switch (tiff.directory(at, d, &n, 1, 1000)) {
    case Tiff::Read::ok: break;
    case Tiff::Read::count_outside: return "an IFD lies outside the file";
    case Tiff::Read::entries_out_of_range: return "an IFD with " + std::to_string(n) + " entries";
    case Tiff::Read::table_outside: return "an IFD runs past the end of the file";
  }
  for (const detail::TiffEntry& e : d.entries) {
    if (e.count == 0) continue;
    switch (e.tag) {
      case 254: out.subfile = tiff.value(e, 0); break;
      case 256: out.width = tiff.value(e, 0); break;
      case 257: out.height = tiff.value(e, 0); break;
      case 258: out.bits = tiff.value(e, 0); break;
      case 259: out.compression = tiff.value(e, 0); break;
      case 273: out.strip_offset = tiff.value(e, 0); out.strips = static_cast<int>(e.count); break;
      case 277: out.samples = tiff.value(e, 0); break;
      case 279: out.strip_bytes = tiff.value(e, 0); break;
      case 330:
        for (uint32_t k = 0; k < e.count && k < 16; ++k) out.sub_ifds.push_back(tiff.value(e, k));
        break;
      case 513: out.jif_offset = tiff.value(e, 0); break;
      case 514: out.jif_bytes = tiff.value(e, 0); break;
      default: break;
    }
  }
  out.next = d.next;
  return {};
}

Expected<DngPreview> find_preview(Tiff& tiff, const std::string& name) {
  uint32_t first = 0;
  switch (tiff.header(first)) {
    case Tiff::Header::tiff: break;
    case Tiff::Header::too_short: return make_error(name + ": shorter than a TIFF header");
    case Tiff::Header::no_byte_order: return make_error(name + ": not a TIFF-based file (no II/MM byte order mark)");
    case Tiff::Header::no_42: return make_error(name + ": not a TIFF-based file (no 42 after the byte order)");
  }
  std::vector<uint32_t> pending_ifds;  // IFD0's chain, then SubIFDs one level down
  std::set<uint32_t> seen;
  for (uint32_t at = first; at != 0 && pending_ifds.size() < 8 && seen.insert(at).second;) {
    pending_ifds.push_back(at);
    Ifd d;
    if (std::string why = read_ifd(tiff, at, d); !why.empty()) return make_error(name + ": " + why);
    at = d.next;
  }
  DngPreview best;
  for (size_t i = 0; i < pending_ifds.size() && i < 64; ++i) {
    Ifd d;
    if (std::string why = read_ifd(tiff, pending_ifds[i], d); !why.empty()) return make_error(name + ": " + why);
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
      [bytes](uint64_t at, size_t n, std::string& out) {  // the bytes may be a head of the file
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
