# reachirl: `make run` and `make test` do all the set-up themselves.
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
SOLVERS := $(VENV)/.solvers
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
# Without a C compiler they are not, and CasADi's virtual machine solves (reachirl.doc.compiled). After emptying the
# cache (~/.cache/reachirl), `rm .venv/.solvers` has them compiled again.
$(SOLVERS): $(STAMP) src/reachirl/doc/casadi.py src/reachirl/doc/symbolic.py src/reachirl/doc/compiled.py src/reachirl/features.py
	$(PY) -m reachirl.doc.compile_job prepare 100
	@touch $(SOLVERS)

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
