# Quick start: `make demo` and `make test` (see README.md and docs/index.md). Both are idempotent.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: all setup fmus demo test docs lint bench acados node-opcua browser clean

all: fmus

setup: $(STAMP)

# (Re)install only when the project's dependency list changes.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[train,dev]'
	touch $(STAMP)

# Rebuilds only when the C sources or model descriptions change (cosim build-fmu checks).
# The robust MPC's compiled kernels for the shipped model (its default tracking law's and the
# paper law's) are cached in ~/.cache/gru-mpc; without a C compiler the controller falls back
# to numpy (hence the '-': not an error for make).
fmus: $(STAMP)
	$(BIN)/cosim build-fmu
	-$(BIN)/cosim build-kernel --quiet
	-$(BIN)/cosim build-kernel --quiet --option 'law="paper"'

demo: fmus
	$(BIN)/cosim run scenarios/paper_steps.csv --out results/demo

# The suite in JOBS worker processes (pytest-xdist), each test module in one of them, so that
# its module-scoped fixtures (a trained model, built FMUs) are made once, the modules handed
# out in collection order (--no-loadscope-reorder: tests/conftest.py collects the ones that
# take minutes first, so that no worker starts one when the other has finished): about 25 min
# on 2 cores. JOBS=1 runs it in one process.
JOBS ?= 2
# acados (benchmarks/bench_acados.py's test) when PyPI serves it, node-opcua (the live tests'
# vendor-style PLC) when npm serves it, Debian's chromium (the run's page in a browser) when
# apt can install it; their tests are skipped without.
test: fmus docs
	-$(MAKE) --no-print-directory acados
	-$(MAKE) --no-print-directory node-opcua
	-$(MAKE) --no-print-directory browser
	$(BIN)/python -m pytest $(if $(filter-out 1,$(JOBS)),-n $(JOBS) --dist loadscope --no-loadscope-reorder)

# The documentation site (mkdocs.yml, docs/): a strict build, any warning is an error.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict --site-dir site

lint: $(STAMP)
	$(BIN)/ruff check .

bench: fmus acados
	for b in benchmarks/bench_*.py; do $(BIN)/python $$b || exit 1; done

# acados beside the kernel (benchmarks/bench_acados.py) in a venv of its own: the
# comma-deps-acados wheel (acados, HPIPM, its Python template) vendors its own casadi, which
# cannot share .venv with the project's.
ACADOS_VENV := .venv-acados
acados: $(ACADOS_VENV)/.installed

$(ACADOS_VENV)/.installed:
	$(PYTHON) -m venv $(ACADOS_VENV)
	$(ACADOS_VENV)/bin/python -m pip install --quiet comma-deps-acados==0.2.2.post92
	touch $@

# node-opcua, a second OPC UA stack, for the live tests' vendor-style PLC
# (tests/cosim/live/vendor_plc/, test_vendor_plc.py): the versions pinned by its
# package-lock.json, into its git-ignored node_modules (69 MB; no install scripts run). Needs
# Node.js >= 18 and npm; without them the vendor PLC's tests are skipped.
VENDOR_PLC := tests/cosim/live/vendor_plc
node-opcua: $(VENDOR_PLC)/node_modules/.installed

$(VENDOR_PLC)/node_modules/.installed: $(VENDOR_PLC)/package.json $(VENDOR_PLC)/package-lock.json
	cd $(VENDOR_PLC) && npm ci --no-audit --no-fund --ignore-scripts --loglevel=error
	touch $@

# A browser for the tests of the run's page (tests/cosim/hmi): Debian's chromium, driven by
# Playwright (the dev extra) through its executable, never Playwright's own download. Installed
# with apt-get when missing (as root, or with sudo that asks for no password); elsewhere
# install it yourself (or point $$COSIM_CHROMIUM at a Chromium) or those tests are skipped.
browser:
	@command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || \
	  { if [ "$$(id -u)" = 0 ]; then SUDO=; elif sudo -n true 2>/dev/null; then SUDO=sudo; \
	    else echo "make browser: no chromium and no root to install it: the page's browser tests are skipped"; exit 1; fi; \
	    DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q chromium >/dev/null || \
	    { $$SUDO apt-get update -q >/dev/null && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -q chromium >/dev/null; }; }

clean:
	rm -rf fmus/build fmus/*.fmu results site .pytest_cache
