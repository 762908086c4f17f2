# fenicsx_drape: everything runs through ./drape, natively where DOLFINx >= 0.10 is installed,
# otherwise in the project's image (built from the Dockerfile on first use).
DRAPE := ./drape
PYTEST := python3 -m pytest -q

.PHONY: test test-serial test-parallel lint demo

# The whole suite: serially, the parallel tests again on 2 and 3 ranks, then the linter.
test: test-serial test-parallel lint

test-serial:
	$(DRAPE) exec $(PYTEST)

# pytest exits with 5 when no test is marked parallel: that is not a failure.
test-parallel:
	@for n in 2 3; do \
	  echo "$(DRAPE) exec mpirun -n $$n python3 -m mpi4py -m pytest -q -m parallel"; \
	  $(DRAPE) exec mpirun -n $$n python3 -m mpi4py -m $(PYTEST) -m parallel; rc=$$?; \
	  if [ $$rc -eq 5 ]; then echo "no test is marked parallel"; \
	  elif [ $$rc -ne 0 ]; then exit $$rc; fi; \
	done

lint:
	$(DRAPE) exec ruff check .

# The main demo: a hemisphere formed from a flat woven sheet.
demo:
	$(DRAPE) form hemisphere --out results/hemisphere
	@echo "pictures, fields and provenance.json: results/hemisphere/"
