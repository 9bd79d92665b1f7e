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
	else $(TB) train DiscreteArrows-v0 dqn --epochs 6 --test-episodes 10 --run-dir $(DQN_RUN); fi
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

# The results pages, generated whole from the runs' records committed under results/ (settings, world,
# progress and typing of each run; no checkpoints: `tactile-braille benchmark ... --archive results/...`
# and `tactile-braille archive` write them). Runs on any machine, no training needed, and rewrites the
# same bytes from the same records (python -m tactile_braille.evaluation.results_pages):
# - docs/results.md: figures, one row per preset, task and agent against the paper's Table III and the
#   typing bound, Table III's coverage, docs/results-notes.md (a reading of them; the long account is
#   docs/notes/results-account.md), and the sections on transfer and warm starts;
# - docs/results-ablations.md: the rows whose settings depart from their preset, and results/ablation-*/
#   (a preset with one part taken away or changed), grouped by preset;
# - docs/results-runs.md: each row's runs and typing confusion;
# - docs/results-tuning.md: results/tuning/ (the runs settings were chosen on; their seeds are not
#   reported) and results/diagnostics/ (runs that test a cause, some stopped early), a row per record.
# results/transfer/ holds runs typed in other worlds (evaluate --world), results/warm-start/ warm starts
# (train --init-from) and their sources: a section each on docs/results.md.
# docs/leaderboard.md ranks the records (not the ablations) and the results files of other libraries'
# agents (results/leaderboard/, written by examples/) per task and track (docs/benchmark.md), and puts its
# headline table (per task: the paper, our best per track, the best other method) into README.md.
ALL_RECORDS = $(sort $(patsubst %/,%,$(dir $(wildcard results/*/*/config.json results/*/*/*/config.json))))
RECORDS = $(filter-out results/tuning/% results/diagnostics/% results/transfer/% results/warm-start/%,$(ALL_RECORDS))
TRANSFER = $(filter results/transfer/%,$(ALL_RECORDS))
WARM = $(filter results/warm-start/%,$(ALL_RECORDS))
ABLATIONS = $(filter results/ablation-%,$(RECORDS))
RANKED = $(filter-out results/ablation-%,$(RECORDS))
RESULT_FILES = $(sort $(wildcard results/leaderboard/*/*.json))
results: $(STAMP)
	$(PY) -m tactile_braille.evaluation.results_pages $(RANKED) --ablations $(ABLATIONS) \
		--transfer $(TRANSFER) --warm-start $(WARM) --tuning results/tuning --diagnostics results/diagnostics \
		--notes docs/results-notes.md --output docs/results.md \
		--title "Results: Table III with the paper's settings, the released code's and ours"
	$(TB) leaderboard $(RANKED) $(RESULT_FILES) --output docs/leaderboard.md --headline README.md \
		--figure docs/images/leaderboard_profiles.png \
		--title "Leaderboard: typing on the braille keyboard"

clean:
	rm -rf $(VENV) $(OUT) .pytest_cache .ruff_cache
