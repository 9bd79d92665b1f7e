# The two commands of the README: `make run` and `make test`.
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
OUT ?= outputs

.PHONY: run test test-slow lint bench results docs clean

# torch is pinned to the version whose CPU build the project's machines hold; a looser
# pin would download gigabytes of CUDA packages. Elsewhere, for the CPU wheel:
# make test TORCH_PIP_ARGS="--index-url https://download.pytorch.org/whl/cpu"
TORCH_PIP_ARGS ?=
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet torch==2.13.0 $(TORCH_PIP_ARGS)
	$(PY) -m pip install --quiet -e ".[dev]"
	touch $(STAMP)

TB := $(VENV)/bin/tactile-braille
DQN_RUN := $(OUT)/DiscreteArrows__dqn

# Datasets, galleries, then a short DQN + HER run on DiscreteArrows (about two
# minutes; continued, not restarted, if it exists) and its report.
run: $(STAMP)
	$(TB) data
	$(TB) show --output $(OUT)/gallery.png
	$(TB) show grid-alphabet --output $(OUT)/grid-alphabet.png
	if [ -f $(DQN_RUN)/config.json ]; then $(TB) train --resume $(DQN_RUN); \
	else $(TB) train DiscreteArrows-v0 dqn --epochs 6 --precision bf16 --test-episodes 10 --run-dir $(DQN_RUN); fi
	$(TB) report $(DQN_RUN) --episodes 50

# Two workers (one per core here); each test file runs whole in one worker, in its own order.
TEST_WORKERS ?= 2
test: $(STAMP)
	$(PY) -m pytest -q -m "not slow" -n $(TEST_WORKERS) --dist loadfile

# The slow tests include a sweep on a local Ray: the optional `sweep` extra.
test-slow: $(STAMP)
	$(PY) -m pip install --quiet -e ".[dev,sweep]"
	$(PY) -m pytest -q -m slow

# The documentation site (mkdocs.yml) into $(OUT)/site; strict: a warning (a broken link between pages,
# an unknown anchor, a docstring that contradicts its signature) fails the build. CI builds it too.
docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(VENV)/bin/mkdocs build --strict --site-dir $(OUT)/site

lint: $(STAMP)
	$(VENV)/bin/ruff check . && $(VENV)/bin/ruff format --check .

bench: $(STAMP)
	$(PY) benchmarks/activation_map.py
	$(PY) benchmarks/render.py
	$(PY) benchmarks/collect.py
	$(PY) benchmarks/separability.py
	$(PY) benchmarks/train_throughput.py

# docs/results.md, generated whole from the runs' records committed under results/ (settings, world,
# progress and typing of each run; no checkpoints: `tactile-braille benchmark ... --archive results/...`
# and `tactile-braille archive` write them). Runs on any machine, no training needed.
# docs/leaderboard.md ranks those records and the results files of other libraries' agents
# (results/leaderboard/, written by examples/) per task and track (docs/benchmark.md), and puts its
# headline table (per task: the paper, our best per track, the best other method) into README.md.
# results/tuning/ holds the runs settings were chosen on (their seeds are not reported), and
# results/diagnostics/ runs that test a cause (some stopped early): both left out here.
# results/transfer/ holds runs typed in other worlds (evaluate --world): their own section.
# results/warm-start/ holds warm starts (train --init-from) and their sources: their own section too.
ALL_RECORDS = $(sort $(patsubst %/,%,$(dir $(wildcard results/*/*/config.json results/*/*/*/config.json))))
RECORDS = $(filter-out results/tuning/% results/diagnostics/% results/transfer/% results/warm-start/%,$(ALL_RECORDS))
TRANSFER = $(filter results/transfer/%,$(ALL_RECORDS))
WARM = $(filter results/warm-start/%,$(ALL_RECORDS))
# results/ablation-*/ hold ablations (a preset with one part taken away or changed): tabled, not ranked.
RANKED = $(filter-out results/ablation-%,$(RECORDS))
RESULT_FILES = $(sort $(wildcard results/leaderboard/*/*.json))
results: $(STAMP)
	$(TB) report $(RECORDS) --output docs/results.md $(if $(TRANSFER),--transfer $(TRANSFER)) \
		$(if $(WARM),--warm-start $(WARM)) \
		--notes docs/results-notes.md --title "Results: Table III with the paper's and the released code's settings"
	$(TB) leaderboard $(RANKED) $(RESULT_FILES) --output docs/leaderboard.md --headline README.md \
		--title "Leaderboard: typing on the braille keyboard"

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .ruff_cache
