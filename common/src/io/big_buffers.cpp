// Large image buffers, prefaulted in one call (big_buffers.hpp).
#include "veneer/io/big_buffers.hpp"

#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>

namespace veneer::io {

namespace {

// Below this, OpenCV's allocator (malloc). (32 MiB, where glibc stops
// reusing freed heap for big blocks, was measured too: the demo pair's cold
// preparation was ~0.05 s slower, its warm one no faster.)
constexpr size_t kMinBig = size_t(4) << 20;
constexpr size_t kAutoStep = 0x7fffffff;     // CV_AUTOSTEP of core_c.h: "work the step out"

// An anonymous mapping of `bytes`, its pages faulted in by the kernel in one
// call (MAP_POPULATE) when they fit in half the free memory (a size a
// damaged file declares is not made resident up front); nullptr when it
// fails.
void* map_populated(size_t bytes) {
  const long free_pages = ::sysconf(_SC_AVPHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  const bool populate = free_pages > 0 && page > 0 && bytes <= size_t(free_pages) * size_t(page) / 2;
  void* p = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | (populate ? MAP_POPULATE : 0),
                   -1, 0);
  return p == MAP_FAILED ? nullptr : p;
}

// OpenCV's StdMatAllocator with the data mapped by map_populated when large.
class PrefaultAllocator final : public cv::MatAllocator {
 public:
  cv::UMatData* allocate(int dims, const int* sizes, int type, void* data0, size_t* step, cv::AccessFlag,
                         cv::UMatUsageFlags) const override {
    size_t total = CV_ELEM_SIZE(type);
    for (int i = dims - 1; i >= 0; --i) {
      if (step) {
        if (data0 && step[i] != kAutoStep) total = step[i];
        else step[i] = total;
      }
      total *= size_t(sizes[i]);
    }
    void* data = data0;
    bool mapped = false;
    if (!data) {
      if (total >= kMinBig && (data = map_populated(total))) mapped = true;
      else data = cv::fastMalloc(total);
    }
    auto* u = new cv::UMatData(this);
    u->data = u->origdata = static_cast<uchar*>(data);
    u->size = total;
    if (data0) u->flags |= cv::UMatData::USER_ALLOCATED;
    if (mapped) u->handle = reinterpret_cast<void*>(1);  // how to free it
    return u;
  }
  bool allocate(cv::UMatData* u, cv::AccessFlag, cv::UMatUsageFlags) const override { return u != nullptr; }
  void deallocate(cv::UMatData* u) const override {
    if (!u) return;
    if (!(u->flags & cv::UMatData::USER_ALLOCATED)) {
      if (u->handle) ::munmap(u->origdata, u->size);
      else cv::fastFree(u->origdata);
      u->origdata = nullptr;
    }
    delete u;
  }
};

}  // namespace

cv::MatAllocator* prefault_allocator() {
  static auto* a = new PrefaultAllocator;  // never destroyed: Mats may outlive static destruction
  return a;
}

cv::Mat big_mat(int rows, int cols, int type) {
  cv::Mat m;
  m.allocator = prefault_allocator();
  m.create(rows, cols, type);
  return m;
}

}  // namespace veneer::io
