# Two entry points, as the README says: `make run` and `make test`.
.PHONY: setup run test test-slow lint
OUT ?= out/main-job

setup:
	bash scripts/setup.sh

run: setup
	.venv/bin/beacon-sim main-job --out $(OUT)

test: setup
	.venv/bin/python -m pytest -q

test-slow: setup
	.venv/bin/python -m pytest -q -m slow

lint: setup
	.venv/bin/ruff check .
