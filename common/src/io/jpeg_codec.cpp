// JPEGs through libjpeg (jpeg_codec.hpp).
#include "jpeg_codec.hpp"

#ifdef VENEER_HAVE_LIBJPEG
#include <csetjmp>
#include <cstdio>
#include <memory>

#include <jpeglib.h>
#endif

namespace veneer::io::detail {

#ifdef VENEER_HAVE_LIBJPEG
namespace {
struct Failure {
  jpeg_error_mgr mgr;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX] = {};
};
void on_error(j_common_ptr c) {
  auto* f = reinterpret_cast<Failure*>(c->err);
  (*c->err->format_message)(c, f->message);
  std::longjmp(f->jump, 1);
}
void on_message(j_common_ptr) {}  // warnings (e.g. extraneous bytes) are not printed
}  // namespace

std::optional<Expected<cv::Mat>> decode_jpeg8(std::string_view bytes, int factor, const std::string& name) {
  if (factor != 1 && factor != 2 && factor != 4 && factor != 8)
    return make_error(name + ": JPEG reduction " + std::to_string(factor) + " is not 1, 2, 4 or 8");
  // Everything the decoder touches lives behind one pointer set before the
  // setjmp and never changed after it: what longjmp returns to is in memory,
  // not in registers.
  struct Context {
    Failure failure;
    jpeg_decompress_struct info{};
    cv::Mat out;
    bool to_opencv = false;
  };
  const auto c = std::make_unique<Context>();
  c->info.err = jpeg_std_error(&c->failure.mgr);
  c->failure.mgr.error_exit = on_error;
  c->failure.mgr.output_message = on_message;
  jpeg_create_decompress(&c->info);
  if (setjmp(c->failure.jump)) {
    jpeg_destroy_decompress(&c->info);
    return make_error(name + ": corrupt or truncated JPEG (" + c->failure.message + ")");
  }
  jpeg_mem_src(&c->info, reinterpret_cast<const unsigned char*>(bytes.data()), static_cast<unsigned long>(bytes.size()));
  jpeg_read_header(&c->info, TRUE);
  // CMYK files are left to OpenCV, which converts them as it always did
  c->to_opencv = c->info.jpeg_color_space == JCS_CMYK || c->info.jpeg_color_space == JCS_YCCK;
  if (!c->to_opencv) {
    c->info.scale_num = 1;
    c->info.scale_denom = static_cast<unsigned>(factor);
    c->info.out_color_space = JCS_EXT_BGR;  // grey files too: libjpeg spreads them
    jpeg_start_decompress(&c->info);
    c->out.create(static_cast<int>(c->info.output_height), static_cast<int>(c->info.output_width), CV_8UC3);
    while (c->info.output_scanline < c->info.output_height) {
      JSAMPROW row = c->out.ptr<unsigned char>(static_cast<int>(c->info.output_scanline));
      jpeg_read_scanlines(&c->info, &row, 1);
    }
    jpeg_finish_decompress(&c->info);
  }
  jpeg_destroy_decompress(&c->info);
  if (c->to_opencv) return std::nullopt;
  return Expected<cv::Mat>(std::move(c->out));
}
#else
std::optional<Expected<cv::Mat>> decode_jpeg8(std::string_view, int, const std::string&) { return std::nullopt; }
#endif

}  // namespace veneer::io::detail
