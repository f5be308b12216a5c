// OpenCV's image codecs opened on first use (codecs.hpp).
#include "veneer/io/codecs.hpp"

#include <dlfcn.h>

#include <mutex>

#ifndef VENEER_IMGCODECS_SONAME
#define VENEER_IMGCODECS_SONAME "libopencv_imgcodecs.so"
#endif

namespace veneer::io::codecs {
namespace {

using Decode = cv::Mat (*)(const cv::_InputArray&, int);
using Encode = bool (*)(const std::string&, const cv::_InputArray&, std::vector<uchar>&, const std::vector<int>&);
using Read = cv::Mat (*)(const std::string&, int);
using Write = bool (*)(const std::string&, const cv::_InputArray&, const std::vector<int>&);

struct Table {
  Decode decode = nullptr;
  Encode encode = nullptr;
  Read read = nullptr;
  Write write = nullptr;
  std::string error;
};

// The C++ functions by their (Itanium ABI) names: what the program would
// have bound at start had it linked the library.
const Table& table() {
  static Table t;
  static std::once_flag once;
  std::call_once(once, [] {
    void* lib = ::dlopen(VENEER_IMGCODECS_SONAME, RTLD_NOW | RTLD_GLOBAL);
    if (!lib) {
      const char* e = ::dlerror();
      t.error = std::string("OpenCV's image codecs (" VENEER_IMGCODECS_SONAME ") could not be loaded: ") +
                (e ? e : "unknown error");
      return;
    }
    t.decode = reinterpret_cast<Decode>(::dlsym(lib, "_ZN2cv8imdecodeERKNS_11_InputArrayEi"));
    t.encode = reinterpret_cast<Encode>(::dlsym(
        lib, "_ZN2cv8imencodeERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEERKNS_11_InputArrayERSt6vectorIhSaIhEERKSB_IiSaIiEE"));
    t.read = reinterpret_cast<Read>(::dlsym(lib, "_ZN2cv6imreadERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEEi"));
    t.write = reinterpret_cast<Write>(::dlsym(
        lib, "_ZN2cv7imwriteERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEERKNS_11_InputArrayERKSt6vectorIiSaIiEE"));
    if (!t.decode || !t.encode || !t.read || !t.write)
      t.error = "OpenCV's image codecs (" VENEER_IMGCODECS_SONAME ") lack imdecode/imencode/imread/imwrite";
  });
  if (!t.error.empty()) CV_Error(cv::Error::StsError, t.error);
  return t;
}

}  // namespace

cv::Mat imdecode(cv::InputArray bytes, int flags) { return table().decode(bytes, flags); }

bool imencode(const std::string& ext, cv::InputArray image, std::vector<uchar>& bytes, const std::vector<int>& params) {
  return table().encode(ext, image, bytes, params);
}

cv::Mat imread(const std::string& file, int flags) { return table().read(file, flags); }

bool imwrite(const std::string& file, cv::InputArray image, const std::vector<int>& params) {
  return table().write(file, image, params);
}

bool loaded() {
  void* lib = ::dlopen(VENEER_IMGCODECS_SONAME, RTLD_NOW | RTLD_NOLOAD);
  if (lib) ::dlclose(lib);
  return lib != nullptr;
}

}  // namespace veneer::io::codecs
