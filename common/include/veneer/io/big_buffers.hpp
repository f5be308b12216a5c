#pragma once
// Large image buffers, their pages faulted in by the kernel in one call. A
// full-resolution frame as float RGB is 252 MB: its first touch, one page
// fault per 4 KiB, is what perf showed next to PNG decoding at the top of a
// cold read (this machine: ~0.45 s/GiB touched, ~0.37 s/GiB with
// MAP_POPULATE). Transparent huge pages were measured too and are slower to
// get in a fresh process (0.9-1.8 s/GiB: compaction), so they are not asked
// for. Mats made here behave as any Mat (shared, released, cloned); below
// 4 MiB they come from OpenCV's usual allocator.
#include <opencv2/core.hpp>

namespace veneer::io {

// The allocator behind big_mat; set as `m.allocator` on an empty Mat before
// m.create().
cv::MatAllocator* prefault_allocator();

// A rows x cols Mat of `type` (uninitialised) from prefault_allocator().
cv::Mat big_mat(int rows, int cols, int type);
inline cv::Mat big_mat(cv::Size size, int type) { return big_mat(size.height, size.width, type); }

}  // namespace veneer::io
