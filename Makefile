# `make demo` and `make test` each build .venv from nothing on a fresh machine, then run: the
# demo needs the FEM and matplotlib alone, the tests everything. Torch is pinned to a version
# whose CPU build installs quickly; for a CUDA build:
#   make test TORCH_SPEC="torch==2.13.0 --index-url https://download.pytorch.org/whl/cu128"
PYTHON ?= python3
VENV ?= .venv
TORCH_SPEC ?= torch==2.13.0
PY := $(VENV)/bin/python
PYTEST_ARGS ?=
TEST_WORKERS ?= 2

.PHONY: demo test bench pretrained clean web web-assets test-web install-mpi test-mpi install-csharp \
	mujoco

$(VENV)/.fem: setup.cfg setup.py
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e ".[plot]"
	touch $@

$(VENV)/.installed: $(VENV)/.fem
	$(PY) -m pip install --quiet $(TORCH_SPEC)
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $@

demo: $(VENV)/.fem
	$(PY) examples/cantilever.py

# The suite runs on TEST_WORKERS processes, one file per process at a time (pytest-xdist);
# tests/test_threads.py measures busy cores, so it runs alone afterwards.
test: $(VENV)/.installed
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile $(PYTEST_ARGS) --ignore=tests/mpi \
	  --ignore=tests/test_threads.py tests
	$(PY) -m pytest -q $(PYTEST_ARGS) tests/test_threads.py

# The petsc engine (anisofem.distributed): PETSc, Open MPI, petsc4py and mpi4py (apt as root or
# with sudo; a few minutes), then its tests on 1 and 2 MPI ranks.
$(VENV)/.mpi: $(VENV)/.installed scripts/install_mpi.sh
	scripts/install_mpi.sh $(PY)
	touch $@

install-mpi: $(VENV)/.mpi

test-mpi: $(VENV)/.mpi
	$(PY) -m pytest -q $(PYTEST_ARGS) tests/mpi

# The MuJoCo plugin (export/mujoco.py): compiled against the installed mujoco wheel into the
# cache folder it is loaded from (it is also built on first use).
mujoco: $(VENV)/.installed
	$(PY) -c "from export import mujoco; print(mujoco.build_plugin())"

# Mono's C# compiler and runtime from the distribution's packages (about 25 MB), so that the
# test of the C runtime's C# example runs (it skips itself without them).
install-csharp:
	@command -v mcs > /dev/null && command -v mono > /dev/null || { \
	  SUDO=$$([ "$$(id -u)" = 0 ] || echo sudo); $$SUDO apt-get update -q && \
	  DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q --no-install-recommends \
	  mono-mcs mono-runtime; }

bench: $(VENV)/.installed
	$(PY) -m anisofem bench
	$(PY) -m anisofem bench --large
	$(PY) -m anisognn bench
	$(PY) -m export bench

# Trains both shipped models side by side (one CPU thread each, about 15 minutes on 2 cores)
# and installs them, with their configs and logs, as anisognn.pretrained(...) and as
# export/models/NAME.onnx.
pretrained: $(VENV)/.installed
	OMP_NUM_THREADS=1 $(PY) -m anisognn train --config configs/shipped-directional.toml --no-progress & d=$$!; \
	OMP_NUM_THREADS=1 $(PY) -m anisognn train --config configs/shipped-meshgraphnets.toml --no-progress & m=$$!; \
	wait $$d && wait $$m
	for name in directional meshgraphnets; do \
	  mkdir -p anisognn/pretrained/$$name && \
	  cp runs/shipped-$$name/model.pt runs/shipped-$$name/log.jsonl anisognn/pretrained/$$name/ && \
	  cp configs/shipped-$$name.toml anisognn/pretrained/$$name/config.toml || exit 1; \
	done
	$(PY) -m anisognn evaluate directional meshgraphnets --json anisognn/pretrained/evaluation.json
	for name in directional meshgraphnets; do \
	  $(PY) -m export $$name -o export/models/$$name.onnx || exit 1; \
	done

# The browser page (web/): onnxruntime-web and three.js from npm (web/package-lock.json), the
# scenes baked from the shipped model (python -m export bake), their reduced models and the C
# runtime built to WebAssembly, served on 127.0.0.1 only.
WEB_SCENES := cantilever cylinder t y
WEB_PORT ?= 8000

web/node_modules/.package-lock.json: web/package.json web/package-lock.json
	cd web && npm ci --no-audit --no-fund

web/models/%.onnx: export/models/%.onnx
	mkdir -p web/models
	cp $< $@

web/scenes/%.json: export/models/directional.onnx export/writers/bake.py export/runtime.py $(VENV)/.installed
	mkdir -p web/scenes
	$(PY) -m export bake $* -o web/scenes/$*

# the T and the Y bend far at their arms: their reduced models are framed
WEB_FRAMED := t y
web/scenes/%-reduced.json: export/writers/reduced.py export/runtime.py export/framed_runtime.py \
                           anisofem/reduced/*.py $(VENV)/.installed
	mkdir -p web/scenes
	$(PY) -m export bake-reduced $* -o web/scenes/$*-reduced \
	  $(if $(filter $*,$(WEB_FRAMED)),--framed,--modes 4 --snapshots 16)

# the tentacle has a reduced model only, with its four bands of fibers as controls (sliders),
# over a floor with a ball to push it with
web/scenes/tentacle-reduced.json: examples/scenes/tentacle_floor.toml examples/scenes/tentacle.msh \
                                  export/writers/reduced.py anisofem/reduced/*.py \
                                  anisofem/physics/contact.py $(VENV)/.installed
	mkdir -p web/scenes
	$(PY) -m export reduced examples/scenes/tentacle_floor.toml --modes 4 --snapshots 14 \
	  -o web/scenes/tentacle-reduced

# the C runtime (export/c, less its file loader) built to WebAssembly by zig's C compiler (the
# ziglang wheel from PyPI): the page's reduced and framed models step with it
ZIG_SPEC ?= ziglang==0.17.1
WASM_SOURCES := $(addprefix export/c/,arrays.c linalg.c reduced.c reach.c contact.c framed.c model.c)

$(VENV)/.zig: $(VENV)/.fem
	$(PY) -m pip install --quiet "$(ZIG_SPEC)"
	touch $@

web/anisofem.wasm: $(WASM_SOURCES) export/c/anisofem.h export/c/af_internal.h $(VENV)/.zig
	$(PY) -m ziglang cc --target=wasm32-wasi -std=c99 -O3 -s -mexec-model=reactor \
	  -Wl,--export-dynamic -Wl,--export=malloc -Wl,--export=free -o $@ $(WASM_SOURCES)

web-assets: web/node_modules/.package-lock.json web/anisofem.wasm web/models/directional.onnx \
            web/models/meshgraphnets.onnx $(WEB_SCENES:%=web/scenes/%.json) \
            $(WEB_SCENES:%=web/scenes/%-reduced.json) web/scenes/tentacle-reduced.json

web: web-assets
	@echo "serving the page at http://127.0.0.1:$(WEB_PORT)/index.html (Ctrl-C stops)"
	$(PY) -m http.server $(WEB_PORT) --bind 127.0.0.1 --directory web

# Chromium from the distribution's packages when it is missing (apt: about 115 packages, 480 MB;
# no browser download).
test-web: web-assets
	@command -v chromium > /dev/null || { SUDO=$$([ "$$(id -u)" = 0 ] || echo sudo); \
	  $$SUDO apt-get update -q && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q chromium; }
	$(PY) web/check_page.py

clean:
	rm -rf $(VENV) build *.egg-info web/node_modules web/models web/scenes web/out web/anisofem.wasm
