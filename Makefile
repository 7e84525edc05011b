# symtrack: two commands on a fresh clone (Python 3.11+ and a C compiler):
#   make demo   -> .venv, install, run the validation scenario, plots and summary in out/validation/
#   make test   -> .venv with the dev extra, ruff, the whole test suite (what CI runs; make test-fast: the
#                  fast set without the slow physics and build checks, make test-slow: only those)
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python

.PHONY: demo test test-fast test-slow lint clean codegen standalone grid-standalone bench fuzz validate docs docs-examples performance keys figures

# installs through uv (pip's interface and resolution, about a seventh of pip's time for the dev extra on a
# fresh machine), or through pip where uv does not install. --compile-bytecode: the installed modules'
# bytecode written once here, as pip does by default (uv does not); without it every Python process
# compiles what it imports from source where the environment sets PYTHONDONTWRITEBYTECODE (casadi,
# numpy, matplotlib, distributed: 4.1 s of CPU per process against 1.1 s, measured by importing
# symtrack.api, its figures, distributed and the closed loop), and the tests start hundreds of them
PIP := $(PY) -m pip install --quiet --disable-pip-version-check
install = ($(PIP) uv && $(VENV)/bin/uv pip install --quiet --compile-bytecode --python $(PY) $(1)) || $(PIP) $(1)
# the package's own bytecode (an editable install is not compiled by the installers); a module edited
# since is compiled again from its source when imported (its timestamp no longer matches)
compile_package = $(PY) -m compileall -q -j 0 symtrack > /dev/null

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(call install,-e .)
	$(compile_package)
	touch $@

$(VENV)/.installed-dev: $(VENV)/.installed
	$(call install,-e '.[dev]')
	touch $@

demo: $(VENV)/.installed
	$(VENV)/bin/symtrack simulate validation --out out/validation

lint: $(VENV)/.installed-dev
	$(VENV)/bin/ruff check .

# the whole suite in one pytest session (the slow tests share their files' fixtures and workers)
test: lint
	$(compile_package)
	$(PY) -m pytest

# the fast set: everything but the tests marked slow
test-fast: lint
	$(compile_package)
	$(PY) -m pytest -m "not slow"

# the tests marked slow (pyproject.toml: brute-force, IDAS and fixed-step references, large compiles)
test-slow: $(VENV)/.installed-dev
	$(compile_package)
	$(PY) -m pytest -m slow

# the scenario loader's fuzz tests with a longer search than the test suite's (100 mutated documents)
fuzz: $(VENV)/.installed-dev
	SYMTRACK_FUZZ_EXAMPLES=3000 $(PY) -m pytest -n 0 tests/test_scenario_mutation.py

# generated C (docs/codegen.md): regenerate generated/, build and run the standalone program, benchmark
CC ?= cc
codegen: $(VENV)/.installed
	$(PY) -m codegen

build/symtrack_standalone: symtrack/codegen/standalone_main.c symtrack/native/distance_stop.h generated/homogeneous_rosenbrock.c generated/homogeneous_rosenbrock.h generated/homogeneous_validation.h
	mkdir -p build
	$(CC) -O2 -std=c99 -Wall -Igenerated -Isymtrack/native symtrack/codegen/standalone_main.c generated/homogeneous_rosenbrock.c -o $@ -lm

standalone: build/symtrack_standalone
	./build/symtrack_standalone

# the grid validation (validation_grid, the million-cell field) on the terrain engine, libc and libm only
build/symtrack_grid_standalone: symtrack/codegen/grid_standalone_main.c symtrack/native/grid_engine.c symtrack/native/subsoil.h symtrack/native/terrain_query.h symtrack/native/distance_stop.h generated/engine_gen.inc generated/engine_soils.inc generated/grid_validation.h
	mkdir -p build
	$(CC) -O2 -Wall -Wno-unused-function -Wno-unused-variable -Wno-unused-but-set-variable -Igenerated -Isymtrack/native symtrack/codegen/grid_standalone_main.c -o $@ -lm

grid-standalone: build/symtrack_grid_standalone
	./build/symtrack_grid_standalone build/grid_validation.csv

# the gallery of published measurements against the models (docs/validation.md): every case, into out/validate
validate: $(VENV)/.installed
	$(VENV)/bin/symtrack validate --out out/validate

bench: $(VENV)/.installed build/symtrack_standalone
	$(VENV)/bin/symtrack bench --out out/bench.json

# the documentation site (docs/index.md): Sphinx over docs/*.md, warnings as errors, into docs/_build/html; the
# gallery of examples/ generated into docs/gallery, its quick examples run (docs/gallery_examples.py; an
# unchanged example is not run again: make clean removes the gallery)
$(VENV)/.installed-docs: $(VENV)/.installed
	$(call install,-e '.[docs]')
	touch $@

# the key tables of docs/scenarios.md ("Keys of a simulation"), made from the loader's own declarations
keys: $(VENV)/.installed
	$(PY) -m symtrack.simulation.keys docs/scenarios.md

docs: $(VENV)/.installed-docs
	$(PY) -m sphinx -b html -W --keep-going docs docs/_build/html
	@echo "the site: docs/_build/html/index.html"

# the examples the pages cite that take under a minute each on a 2-core machine, from the checkout, figures
# into out/examples (about 7 min in all); the slower ones (oscillation_study, one_soil, mpc_headland_uturn,
# bench_terrain, density_passes) say at their top how to run them
EX := out/examples
docs-examples: $(VENV)/.installed
	mkdir -p $(EX)
	$(PY) examples/ramp_3d.py --plot $(EX)/ramp_3d.png
	$(PY) examples/side_slope_3d.py --plot $(EX)/side_slope_3d.png
	$(PY) examples/furrows_3d.py --plot $(EX)/furrows_3d.png
	$(PY) examples/second_pass_3d.py --plot $(EX)/second_pass_3d.png
	$(PY) examples/mpc_side_slope_3d.py --plot $(EX)/mpc_side_slope_3d.png
	$(PY) examples/turn_rut.py --plot $(EX)/turn_rut.png
	$(PY) examples/steady_turns.py
	$(PY) examples/hull_rotation.py
	$(PY) examples/kroulik_seasons.py --plot $(EX)/kroulik_seasons.png
	$(PY) examples/gis_field.py --out $(EX)/gis_field --png $(EX)/gis_field/rut_depth.png
	$(PY) examples/wet_headland.py --out $(EX)/wet_headland
	$(PY) examples/lqr_speed_yaw.py --out $(EX)/lqr_speed_yaw
	$(PY) examples/lane_keeping_ruts.py --out $(EX)/lane_keeping_ruts
	$(PY) examples/compaction_reference.py
	$(PY) examples/compaction_day_and_machine.py
	$(PY) examples/tracks_against_wheels.py
	$(PY) examples/engine_variants.py
	$(PY) examples/engine_clocks.py
	$(PY) examples/validation_sensitivity.py

# today's speed figures: measures and rewrites the tables of docs/performance.md (a few minutes)
performance: $(VENV)/.installed
	$(PY) docs/performance.py

# the tables of run results in the pages (docs/figures.py): runs each table's command again and rewrites the
# table between its markers; NAMES="a b" for some of them (python docs/figures.py --list names them); the whole
# takes about an hour on a 2-core machine (docs/howto.md, "Regenerate the figures")
figures: $(VENV)/.installed
	$(PY) docs/figures.py $(if $(NAMES),--only $(NAMES))

clean:
	rm -rf out build *.egg-info docs/_build docs/gallery
