# The README's two commands are `make demo` and `make test`; both install first.
# Process-level settings (PETSC_DIR, Open MPI as root, oversubscription) live in
# pdemfem/runtime.py and reach every command through `$(RUN)`.
PYTHON := .venv/bin/python
RUN := $(PYTHON) -m pdemfem.launch
DEMO_SCENE := examples/coupled_demo.yaml
DEMO_OUT := out/demo
DEMO_RANKS := 2
PYTEST_ARGS ?=

.PHONY: install demo test benchmark clean

install:
	@bash scripts/install.sh

demo: install
	@$(RUN) -n $(DEMO_RANKS) -- $(PYTHON) -m pdemfem.cli run $(DEMO_SCENE) -o $(DEMO_OUT) --force
	@$(RUN) -- $(PYTHON) -m pdemfem.cli plot $(DEMO_OUT) --quiet
	@echo "demo results: $(DEMO_OUT)/ (history.csv, plots/*.png, particles.xdmf and plate.xdmf for ParaView)"

# One pytest worker per core (pytest-xdist); the tests that launch mpiexec all run on one of them, one at a
# time (tests/conftest.py), so that two MPI jobs never run at once.
test: install
	@$(RUN) -- $(PYTHON) -m pytest -q -n auto --dist loadgroup $(PYTEST_ARGS)

benchmark: install
	@$(RUN) -- $(PYTHON) benchmarks/settle.py

clean:
	rm -rf out .pytest_cache
