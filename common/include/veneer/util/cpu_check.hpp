// A program built for AVX2 and FMA (cmake -DVENEER_AVX2=ON, the default on
// x86-64) stops at once, with one line saying why, on a processor without
// them, instead of dying later of an illegal instruction in the middle of a
// transfer. Include this header in the file holding main() (once per
// program): the check runs before the program's other static initialisers,
// and is itself compiled for plain x86-64 so that it runs anywhere.
#pragma once

#if defined(__x86_64__) && defined(__AVX2__) && defined(__FMA__)
#include <cstdio>
#include <cstdlib>

namespace veneer::detail {

__attribute__((constructor(101), target("arch=x86-64"), used)) inline void require_build_cpu() {
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return;
  std::fputs(
      "veneer: this build needs a processor with AVX2 and FMA (x86-64 from 2013 on), and this one lacks them; "
      "rebuild with cmake -DVENEER_AVX2=OFF for any x86-64\n",
      stderr);
  std::_Exit(1);
}

}  // namespace veneer::detail
#endif
