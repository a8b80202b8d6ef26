# Two commands for users:  `make reproduce`  (the whole study)  and  `make test`.
# Both call `setup`, which is idempotent: a second run installs nothing.
SHELL := /bin/bash
VENV := .venv
PY := $(VENV)/bin/python
JOBS ?= 2
CONFIG ?= config.yaml
WORKDIR ?= .
SNAKEMAKE_ARGS ?=
# A named sweep replacing the config's cases (fem.sweep.SWEEP_PRESETS), e.g. PRESET=paper.
PRESET ?=
PRESET_ARGS := $(if $(PRESET),--config "sweep={preset: $(PRESET)}")
SNAKEMAKE := $(VENV)/bin/snakemake --snakefile $(CURDIR)/Snakefile --directory $(abspath $(WORKDIR)) \
	--configfile $(abspath $(CONFIG)) --workflow-profile $(CURDIR)/profiles/default

# Debian packages: dolfinx 0.5.2 (PETSc 3.18, MPI), h5py on the same HDF5, a fast BLAS for MUMPS,
# the X/GL libraries the gmsh wheel links against, SLURM + munge for the cluster-profile test,
# and Chromium for the viewer's browser test (driven by Playwright, pointed at this browser).
APT_PACKAGES := python3-dolfinx python3-h5py python3-pygalmesh libopenblas0-pthread \
	python3-venv \
	libglu1-mesa libxcursor1 libxft2 libxinerama1 \
	slurm-wlm munge \
	chromium fonts-dejavu-core

.PHONY: setup system-packages test reproduce lint lock clean-results

setup: system-packages $(VENV)/.installed node_modules/.package-lock.json

system-packages:
	@missing=$$(for p in $(APT_PACKAGES); do \
		dpkg-query -W -f='$${Status}\n' $$p 2>/dev/null | grep -q '^install ok installed$$' || echo $$p; \
	done); \
	if [ -n "$$missing" ]; then \
		echo "setup: installing Debian packages:" $$missing; \
		sudo=""; [ "$$(id -u)" -eq 0 ] || sudo="sudo"; \
		$$sudo apt-get update && \
		DEBIAN_FRONTEND=noninteractive $$sudo apt-get install -y --no-install-recommends $$missing; \
	fi

$(VENV)/.installed: requirements.lock constraints.txt pyproject.toml
	@echo "setup: creating $(VENV) over /usr/bin/python3 and installing requirements.lock"
	/usr/bin/python3 -m venv --system-site-packages $(VENV)
	$(PY) -m pip install --disable-pip-version-check -q --no-deps -c constraints.txt -r requirements.lock
	$(PY) -m pip install --disable-pip-version-check -q -c constraints.txt --no-deps --no-build-isolation -e .
	$(PY) -c "import numpy, petsc4py, dolfinx, jax, optax, gmsh, snakemake; assert numpy.__version__ == '1.24.2', numpy.__version__"
	touch $@

# The viewer's JavaScript tools, pinned in package-lock.json: three.js (rendering, bundled into
# the page) and esbuild (the bundler). Node.js and npm come from Debian where they are missing.
node_modules/.package-lock.json: package.json package-lock.json
	@command -v npm >/dev/null || { \
		sudo=""; [ "$$(id -u)" -eq 0 ] || sudo="sudo"; \
		$$sudo apt-get update && DEBIAN_FRONTEND=noninteractive $$sudo apt-get install -y \
			--no-install-recommends nodejs npm; }
	npm ci --no-audit --no-fund
	touch $@

# The checks first (seconds), then the suite on every core (pytest-xdist: TEST_WORKERS workers,
# each module's tests on one worker, so that its fixtures are built once; the longest modules
# first, in tests/conftest.py's order);
# `make test PYTEST_ARGS="-m unit"` runs one layer (markers in pyproject.toml: unit, solve,
# workflow, cluster), `TEST_WORKERS=0` one test at a time.
PYTEST_ARGS ?=
TEST_WORKERS ?= auto
test: setup lint
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadscope --no-loadscope-reorder --durations=15 $(PYTEST_ARGS) tests

# The config is checked first (a YAML syntax error with its line, every bad value named), then
# the run. Every run of the Snakefile holds the working directory's run lock (run.workdir):
# a second run there is refused, and the Snakemake locks a killed run left are cleared, so
# finished cases are kept and interrupted ones are redone without --unlock.
#
# Without SNAKEMAKE_ARGS, two Snakemake runs back to back (one run in the report's time): the
# first report's jobs (the sweep, the dataset, the selected model, the 3D view), then the rest.
# Snakemake does not stop a running job for a more urgent one, so in one run a long study that
# took a free core would hold it while the first results wait. The second runs even if the
# first failed (a failed job is kept going past), and either's failure fails the target; an
# interrupt (Ctrl-C) stops both.
FIRST_RESULTS := first_report
reproduce: setup
	@if [ -e "$(WORKDIR)" ] && [ ! -d "$(WORKDIR)" ]; then \
		echo "error: WORKDIR=$(WORKDIR) is a file, not a folder to work in" >&2; exit 2; fi
	$(PY) -m run.config $(abspath $(CONFIG))
	$(if $(SNAKEMAKE_ARGS),$(SNAKEMAKE) -j$(JOBS) $(SNAKEMAKE_ARGS) $(PRESET_ARGS),\
		trap 'exit 130' INT TERM; $(SNAKEMAKE) -j$(JOBS) $(PRESET_ARGS) $(FIRST_RESULTS); first=$$?; \
		$(SNAKEMAKE) -j$(JOBS) $(PRESET_ARGS); rest=$$?; exit $$(( first || rest )))

# ruff (with the docstring rules of pyproject.toml), the import-linter contracts (the layers
# import downward only) and Snakemake's own lint of the workflow (as a dry run, -n: it writes no
# run log, and may look beside a run working here, which any other Snakemake call may not).
lint: setup
	$(VENV)/bin/ruff check .
	$(VENV)/bin/lint-imports
	$(VENV)/bin/snakemake --lint -n

# Re-resolve the pins from requirements.in (needs network); review the diff. Lines marked
# "# NODEPS" are installed without dependency resolution (see requirements.in).
lock:
	rm -rf /tmp/lock-venv && /usr/bin/python3 -m venv --system-site-packages /tmp/lock-venv
	/tmp/lock-venv/bin/pip install -q -c constraints.txt -r requirements.in
	/tmp/lock-venv/bin/pip install -q --no-deps $$(sed -n 's/^# NODEPS //p' requirements.in)
	{ echo "# Complete pinned set of PyPI packages installed into .venv (over Debian's python3-dolfinx),"; \
	  echo "# installed with --no-deps so that exactly these versions land. Regenerate: make lock"; \
	  /tmp/lock-venv/bin/pip list --local --format=freeze | grep -v -E '^(pip|setuptools)=='; } > requirements.lock

clean-results:
	rm -rf results .snakemake
