# Two commands set everything up on a fresh machine: `make demo` and `make test`.
# Both create .venv and install what they need. torch is pinned to the CPU build (see README for GPU).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
TORCH  ?= torch==2.13.0

.PHONY: demo test bench lint clean venv blender

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

bench: venv
	$(PY) -m pytest -q -m bench --benchmark-enable --benchmark-only tests/bench

lint: venv
	$(VENV)/bin/ruff check .

clean:
	rm -rf $(VENV) demo_out .pytest_cache .benchmarks
