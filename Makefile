# The two entry points (see README):
#   make main   set up the venv from environment-lock.txt, run the pipeline (paper profile), build the book
#   make why    the why profile (the claims over the settings the paper leaves open), then the book
#   make test   set up the venv from environment-lock.txt, run the test suite
#
# Variables: PROFILE (paper|smoke), DATA_DIR (data directory, default data/ in the repository), VENV (venv folder), PYTHON (interpreter that makes the venv),
# PIP_ARGS (extra pip options, e.g. another index), TORCH_INDEX (the index of torch's CPU build, default PyTorch's),
# RUN_ARGS (options of `fnn-pipeline run`: --workers K, --scheduler tcp://HOST:PORT; default: a local Dask
# cluster with one worker per core, capped by memory), TEST_WORKERS (pytest-xdist workers of `make test`;
# default: one more than the cores).

PYTHON ?= python3
VENV ?= .venv
PROFILE ?= paper
PIP_ARGS ?=
# where pip finds the locked CPU build of torch (torch-2.13.0+cpu); PIP_ARGS adds any other index
TORCH_INDEX ?= https://download.pytorch.org/whl/cpu
RUN_ARGS ?=
# the real throws (Sec. 5.1): data/ in the repository (git-ignored) unless told otherwise
DATA_DIR ?= data
PY := $(VENV)/bin/python

.PHONY: main why test venv pipeline book lock data notebooks

# The throws and the cascaded tanks data are fetched when missing (one attempt per source; without network
# one line each says so and the bottle and cascaded tanks tasks do not run). The book is built even when a
# task failed or did not run (e.g. its data are missing); make then exits with the pipeline's status.
main: venv
	$(VENV)/bin/fnn-pipeline data fetch --optional --tanks --data-dir $(DATA_DIR)
	$(VENV)/bin/fnn-pipeline run --profile $(PROFILE) --data-dir $(DATA_DIR) $(RUN_ARGS); status=$$?; \
	$(VENV)/bin/fnn-pipeline book --profile $(PROFILE) --data-dir $(DATA_DIR) && exit $$status

# The why profile (after or without `make main`: it reuses the paper profile's outputs and runs what they
# lack), then the paper book, whose scoreboard rows then carry each claim's why.
why: venv
	$(VENV)/bin/fnn-pipeline data fetch --optional --tanks --release --data-dir $(DATA_DIR)
	$(VENV)/bin/fnn-pipeline run --profile why --data-dir $(DATA_DIR) $(RUN_ARGS); status=$$?; \
	$(VENV)/bin/fnn-pipeline book --profile paper --data-dir $(DATA_DIR) && exit $$status

venv: $(VENV)/.installed

# torch first, alone, with PyTorch's CPU wheel index as an extra index (PyPI does not serve the locked CPU
# build): where that index is unreachable pip retries it for about 10 s and goes on with what its other
# indexes and find-links hold. Then the rest of the lock, torch already in place.
$(VENV)/.installed: environment-lock.txt pyproject.toml
	$(PYTHON) -m venv $(VENV)
	awk '/^torch==/{p=1; print; next} p && /^[^ #]/{p=0} p' environment-lock.txt > $(VENV)/torch-lock.txt
	$(PY) -m pip install --quiet --require-hashes --no-deps --extra-index-url $(TORCH_INDEX) $(PIP_ARGS) \
		-r $(VENV)/torch-lock.txt
	$(PY) -m pip install --quiet --require-hashes --no-deps $(PIP_ARGS) -r environment-lock.txt
	$(PY) -m pip install --quiet --no-deps --no-build-isolation -e .
	$(PY) -m pip check
	touch $@

pipeline: venv
	$(VENV)/bin/fnn-pipeline run --profile $(PROFILE) --data-dir $(DATA_DIR) $(RUN_ARGS)

book: venv
	$(VENV)/bin/fnn-pipeline book --profile $(PROFILE) --data-dir $(DATA_DIR)

# Download the published throws (Sec. 5.1) and the cascaded tanks benchmark into DATA_DIR and check their SHA-256 (an error without network).
data: venv
	$(VENV)/bin/fnn-pipeline data fetch --tanks --data-dir $(DATA_DIR)

# One pytest-xdist worker more than there are cores: the tests spend ~15 % of their time waiting on processes
# they start (kernels, Dask workers, chromium), and the extra worker keeps the cores busy meanwhile (2 cores:
# 3 workers, 4 min 52 s against 5 min 8 s with 2). The smoke pipeline still runs once (tests/conftest.py).
TEST_WORKERS ?= $(shell echo $$(( $$(getconf _NPROCESSORS_ONLN 2>/dev/null || echo 1) + 1 )))
# The suite starts ~100 Python processes (xdist workers, notebook kernels, nbval's reruns) that import the same
# modules: it lets Python keep their bytecode (in the git-ignored __pycache__ folders) even where the environment
# says not to (PYTHONDONTWRITEBYTECODE=1, which the machines this was measured on set), instead of compiling them
# again in every process.
test: venv
	env -u PYTHONDONTWRITEBYTECODE $(PY) -m pytest -n $(TEST_WORKERS) --durations=25

# Rebuild notebooks/NN_<name>.ipynb from its source notebooks/src/NN_<name>.py (jupytext's percent format),
# keeping the cell ids; tests/test_notebook_sources.py checks that the committed notebooks match.
notebooks: venv
	$(VENV)/bin/python tools/write_parameters_cells.py   # each parameters cell from its settings in fnnbook/tasks
	for f in notebooks/src/*.py; do $(VENV)/bin/jupytext --update --set-kernel python3 --to ipynb \
		-o "notebooks/$$(basename "$${f%.py}").ipynb" "$$f" || exit 1; done

# Regenerate environment-lock.txt after changing pyproject.toml (needs pip-tools in some venv).
lock:
	pip-compile --quiet --generate-hashes --allow-unsafe --strip-extras --extra book --extra test \
		--no-emit-index-url --no-emit-find-links -o environment-lock.txt pyproject.toml
