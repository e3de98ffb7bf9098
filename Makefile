# Two commands set everything up on a fresh machine: `make demo` and `make test`.
# Both create .venv and install what they need. torch is pinned to the CPU build (see README for GPU).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
TORCH  ?= torch==2.13.0

.PHONY: demo test check bench lint clean venv blender

venv: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml setup.py cghair_format/_native.pyx training/_raster.pyx
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q "$(TORCH)"
	$(PY) -m pip install -q -e ".[cards,training,viewer,usd,dev]"
	touch $@

# Blender as a Python module (bpy 5.0, ~370 MB, Python 3.11) for the DCC round-trip and Cycles tests.
# bpy pins numpy<2, so it gets its own environment inside .venv instead of downgrading the project's
# numpy; tests run Blender in a subprocess with this interpreter (or CGH_BLENDER_PYTHON).
BLENDER_VENV := $(VENV)/blender

blender: $(BLENDER_VENV)/.installed

$(BLENDER_VENV)/.installed: $(VENV)/.installed
	$(PYTHON) -m venv $(BLENDER_VENV)
	$(BLENDER_VENV)/bin/python -m pip install -q "bpy==5.0.*"
	touch $@

demo: venv
	$(VENV)/bin/cgh demo -o demo_out

test: venv blender
	$(PY) -m pytest -q

# The fast tier for the edit-test loop (see CONTRIBUTING.md); `make test` runs every tier, as CI does.
check: venv
	$(PY) -m pytest -q -m "not slow and not gl and not blender and not bench"

# Figures go to .benchmarks/bench.json and, as tables, to docs/benchmarks.md (tools/bench_tables.py).
bench: venv
	mkdir -p .benchmarks
	$(PY) -m pytest -q -s -m bench --benchmark-enable --benchmark-only --benchmark-json=.benchmarks/bench.json tests/bench
	$(PY) tools/bench_tables.py .benchmarks/bench.json -o docs/benchmarks.md

lint: venv
	$(VENV)/bin/ruff check .

clean:
	rm -rf $(VENV) demo_out .pytest_cache .benchmarks
