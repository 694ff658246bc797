# make demo | make test | make bench  — each bootstraps .venv on first use.
# make demo TASK=completion|quality|canonical runs one task's demo (default: all three).
# GPU users: make demo TORCH_SPEC=torch   (or install your CUDA torch build into .venv first)
VENV ?= .venv
TORCH_SPEC ?= torch==2.13.0
TASK ?= all
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
export VENV TORCH_SPEC

.PHONY: demo test test-all bench bench-gpu install clean lint

$(STAMP): pyproject.toml scripts/bootstrap.sh
	bash scripts/bootstrap.sh

install: $(STAMP)

demo: $(STAMP)
	bash scripts/demo.sh $(TASK)

test: $(STAMP)
	$(BIN)/lint-imports
	$(BIN)/python -m pytest -q

test-all: $(STAMP)
	$(BIN)/python -m pytest -q -m "not gpu"

lint: $(STAMP)
	$(BIN)/lint-imports

bench: $(STAMP)
	$(BIN)/python -m benchmarks.run

# On a CUDA machine: only the GPU rows, into benchmarks/gpu_rows.json (the next `make bench` shows them)
bench-gpu: $(STAMP)
	$(BIN)/python -m benchmarks.run --gpu

clean:
	rm -rf logs outputs multirun .pytest_cache
