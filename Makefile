# Set-up commands: `make demo` and `make test` (ruff, then mypy beside pytest); `make test-fast` (ruff, then the tests the
# last runs measured at most 0.2 s CPU each: the change-test loop). Each bootstraps .venv on its own.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
export OMP_NUM_THREADS ?= 1

.PHONY: demo test test-fast bench study clean venv

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/pin-kpi-oed demo

# mypy (about 35 s CPU on a fresh clone, one core) runs beside the tests, its report printed after theirs; the
# target fails when either fails.
test: $(STAMP)
	$(PY) -m ruff check pin_kpi_oed tests
	@log=$$(mktemp); $(PY) -m mypy pin_kpi_oed >"$$log" 2>&1 & types_pid=$$!; \
	$(PY) -m pytest -n 2 --dist loadgroup -q --durations=15; tests=$$?; \
	wait $$types_pid; types=$$?; echo "mypy pin_kpi_oed:"; cat "$$log"; rm -f "$$log"; \
	test $$tests -eq 0 && test $$types -eq 0

test-fast: $(STAMP)
	$(PY) -m ruff check pin_kpi_oed tests
	$(PY) -m pytest -n 2 --dist loadgroup -q --fast

bench: $(STAMP)
	$(PY) -m benchmarks

clean:
	rm -rf $(VENV) build *.egg-info
