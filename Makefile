# fourws: every target does its own set-up. See README.md.
SHELL := /bin/bash
.DEFAULT_GOAL := run
ENV := source ros_ws/env.sh
PYTEST_ARGS ?=
OUT ?= runs/paper

.PHONY: setup run test lint bench tune-check limits clean

setup:
	@bash tools/setup.sh

COMPOSE ?= all

run: setup
	@$(ENV) && fourws paper --out $(OUT) --force --compose $(COMPOSE)

lint: setup
	@$(ENV) && ruff check .

test: setup
	@$(ENV) && echo "[test] ruff" && ruff check . && echo "[test] pytest" && python -m pytest $(PYTEST_ARGS)

bench: setup
	@$(ENV) && mkdir -p bench && python bench/run_all.py bench/results.json

# the tuning procedure rerun for every group (CI reruns one group): the presets must be its choice
tune-check: setup
	@$(ENV) && fourws tune benchmarks/tuning.yaml --workers 2 --check

# the limit-handling bench (benchmarks/limits.yaml): runs it and writes docs/limits.md
limits: setup
	@$(ENV) && python tools/make_limits.py --workers 2

clean:
	rm -rf ros_ws/build ros_ws/install ros_ws/log
