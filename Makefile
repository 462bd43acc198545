# Exocet entry points. `make demo` and `make test` work on a fresh Debian bookworm machine:
# each installs the Debian packages it needs, builds the catkin workspace and runs.
SHELL := /bin/bash
# A pyenv python3 ahead of /usr/bin breaks catkin and pluginlib's cmake: Debian's ROS wants /usr/bin/python3.
export PATH := /usr/bin:/bin:/usr/sbin:/sbin:$(PATH)
export ROS_HOME ?= $(CURDIR)/out/ros
JOBS ?= $(shell nproc)
BUILD_TYPE ?= Release
# ccache (installed by tools/install-deps.sh) makes a rebuild, CI's fresh clone included, cost what changed only;
# paths under the workspace are hashed relative to it, so that other clones share the cache.
export CCACHE_BASEDIR := $(CURDIR)
CCACHE := $(shell command -v ccache 2>/dev/null)
LAUNCHER := $(if $(CCACHE),-DCMAKE_CXX_COMPILER_LAUNCHER=$(CCACHE) -DCMAKE_C_COMPILER_LAUNCHER=$(CCACHE))

.PHONY: all deps build bags demo test check bench soak format clean
all: build

deps:
	@tools/install-deps.sh

build: deps
	@mkdir -p out
	catkin_make -j$(JOBS) -DCMAKE_BUILD_TYPE=$(BUILD_TYPE) -DCATKIN_ENABLE_TESTING=ON $(LAUNCHER)

# The sample dives, made deterministically by the project's simulator (not committed).
bags: build
	@tools/make-bags.sh

demo: build
	@tools/make-bags.sh sample_lawnmower
	@tools/run-demo.sh

test: build
	@tools/make-bags.sh sample_out_and_back
	@tools/run-tests.sh

# The fast tier: every gtest, the build checks' and the Python unit tests (no rostest, no bag); the same closing line.
check: build
	@tools/run-tests.sh --gtest-only

bench: build
	@tools/make-bags.sh sample_out_and_back
	@tools/run-bench.sh

# The soak benchmark (not part of make test or make bench): an hour-long simulated survey through the whole live chain,
# each node's memory and CPU over the dive (out/bench/soak.json, soak_* keys of out/bench/reliability.json).
soak: build
	@tools/run-soak.sh

format:
	@find src tests -name '*.cpp' -o -name '*.h' | xargs clang-format -i

clean:
	rm -rf build devel install out
