# Two commands do everything on a fresh machine (see README.md):
#   make demo   - create .venv, install pinned dependencies, run the paper's scenario end to end
#                 in the recommended configuration (the shipped latency-certified default gain
#                 config/tracker_gains.yaml, delay compensation);
#                 make demo ARGS=--paper: the paper's configuration (K_nf, no compensation)
#                 make demo ARGS="--robot jackal": a MuJoCo base (turtlebot3, jackal_skid)
#   make test   - create .venv if needed and run the whole test suite
#   (make docs  - build the documentation in doc/ into doc/_build/html, warnings as errors)
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
# setuptools of a Jazzy install (Ubuntu 24.04) and the newest colcon-core accepts, each in a
# directory of its own: test/package/test_colcon_setuptools.py builds the package with each
COLCON_SETUPTOOLS := 68.1.2 79.0.1

.PHONY: demo test soak docs venv bench bench-env tdcpy-env reproduce clean

# The dependencies are byte-compiled after the install, on every core (pip compiles one file
# after another: 35 s -> 27 s); a file that does not compile is skipped, as pip skips it.
$(STAMP): requirements.txt
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --no-compile --disable-pip-version-check -r requirements.txt
	for v in $(COLCON_SETUPTOOLS); do $(PY) -m pip install --quiet --no-compile \
	  --disable-pip-version-check --no-deps --target $(VENV)/colcon-setuptools/$$v \
	  setuptools==$$v || exit 1; done
	$(PY) -m compileall -q -j 0 $(VENV)/lib $(VENV)/colcon-setuptools > /dev/null || true
	$(PY) -c "import pathlib, site; pathlib.Path(site.getsitepackages()[0], 'nonfragile_tracker_dev.pth').write_text(str(pathlib.Path('.').resolve()) + '\n')"
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(PY) -m nonfragile_tracker.cli run $(if $(filter --paper,$(ARGS)),,--delay-compensation) $(ARGS)

# Every test but the real-time ones on one worker more than cores (pytest-xdist, whole modules
# per worker; the ROS tests wait on processes and DDS part of the time, and in lockstep or
# about processes they do not depend on the load; each worker has ROS domains of its own),
# then the numerical tests (mark `numerical`: synthesis, certificates, delay spectrum,
# reproduction, golden bags and replays) again under a second OpenBLAS kernel - OpenBLAS picks
# its kernels by CPU and the suite must pass on any CPU: test/blas_kernel.py chooses it per
# architecture (x86-64: Sandybridge, or Prescott; aarch64: ARMV8; else none, said loudly) and
# test/test_blas_kernel.py checks that the pass really ran it - then the real-time tests
# alone, at most three at a time (-n 3): they run nodes on the wall clock and judge timing, and
# together use about 0.75 of the two cores.  The first pass keeps the machine's environment.
# The package is byte-compiled first: with PYTHONDONTWRITEBYTECODE set (as in CI) every node
# process would compile it again.
# Exit 5 (no tests) is a failure unless another part ran tests (ARGS may select one part).
WORKERS ?= $(shell echo $$(( $$(nproc) + 1 )))
test: $(STAMP)
	$(PY) -m compileall -q nonfragile_tracker
	$(PY) -m pytest -q -p no:cacheprovider -n $(WORKERS) -m "not realtime" test $(ARGS); a=$$?; \
	first=$$($(PY) test/blas_kernel.py --current) && second=$$($(PY) test/blas_kernel.py) || exit 1; \
	env $$second NONFRAGILE_FIRST_KERNEL=$$first $(PY) -m pytest -q -p no:cacheprovider \
	  -n $(WORKERS) -m "numerical and not realtime" test $(ARGS); c=$$?; \
	$(PY) -m pytest -q -p no:cacheprovider -n 3 -m realtime test $(ARGS); b=$$?; \
	if [ $$a -eq 5 ] && [ $$b -eq 5 ] && [ $$c -eq 5 ]; then echo "pytest collected no tests: failing"; exit 1; fi; \
	for rc in $$a $$c $$b; do if [ $$rc -ne 0 ] && [ $$rc -ne 5 ]; then exit $$rc; fi; done

# The signal tests repeated to catch rare races (20 trials of every pattern instead of 8), and
# Ctrl-C under an emulated ros2 launch at 20 random moments (every node ends within 1 s).
soak: $(STAMP)
	NONFRAGILE_SOAK=1 $(PY) -m pytest -q -p no:cacheprovider -n 0 test/nodes/test_signals.py $(ARGS)

# The Sphinx + MyST project in doc/ (rosdoc2's layout), as test/package/test_docs.py builds it.
docs: $(STAMP)
	$(PY) -m sphinx -W --keep-going -q -b html doc doc/_build/html
	@echo "docs: doc/_build/html/index.html"

# tdcpy (peer of the delay-analysis rows 2.4) in its own environment benchmarks/tdcpy-venv,
# made by `make bench` if missing (skipped when TDCPY_PYTHON names an interpreter that has
# it).  If PyPI is not reachable the rows show ours only and `make bench` does not try again
# (a marker file) until `make bench-env` is run.
TDCPY_VENV := benchmarks/tdcpy-venv
TDCPY_REQ := benchmarks/tdcpy-requirements.txt

bench-env:
	@rm -f $(TDCPY_VENV)/.failed
	@$(MAKE) --no-print-directory tdcpy-env

tdcpy-env:
ifeq ($(TDCPY_PYTHON),)
	@if [ -f $(TDCPY_VENV)/.failed ]; then \
	  echo "tdcpy: not installed (an earlier attempt failed; make bench-env tries again)"; \
	elif [ ! -f $(TDCPY_VENV)/.installed ] || [ $(TDCPY_REQ) -nt $(TDCPY_VENV)/.installed ]; then \
	  echo "creating $(TDCPY_VENV) (tdcpy from PyPI, for benchmark rows 2.4)"; \
	  rm -rf $(TDCPY_VENV); \
	  if $(PYTHON) -m venv $(TDCPY_VENV) && $(TDCPY_VENV)/bin/pip install --quiet \
	      --disable-pip-version-check --retries 1 --timeout 20 -r $(TDCPY_REQ); then \
	    touch $(TDCPY_VENV)/.installed; \
	  else \
	    rm -rf $(TDCPY_VENV); mkdir -p $(TDCPY_VENV); touch $(TDCPY_VENV)/.failed; \
	    echo "tdcpy could not be installed (PyPI not reachable?): rows 2.4 show ours only"; \
	  fi; \
	fi
endif

bench: $(STAMP) tdcpy-env
	$(PY) benchmarks/run.py $(ARGS)

clean:
	rm -rf build install log doc/_build
