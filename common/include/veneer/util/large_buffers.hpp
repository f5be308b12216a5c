// Large pictures go back to the system when freed. glibc serves a request
// from mmap only above a threshold that it raises to the size of each mmapped
// block freed (up to 32 MB), so after the first few frames the 5-30 MB rows,
// planes and half-float copies of a full-resolution transfer come from the
// heap, where they fragment it: `veneer transfer` at 5600x3750 peaked at
// 4.05 GiB with the moving threshold and 3.77 GiB with it fixed at 8 MB, in
// the same time (issue 42). Include this header in the file holding main()
// (once per program); setting the threshold fixes it.
#pragma once

#include <cstdlib>  // defines __GLIBC__ on glibc

#if defined(__GLIBC__)
#include <malloc.h>

namespace veneer::detail {

__attribute__((constructor(102), used)) inline void fixed_mmap_threshold() { mallopt(M_MMAP_THRESHOLD, 8 << 20); }

}  // namespace veneer::detail
#endif
