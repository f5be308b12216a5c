# Veneer — the front door.
#   make          install what is missing (tools/install-dev-deps), build into build/ (programs in build/bin/)
#   make demo     install what is missing of the demo's packages only (tools/debian-packages.txt), build
#                 only the programs the demo runs (veneerd, veneer; no Qt, no tests configured),
#                 run the main job on the simulated rig (and veneer-viewer, if built, with a display)
#   make test     install what is missing (tools/install-test-deps: also headless Chromium for the
#                 web page's test), build everything but the benchmarks, run every test (CTest)
#   make bench    build the benchmarks (target benches) and run them, printing their tables
#   make buildtime  a cold build (no compiler cache) in build-time/: wall time of make demo's and
#                 make test's targets, the load beside them, the slowest translation units
#   make soak     SOAK_CAPTURES (default 1000) captures and as many pulls against veneerd --simulate with
#                 injected faults (SOAK_FAULTS, a fault-plan SPEC; default: every fault); writes
#                 soak-out/report.json and soak-out/soak.png (not part of make test; a short run is)
#   make asan     address/undefined-sanitizer build + tests in build-asan/
#   make fuzz     build the libFuzzer targets with clang and run each briefly
#   make package  Debian packages into build-package/: veneerd (arm64, cross-built, and amd64),
#                 veneer and veneer-viewer (amd64); lintian; then package-test
#   make package-test  install them into fresh Debian 12 roots (amd64, arm64 under qemu-user) and run them

BUILD      ?= build
BUILD_TYPE ?= Release
JOBS       ?= $(shell nproc)
CMAKE_ARGS ?=
FUZZ_SECONDS ?= 30

PACKAGE_OUT ?= build-package
SOAK_CAPTURES ?= 1000
SOAK_FAULTS ?=

.PHONY: all deps dev-deps test-deps configure configure-demo build demo test bench soak buildtime asan fuzz package package-deps package-test clean

all: dev-deps
	@$(MAKE) --no-print-directory build

# What `make demo` needs (tools/debian-packages.txt): building veneerd and veneer, running the demo.
deps:
	@tools/install-deps
# Also the viewer's, the tests' and the fuzz build's (tools/debian-packages-dev.txt): everything but `make demo`.
dev-deps:
	@tools/install-dev-deps
# Also Chromium (tools/debian-packages-test.txt), which only the tests use.
test-deps:
	@tools/install-test-deps

# A build folder is configured for everything (the viewer, the tests), but
# `make demo` configures a new one without them (issue 49: its first picture
# waits for neither Qt nor GoogleTest to be installed); `make`, `make test`,
# ... reconfigure such a folder with them, keeping what is built.
CONFIGURE = cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=$(BUILD_TYPE)
CONFIGURE_FAILED = { echo "make: configuring failed; if a library (OpenCV, LibRaw, Qt, ...) is missing, run: make dev-deps (make demo: make deps)"; exit 1; }

configure:
	@if [ ! -f $(BUILD)/build.ninja ] || grep -qE '^VENEER_BUILD_(APP|TESTS):BOOL=OFF' $(BUILD)/CMakeCache.txt; then \
	  $(CONFIGURE) -DVENEER_BUILD_APP=ON -DVENEER_BUILD_TESTS=ON $(CMAKE_ARGS) || $(CONFIGURE_FAILED); fi

configure-demo:
	@if [ ! -f $(BUILD)/build.ninja ]; then \
	  $(CONFIGURE) -DVENEER_BUILD_APP=OFF -DVENEER_BUILD_TESTS=OFF $(CMAKE_ARGS) || $(CONFIGURE_FAILED); fi

build: configure
	cmake --build $(BUILD) -j $(JOBS)

# What tools/demo.sh runs, and the libraries they link: nothing else.
demo: deps
	@$(MAKE) --no-print-directory configure-demo
	@echo "make demo: building veneerd and veneer (make builds veneer-viewer too, make test the tests, make bench the benchmarks)"
	cmake --build $(BUILD) -j $(JOBS) --target veneerd veneer
	tools/demo.sh $(BUILD)

test: test-deps
	@$(MAKE) --no-print-directory build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS) --timeout 600

bench: dev-deps
	@$(MAKE) --no-print-directory build
	cmake --build $(BUILD) -j $(JOBS) --target benches
	tools/bench.sh $(BUILD)

soak: dev-deps
	@$(MAKE) --no-print-directory configure
	cmake --build $(BUILD) -j $(JOBS) --target veneer_soak
	$(BUILD)/tests/veneer_soak --captures $(SOAK_CAPTURES) --out soak-out $(if $(SOAK_FAULTS),--faults '$(SOAK_FAULTS)')

buildtime: dev-deps
	tools/buildtime.sh build-time $(JOBS)

asan: dev-deps
	cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DVENEER_SANITIZE=ON $(CMAKE_ARGS)
	cmake --build build-asan -j $(JOBS)
	cd build-asan && ASAN_OPTIONS=detect_leaks=1 ctest --output-on-failure -j $(JOBS) --timeout 1200

fuzz: dev-deps
	CC=clang CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DVENEER_FUZZ=ON -DVENEER_BUILD_APP=OFF $(CMAKE_ARGS)
	cmake --build build-fuzz -j $(JOBS) --target fuzz-all
	tools/fuzz.sh build-fuzz $(FUZZ_SECONDS)

# Debian packages (tools/package/build.sh) and their install test
# (tools/package/test.sh); the cross toolchain, lintian, debootstrap and
# qemu-user-static come from tools/debian-packages-package.txt, installed here only.
package-deps:
	@tools/install-package-deps

package: dev-deps package-deps
	JOBS=$(JOBS) tools/package/build.sh $(PACKAGE_OUT)
	tools/package/test.sh $(PACKAGE_OUT)

package-test: package-deps
	tools/package/test.sh $(PACKAGE_OUT)

clean:
	rm -rf $(BUILD) build-asan build-fuzz build-time demo-out soak-out fuzz-out $(PACKAGE_OUT)
