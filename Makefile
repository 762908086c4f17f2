# fenicsx_drape: everything runs through ./drape, natively where DOLFINx >= 0.10 is installed,
# otherwise in the project's image (built from the Dockerfile on first use).
DRAPE := ./drape
# Every part of the suite ends with a verdict, whatever stops it. A test over its time limit
# (`timeout` in pyproject.toml) fails by its name and the part goes on (tests/verdict.py); a part
# still running after PART_LIMIT seconds is interrupted (pytest then prints its summary and the
# tests that did not finish). `make test` runs every part even after one failed, then prints
# one line per part (tests/run_part.sh, from the ledger each part writes as it runs).
PYTEST_ARGS := -q --ledger={ledger}
PART_LIMIT := 2700
LIMIT = timeout --foreground -s INT -k 60 $(PART_LIMIT)
PART = tests/run_part.sh
RESULTS :=
# The one-process tests on every core (pytest-xdist), each module whole on one worker, the
# heaviest modules first (tests/conftest.py: HEAVY). XDIST= runs them in one process.
XDIST := -n auto --dist loadfile --no-loadscope-reorder

.PHONY: test test-serial test-parallel test-fast test-launcher bench bench-parallel lint demo docs

# The whole suite: on every core, the parallel tests again on 2 and 3 ranks, the launcher's
# own tests on the host, the linter; then the verdict (non-zero exit when a part failed).
test:
	@results=$$(mktemp -d "$${TMPDIR:-/tmp}/fenicsx-drape-test.XXXXXX"); \
	$(MAKE) --no-print-directory -k test-serial test-parallel test-launcher lint \
	  RESULTS=$$results; \
	$(PART) --verdict $$results

test-serial:
	@$(PART) serial "$(RESULTS)" -- $(DRAPE) exec $(LIMIT) python3 -m pytest $(PYTEST_ARGS) \
	  $(XDIST) -m "not bench"

# The suite without the tests marked slow, for every change.
test-fast:
	@$(PART) fast "$(RESULTS)" -- $(DRAPE) exec $(LIMIT) python3 -m pytest $(PYTEST_ARGS) \
	  $(XDIST) -m "not slow and not bench"

# The heavy forming tests (marked bench): the full-size runs the suite checks on smaller ones,
# an hour each at most. Then the scenario benchmark (docs/scenarios.md): lab-style bundles with
# a hidden truth through the README's diagnose command, hours on two cores; it rewrites the
# page's table.
bench:
	@$(PART) bench "$(RESULTS)" -- $(DRAPE) exec python3 -m pytest $(PYTEST_ARGS) \
	  --timeout=3600 -m bench
	$(DRAPE) exec nice -n 10 python3 benchmarks/scenarios/run.py --seed 51 --count 48 \
	  --docs docs/scenarios.md

# The parallel tests on 2 ranks, the quick ones again on 3 (an odd partition; 3 ranks on two
# cores take twice as long, so the slow forming comparisons run on 2 only, and all of them with
# PARALLEL3="parallel"); those marked bench (a whole stack formed on 1 and N ranks, minutes
# of CPU) run with `make bench-parallel`. A part of these that selects no test is not a failure.
# A rank that waits for another yields its core: Open MPI otherwise spins, and on a machine
# busy with other work the rank it waits for then gets less of the core.
PARALLEL3 := parallel and not slow and not bench
MPIRUN := mpirun --mca mpi_yield_when_idle 1
test-parallel:
	@rc=0; \
	$(PART) --none-ok mpi-2 "$(RESULTS)" -- $(DRAPE) exec $(LIMIT) $(MPIRUN) -n 2 \
	  python3 -m mpi4py -m pytest $(PYTEST_ARGS) -m "parallel and not bench" || rc=1; \
	$(PART) --none-ok mpi-3 "$(RESULTS)" -- $(DRAPE) exec $(LIMIT) $(MPIRUN) -n 3 \
	  python3 -m mpi4py -m pytest $(PYTEST_ARGS) -m "$(PARALLEL3)" || rc=1; \
	exit $$rc

# The stacks formed under mpirun on 2 and 3 ranks against one (tests/test_forming_stack_parallel.py).
bench-parallel:
	@rc=0; \
	$(PART) --none-ok bench-mpi-2 "$(RESULTS)" -- $(DRAPE) exec $(LIMIT) $(MPIRUN) -n 2 \
	  python3 -m mpi4py -m pytest $(PYTEST_ARGS) -m "parallel and bench" || rc=1; \
	$(PART) --none-ok bench-mpi-3 "$(RESULTS)" -- $(DRAPE) exec $(LIMIT) $(MPIRUN) -n 3 \
	  python3 -m mpi4py -m pytest $(PYTEST_ARGS) -m "parallel and bench" || rc=1; \
	exit $$rc

# The launcher's own test runs where the launcher does: on the host (in the image it cannot
# start the image; there its test of what is mounted runs with the others). The host's pytest
# may have no pytest-timeout: its setting in pyproject.toml is then unknown there.
test-launcher:
	@if python3 -c "import pytest" 2>/dev/null; then \
	  $(PART) launcher "$(RESULTS)" -- python3 -m pytest -q -p no:cacheprovider \
	    -W "ignore:Unknown config option:pytest.PytestConfigWarning" \
	    --ledger={ledger} tests/test_launcher.py; \
	else $(PART) --skip launcher "$(RESULTS)" \
	  "no pytest on the host: tests/test_launcher.py runs in the image only"; fi

lint:
	@$(PART) ruff "$(RESULTS)" -- $(DRAPE) exec ruff check .

# The main demo: a hemisphere formed from a flat woven sheet.
demo:
	$(DRAPE) form hemisphere --out results/hemisphere
	@echo "pictures, fields and provenance.json: results/hemisphere/"

# The documentation as a website (docs/_build/html): the docs/ pages, the demos run as pages,
# the API reference from the docstrings (regenerated: no page of a module that is gone).
# Warnings are errors.
docs:
	rm -rf docs/api
	$(DRAPE) exec sphinx-build -W --keep-going -b html docs docs/_build/html
