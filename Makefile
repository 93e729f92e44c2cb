# The project's entry points. See README.md.
SHELL := /bin/bash
ROOT := $(abspath $(dir $(lastword $(MAKEFILE_LIST))))
PYTEST_ARGS ?=

.PHONY: setup test soak demo bench clean distclean firmware

setup:
	@bash $(ROOT)/scripts/setup.sh

test: setup
	@bash $(ROOT)/scripts/test.sh $(PYTEST_ARGS)

# make soak N=5 [BUSY=1]: the topic-level tests N times, per-test runs/failures/slowest
N ?= 5
soak: setup
	@. $(ROOT)/scripts/env.sh && cd $(ROOT) && python scripts/soak.py --rounds $(N) $(if $(BUSY),--busy,) $(SOAK_PATHS)

demo: setup
	@$(ROOT)/sslfr sim --out $(ROOT)/out/demo

bench: setup
	@. $(ROOT)/scripts/env.sh && cd $(ROOT) && for b in benchmarks/bench_*.py; do echo "== $$b"; python $$b || exit 1; done

# the board firmware (firmware/Makefile: avr-gcc, sizes printed), the simavr harness and
# the protocol code as a host library (docs/firmware.md)
firmware:
	@$(MAKE) -s -C $(ROOT)/firmware all sim host

clean:
	rm -rf $(ROOT)/firmware/build
	rm -rf $(ROOT)/ros_ws/build $(ROOT)/ros_ws/install $(ROOT)/ros_ws/log $(ROOT)/ros_ws/.setup-stamp

distclean: clean
	rm -rf $(ROOT)/.venv
