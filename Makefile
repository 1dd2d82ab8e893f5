# Quick start: `make demo` and `make test` (each installs into .venv first when needed).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
# The CPU build of PyTorch; override, e.g. `make install TORCH_SPEC=torch` for a CUDA build.
TORCH_SPEC ?= torch==2.13.0

.PHONY: install llvm demo test bench edit screenshot clean

install: $(VENV)/.installed

# The fused kernels compile for float64 beside float32 (the tests compare them with PyTorch in
# both); on two or more cores the two compile at once, in the time of one.
$(VENV)/.installed: pyproject.toml
	@echo "installing into $(VENV): 1/4 the virtual environment"
	$(PYTHON) -m venv $(VENV)
	@echo "installing into $(VENV): 2/4 PyTorch, $(TORCH_SPEC) (about a minute from a local wheel, more to download)"
	$(BIN)/python -m pip install --quiet "$(TORCH_SPEC)"
	@echo "installing into $(VENV): 3/4 wise and its dependencies (one to two minutes from local wheels, more to download)"
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	@echo "installing into $(VENV): 4/4 the fast CPU kernels: checking LLVM, then compiling"
	$(BIN)/python -m wise.filters.fused.llvm || $(MAKE) --no-print-directory llvm
	$(BIN)/python -m wise.effects.compile float32 float64
	touch $@

# The Dr.Jit kernels load the system's LLVM (15 or newer). Installed with apt-get where this runs
# as root on Debian or Ubuntu; elsewhere the command to run is printed, and the filters run on the
# slower PyTorch path until then.
llvm:
	@if command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" -eq 0 ]; then \
		echo "installing the LLVM library for the fast CPU kernels (apt-get, about a minute)"; \
		apt-get update -qq && { DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >/dev/null 2>&1 || \
			DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm15 >/dev/null; } || true; \
		$(BIN)/python -m wise.filters.fused.llvm || true; \
	else \
		echo "for the fast CPU kernels install LLVM 15 or newer, e.g. \`sudo apt-get install libllvm15\`"; \
	fi

demo: install
	$(BIN)/python -m wise.demo --out out

# The tests run in parallel, one process per core (at most 4), each on one thread; a test file
# stays in one process, so the Ray and Lightning ones start their clusters once.
TEST_WORKERS ?= $(shell n=$$(nproc 2>/dev/null || echo 1); [ "$$n" -gt 4 ] && n=4; echo $$n)

test: install
	OMP_NUM_THREADS=1 $(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile --durations=15

# The web editor on the demo's result (made first when missing): open http://127.0.0.1:8000/
edit: install
	test -f out/transfer/params.safetensors || $(BIN)/python -m wise.demo --out out
	$(BIN)/wise edit out/astronaut.png --params out/transfer/params.safetensors

# The README's picture of the editor, taken by the browser test.
screenshot: install
	WISE_EDITOR_SCREENSHOT=docs/editor.png $(BIN)/python -m pytest -q tests/editor/test_page.py

bench: install
	$(BIN)/python benchmarks/bench_effects.py --markdown

clean:
	rm -rf $(VENV) out build *.egg-info src/*.egg-info .pytest_cache
