# Veneer — the front door.
#   make          install what is missing (tools/install-deps), build into build/ (programs in build/bin/)
#   make demo     install what is missing, build, run the main job on the simulated rig
#   make test     install what is missing, build, run every test (CTest)
#   make bench    run the benchmarks and print their tables
#   make asan     address/undefined-sanitizer build + tests in build-asan/
#   make fuzz     build the libFuzzer targets with clang and run each briefly

BUILD      ?= build
BUILD_TYPE ?= Release
JOBS       ?= $(shell nproc)
CMAKE_ARGS ?=
FUZZ_SECONDS ?= 30

.PHONY: all deps configure build demo test bench asan fuzz clean

all: deps
	@$(MAKE) --no-print-directory build

deps:
	@tools/install-deps

$(BUILD)/build.ninja:
	@cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=$(BUILD_TYPE) $(CMAKE_ARGS) || { \
	  echo "make: configuring failed; if a library (OpenCV, LibRaw, ...) is missing, run: make deps"; exit 1; }

configure: $(BUILD)/build.ninja

build: configure
	cmake --build $(BUILD) -j $(JOBS)

demo: deps
	@$(MAKE) --no-print-directory build
	tools/demo.sh $(BUILD)

test: deps
	@$(MAKE) --no-print-directory build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS) --timeout 600

bench: deps
	@$(MAKE) --no-print-directory build
	tools/bench.sh $(BUILD)

asan: deps
	cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DVENEER_SANITIZE=ON $(CMAKE_ARGS)
	cmake --build build-asan -j $(JOBS)
	cd build-asan && ASAN_OPTIONS=detect_leaks=1 ctest --output-on-failure -j $(JOBS) --timeout 1200

fuzz: deps
	CC=clang CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DVENEER_FUZZ=ON -DVENEER_BUILD_APP=OFF $(CMAKE_ARGS)
	cmake --build build-fuzz -j $(JOBS) --target fuzz-all
	tools/fuzz.sh build-fuzz $(FUZZ_SECONDS)

clean:
	rm -rf $(BUILD) build-asan build-fuzz demo-out
