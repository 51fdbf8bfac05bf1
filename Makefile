# reachirl: `make run` and `make test` do all the set-up themselves.
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
# reachirl's cache folder, as reachirl.io.cache_root finds it; make run's solvers are noted there (in the folder of
# the CasADi version the lock pins), so that emptying the cache has them compiled again
CACHE   := $(or $(REACHIRL_CACHE),$(if $(XDG_CACHE_HOME),$(XDG_CACHE_HOME)/reachirl),$(HOME)/.cache/reachirl)
SOLVERS := $(CACHE)/casadi-$(shell sed -n 's/^casadi==//p' requirements.lock)/make-run-solvers.stamp
ifneq ($(words $(SOLVERS)),1)  # a cache path with a space is no make target: the note stays in the environment
SOLVERS := $(VENV)/.solvers
endif
export MUJOCO_GL ?= osmesa
export PYOPENGL_PLATFORM ?= osmesa
export OMP_NUM_THREADS ?= 1

.PHONY: install run test test-slow bench measured docs lint clean system-deps

install: $(STAMP)

# OSMesa for MuJoCo's offscreen rendering on CPU (Debian: libosmesa6). Installed when we are root and it is missing.
system-deps:
	@if ! ldconfig -p 2>/dev/null | grep -q libOSMesa; then \
	  if [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null; then \
	    echo "installing libosmesa6 for offscreen rendering"; \
	    (apt-get install -y -qq libosmesa6 >/dev/null 2>&1 || (apt-get update -qq >/dev/null && apt-get install -y -qq libosmesa6 >/dev/null)); \
	  else echo "note: libOSMesa not found; MuJoCo rendering will be unavailable (apt-get install libosmesa6)"; fi; \
	fi

# The editable install leaves src/ uncompiled: where PYTHONDONTWRITEBYTECODE is set, every process (the command's,
# each worker's) would compile reachirl's sources anew (about 0.1 s each), hence compileall.
$(STAMP): requirements.lock pyproject.toml
	@$(MAKE) --no-print-directory system-deps
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -r requirements.lock
	$(PY) -m pip install -q --no-deps --no-build-isolation -e .
	$(PY) -m compileall -q src >/dev/null
	@touch $(STAMP)

# make run's DOC solvers (100 knots, cold and warm) compiled to C once, side by side (about a minute; again when the
# code that builds them changes): its fatrop solves then take about half their CPU, with the same answers bit for bit.
# Without a C compiler they are not, and CasADi's virtual machine solves (reachirl.doc.compiled). The note lives in the
# cache: a cache emptied (or another REACHIRL_CACHE) has them compiled again; an unwritable one is no error.
$(SOLVERS): $(STAMP) src/reachirl/doc/casadi.py src/reachirl/doc/symbolic.py src/reachirl/doc/compiled.py src/reachirl/features.py
	$(PY) -m reachirl.doc.compile_job prepare 100
	@mkdir -p $(dir $(SOLVERS)) 2>/dev/null && touch $(SOLVERS) 2>/dev/null || true

run: install $(SOLVERS)
	$(VENV)/bin/reachirl reproduce --out results

test: install
	$(PY) -m pytest -q

test-slow: install
	$(PY) -m pytest -q -m slow

bench: install
	$(VENV)/bin/reachirl bench --out bench.json

# docs/benchmarks.md's Measured section and docs/measured.json, from the outputs of `make run` and `make bench`
measured: run bench
	$(PY) benchmarks/measured.py --results results/results.json --bench bench.json

# the generated parts of docs/: docs/cli.md from the parsers, and the Measured section from docs/measured.json
docs: install
	$(PY) -m reachirl.cli.docs --out docs/cli.md
	$(PY) benchmarks/measured.py

lint: install
	$(VENV)/bin/ruff check src tests benchmarks examples

clean:
	rm -rf $(VENV) results bench.json .pytest_cache
