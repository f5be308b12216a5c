# CMake toolchain for cross-building veneerd for the rig's board (Raspberry Pi,
# 64-bit Raspberry Pi OS / Debian 12 arm64) on an amd64 Debian 12 machine, with
# Debian's cross compiler (crossbuild-essential-arm64) and the arm64 libraries
# of an arm64 Debian 12 root given as -DVENEER_ARM64_SYSROOT=DIR (build.sh
# debootstraps it; without it, the libraries installed multiarch as
# libfoo-dev:arm64 in /usr/lib/aarch64-linux-gnu).
# Programs (protoc) are the build machine's; libraries, headers and CMake
# package files are looked up for aarch64 only.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)
list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES VENEER_ARM64_SYSROOT)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
if(VENEER_ARM64_SYSROOT)
  set(CMAKE_SYSROOT ${VENEER_ARM64_SYSROOT})
  set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
  set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
  set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)
  set(ENV{PKG_CONFIG_SYSROOT_DIR} ${VENEER_ARM64_SYSROOT})
  set(ENV{PKG_CONFIG_LIBDIR}
    "${VENEER_ARM64_SYSROOT}/usr/lib/aarch64-linux-gnu/pkgconfig:${VENEER_ARM64_SYSROOT}/usr/share/pkgconfig")
else()
  # Multiarch shares /usr; the compiler's own search path is aarch64 only.
  set(ENV{PKG_CONFIG_LIBDIR} "/usr/lib/aarch64-linux-gnu/pkgconfig:/usr/share/pkgconfig")
endif()
