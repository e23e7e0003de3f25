# The README's two commands: `make demo` and `make test`. Both create or update .venv.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
PIP := $(PY) -m pip

.PHONY: demo test test-fast bench clean chromium alertmanager

$(VENV)/.created:
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "need $(PYTHON) on PATH"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	touch $@

$(VENV)/.installed: $(VENV)/.created pyproject.toml
	$(PIP) install -q -e .
	touch $@

$(VENV)/.installed-test: $(VENV)/.created pyproject.toml
	$(PIP) install -q -e '.[test]'
	touch $@ $(VENV)/.installed

# numba compiles the kernels once into its cache here, never inside a user's first command
demo: $(VENV)/.installed
	$(VENV)/bin/buoymon warmup
	$(VENV)/bin/buoymon demo --out out/demo

# the HTML report test renders in headless Chromium (Debian package); install it when missing
chromium:
	@test -x /usr/bin/chromium || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null; \
	  else echo "note: /usr/bin/chromium missing and cannot install it; its test will skip"; fi; }

# the alert delivery tests run a real Prometheus Alertmanager (Debian package); install it
# when missing (never started as a service here: the tests run their own on 127.0.0.1)
alertmanager:
	@test -x /usr/bin/prometheus-alertmanager || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
	      --no-install-recommends prometheus-alertmanager >/dev/null; \
	  else echo "note: prometheus-alertmanager missing and cannot install it; its tests will skip"; fi; }

test: $(VENV)/.installed-test chromium alertmanager
	cd $(CURDIR) && $(VENV)/bin/lint-imports --no-cache
	$(VENV)/bin/buoymon warmup
	$(PY) -m mypy
	$(PY) -m pytest -q

# the unit tests alone (no daemons, servers, browsers or whole records): under a minute
test-fast: $(VENV)/.installed-test
	$(VENV)/bin/buoymon warmup
	$(PY) -m pytest -q -m "not integration and not slow"

# every benchmark script prints its figures (the 30-day replay takes a few minutes)
bench: $(VENV)/.installed-test
	@for f in bench/bench_*.py; do echo "== $$f"; $(PY) $$f || exit 1; done

clean:
	rm -rf $(VENV) out .pytest_cache
