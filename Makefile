# Two commands do everything on a fresh machine (see README.md):
#   make demo   - create .venv, install pinned dependencies, run the paper's scenario end to end
#                 in the recommended configuration (shipped gain, delay compensation);
#                 make demo ARGS=--paper: the paper's configuration (K_nf, no compensation)
#   make test   - create .venv if needed and run the whole test suite
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test venv bench reproduce clean

$(STAMP): requirements.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements.txt
	$(PY) -c "import pathlib, site; pathlib.Path(site.getsitepackages()[0], 'nonfragile_tracker_dev.pth').write_text(str(pathlib.Path('.').resolve()) + '\n')"
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(PY) -m nonfragile_tracker.cli run $(if $(filter --paper,$(ARGS)),,--delay-compensation) $(ARGS)

test: $(STAMP)
	$(PY) -m pytest -q -p no:cacheprovider test $(ARGS); rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "pytest collected no tests: failing"; exit 1; fi; exit $$rc

bench: $(STAMP)
	$(PY) benchmarks/run.py $(ARGS)

clean:
	rm -rf build install log
