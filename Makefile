# fenicsx_drape: everything runs through ./drape, natively where DOLFINx >= 0.10 is installed,
# otherwise in the project's image (built from the Dockerfile on first use).
DRAPE := ./drape
# A test that runs 5 min prints the stacks of its threads (a hung collective shows where), and
# a run stuck for 30 min is stopped (exit status 124), so that CI fails instead of stalling.
PYTEST_ARGS := -q -o faulthandler_timeout=300
LIMIT := timeout 1800
# The one-process tests on every core (pytest-xdist; a worker that is done takes tests from the
# other's queue, so that the few long tests do not end on one). XDIST= runs them in one process.
XDIST := -n auto --dist worksteal

.PHONY: test test-serial test-parallel test-fast test-launcher bench lint demo docs

# The whole suite: on every core, the parallel tests again on 2 and 3 ranks, the launcher's
# own tests on the host, then the linter.
test: test-serial test-parallel test-launcher lint

test-serial:
	$(DRAPE) exec $(LIMIT) python3 -m pytest $(PYTEST_ARGS) $(XDIST) -m "not bench"

# The suite without the tests marked slow: a few minutes, for every change.
test-fast:
	$(DRAPE) exec $(LIMIT) python3 -m pytest $(PYTEST_ARGS) $(XDIST) -m "not slow and not bench"

# The heavy forming tests (marked bench): the full-size runs the suite checks on smaller ones.
# Then the scenario benchmark (docs/scenarios.md): lab-style bundles with a hidden truth through
# the README's diagnose command, hours on two cores; it rewrites the page's table.
bench:
	$(DRAPE) exec $(LIMIT) python3 -m pytest $(PYTEST_ARGS) -m bench
	$(DRAPE) exec nice -n 10 python3 benchmarks/scenarios/run.py --seed 51 --count 48 \
	  --docs docs/scenarios.md

# The parallel tests on 2 ranks, the quick ones again on 3 (an odd partition; 3 ranks on two
# cores take twice as long, so the slow forming comparisons run on 2 only, and all of them with
# PARALLEL3="parallel"). pytest exits with 5 when no test is selected: not a failure.
PARALLEL3 := parallel and not slow
test-parallel:
	@for n in 2 3; do \
	  if [ $$n -eq 2 ]; then marks="parallel"; else marks="$(PARALLEL3)"; fi; \
	  echo "$(DRAPE) exec mpirun -n $$n python3 -m mpi4py -m pytest $(PYTEST_ARGS) -m \"$$marks\""; \
	  $(DRAPE) exec $(LIMIT) mpirun -n $$n python3 -m mpi4py -m pytest $(PYTEST_ARGS) \
	    -m "$$marks"; rc=$$?; \
	  if [ $$rc -eq 5 ]; then echo "no test is marked $$marks"; \
	  elif [ $$rc -ne 0 ]; then exit $$rc; fi; \
	done

# The launcher's own test runs where the launcher does: on the host (in the image it cannot
# start the image; there its test of what is mounted runs with the others).
test-launcher:
	@if python3 -c "import pytest" 2>/dev/null; then \
	  python3 -m pytest $(PYTEST_ARGS) -p no:cacheprovider tests/test_launcher.py; \
	else echo "no pytest on the host: tests/test_launcher.py runs in the image only"; fi

lint:
	$(DRAPE) exec ruff check .

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
