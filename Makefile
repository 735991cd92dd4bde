# Everything goes through tools/bootstrap.sh (pinned .venv + colcon workspace, idempotent)
# and tools/env.sh (the ROS 2 environment); ./tmgwr does both, then runs the CLI.
SHELL := /bin/bash
PYTEST_ARGS ?=

.PHONY: all bootstrap rebuild demo test bench docs results clean distclean

all: bootstrap

bootstrap:
	@tools/bootstrap.sh

rebuild:
	@tools/bootstrap.sh --rebuild

demo:
	./tmgwr demo

test: bootstrap
	@source tools/env.sh && python -m pytest -q test $(PYTEST_ARGS)

# The benchmark, recorded with its command, commit and load (results/bench.json), then
# every table rendered again (docs/benchmarks.md shows it).
bench:
	./tmgwr results record bench -- bench
	./tmgwr results

# The documentation (mkdocs.yml, docs/): strict, so a warning (a broken link, an unknown
# API reference, a page missing from the nav) fails the build. Output in site/.
docs: bootstrap
	@source tools/env.sh && NO_MKDOCS_2_WARNING=1 mkdocs build --strict --quiet

# Every results table of README.md and docs/, and docs/figures/, from results/*.json.
results:
	./tmgwr results

# Build trees only (the .venv stays; `make distclean` removes it too).
clean:
	rm -rf build install log site

distclean: clean
	rm -rf .venv
