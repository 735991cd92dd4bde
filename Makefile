# Everything goes through tools/bootstrap.sh (pinned .venv + colcon workspace, idempotent)
# and tools/env.sh (the ROS 2 environment); ./tmgwr does both, then runs the CLI.
SHELL := /bin/bash
PYTEST_ARGS ?=

.PHONY: all bootstrap rebuild demo test bench clean distclean

all: bootstrap

bootstrap:
	@tools/bootstrap.sh

rebuild:
	@tools/bootstrap.sh --rebuild

demo:
	./tmgwr demo

test: bootstrap
	@source tools/env.sh && python -m pytest -q test $(PYTEST_ARGS)

bench:
	./tmgwr bench

# Build trees only (the .venv stays; `make distclean` removes it too).
clean:
	rm -rf build install log

distclean: clean
	rm -rf .venv
