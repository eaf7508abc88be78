# The two README commands: `make demo` (install + main job) and `make test` (install + tests).
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: install demo test thesis bench clean

$(STAMP): pyproject.toml
	bash scripts/install-system-deps.sh
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/topomatch run configs/demo.yaml
	$(BIN)/topomatch run configs/registration/demo.yaml
	$(BIN)/topomatch run configs/retrieval/demo.yaml

# Every figure and table of the thesis on one page (thesis/thesis.html); the external data root
# (DATA_ROOT, default ../shared/data when it exists) adds the configs that need it.
DATA_ROOT ?= $(wildcard ../shared/data)
thesis: $(STAMP)
	$(BIN)/topomatch thesis --out thesis $(if $(DATA_ROOT),--data-root $(DATA_ROOT))

test: $(STAMP)
	bash scripts/install-system-deps.sh --browser
	TOPOMATCH_ARTEFACTS=$${TOPOMATCH_ARTEFACTS:-test-artefacts} $(BIN)/python -m pytest -q

clean:
	rm -rf runs thesis .pytest_cache test-artefacts
