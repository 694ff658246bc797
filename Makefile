# make demo | make test | make bench  — each bootstraps .venv on first use.
# make demo TASK=completion|quality|canonical runs one task's demo (default: all three).
# GPU users: make demo TORCH_SPEC=torch   (or install your CUDA torch build into .venv first)
VENV ?= .venv
TORCH_SPEC ?= torch==2.13.0
TASK ?= all
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
EXTRAS := $(VENV)/.extras
export VENV TORCH_SPEC

.PHONY: demo demo-compare test test-all bench bench-gpu install clean lint

$(STAMP): pyproject.toml scripts/bootstrap.sh
	bash scripts/bootstrap.sh

# the catalogues of data=completion_installed and the Anny cache: for the tests and benchmarks, not the demo
$(EXTRAS): $(STAMP) scripts/bootstrap_extras.sh
	bash scripts/bootstrap_extras.sh

install: $(STAMP) $(EXTRAS)

demo: $(STAMP)
	bash scripts/demo.sh $(TASK)

# two demo folders value by value as printed (metrics, summary lines, cache manifest hashes; times left out):
#   make demo-compare DEMO_A=/tmp/demo_a DEMO_B=/tmp/demo_b   (exit 1 when a value differs; studies/layout/README.md)
demo-compare: $(STAMP)
	$(BIN)/python -m studies.layout.compare_demo $(DEMO_A) $(DEMO_B)

# the suite in TEST_WORKERS processes (pytest-xdist; a test file stays in one process); TEST_WORKERS=0: one process
TEST_WORKERS ?= 2
test: $(STAMP) $(EXTRAS)
	$(BIN)/lint-imports
	$(BIN)/ruff check lit3d datamodules studies benchmarks tests
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile

test-all: $(STAMP) $(EXTRAS)
	$(BIN)/python -m pytest -q -m "not gpu"

lint: $(STAMP)
	$(BIN)/lint-imports
	$(BIN)/ruff check lit3d datamodules studies benchmarks tests

bench: $(STAMP) $(EXTRAS)
	$(BIN)/python -m benchmarks.run

# On a CUDA machine: only the GPU rows, into benchmarks/gpu_rows.json (the next `make bench` shows them),
# then a torch.profiler table of one paper-scale step at batch 3 and 12 into benchmarks/gpu_profile.md
bench-gpu: $(STAMP) $(EXTRAS)
	$(BIN)/python -m benchmarks.run --gpu
	$(BIN)/python -m benchmarks.profile_step --out benchmarks/gpu_profile.md

clean:
	rm -rf logs outputs multirun .pytest_cache
