#!/usr/bin/env bash
# A benchmark sweep on a GPU node without network access (docs/evaluation.md, "On an offline GPU
# node"). Such a node cannot download wheels or generate what it lacks from the network, and its run
# folders may not outlive the job: so the wheels it lacks and the default datasets are prepared
# beforehand on a machine with network and carried to it, the sweep runs for a fixed time budget, and
# what comes back, packed into the folder $OUT, is the archive of the trials that finished and the
# epochs and seconds of every trial (finished or not).
#
#   tools/offline_gpu_sweep.sh prepare
#       on a machine with network, once: the wheels the node lacks in .whl/, the default datasets in
#       .data/ (both ignored by git; carry both to the node with the checkout)
#   tools/offline_gpu_sweep.sh run BUDGET_S ARCHIVE BENCHMARK_ARGS...
#       on the node, in one job: `tactile-braille benchmark BENCHMARK_ARGS --archive ARCHIVE` on CUDA
#       (DEVICE to change), JOBS trials side by side (default 14), stopped after BUDGET_S seconds; then
#       ARCHIVE and the sweep's log as $OUT/records.tgz, and $OUT/epochs.tsv: each trial's folder,
#       epochs done and mean seconds an epoch. Unpack records.tgz in the checkout and commit the records.
#   tools/offline_gpu_sweep.sh start BUDGET_S ARCHIVE BENCHMARK_ARGS...
#       on the node: the same sweep in a process session of its own, which outlives the command that
#       started it (its state in STATE, default /tmp/offline_gpu_sweep); returns after about 20 s
#   tools/offline_gpu_sweep.sh collect WAIT_S
#       on the same node, later: waits up to WAIT_S s for the started sweep, then $OUT/records.tgz and
#       $OUT/epochs.tsv as `run` makes them, and $OUT/progress.tgz (every trial's progress.csv); a
#       sweep still running is left to run on
#   tools/offline_gpu_sweep.sh tune SEARCH_S FINAL_S TASK ALGO TRIALS [ARGS...]
#       on the node, in one job: the Stable-Baselines3 search of `python -m tactile_braille.baselines.sb3
#       tune TASK ALGO --trials TRIALS` on CUDA (DEVICE to change) by min(JOBS, TRIALS) processes sharing
#       its study in STUDY (default runs/tune: carry it to go on with a search begun elsewhere), stopped
#       after SEARCH_S seconds (a trial stopped there is run again by the next search; SEARCH_S 0: no
#       search, the final seeds of a finished one, whose study or record is in STUDY, e.g.
#       results/searches); then the best settings on SEEDS (default 0-4), a process each, stopped after
#       FINAL_S, into RESULTS (default results/leaderboard/sb3-tuned). ARGS go to both (--dataset FILE);
#       STEPS, if set, is the search's budget in place of the task's official one; FINAL_STEPS the final
#       seeds' (a quick check: their rows are then ranked apart). Then $OUT/tuning.tgz: the study, its
#       summary, the results files and each process's log.
#       With PRESET set, ALGO is one of this project's agents, searched from that preset by
#       `tactile-braille tune search|run TASK ALGO --preset PRESET` (its space: the agent's
#       `search_space`); STEPS and FINAL_STEPS are then EPOCHS and FINAL_EPOCHS, the final runs' folders
#       go under ROOT (default runs/tuned) and RESULTS defaults to results/tuned.
#
# SWEEP_COMMAND=sweep runs `tactile-braille sweep` instead of `benchmark` (a preset's variant: its
# settings and --variant NAME among the arguments).
#
# e.g. tools/offline_gpu_sweep.sh run 500 results/table3-v2 --paper --presets released \
#          --tasks DiscreteAlphabet-v0 --algos dqn --seeds 1 2 3 4 --precision bf16 --root runs/table3-v2
set -euo pipefail
cd "$(dirname "$0")/.."

STATE=${STATE:-/tmp/offline_gpu_sweep}
SWEEP_COMMAND=${SWEEP_COMMAND:-benchmark}

usage() { sed -n '2,42p' "$0" >&2; exit 2; }
fail() { echo "$*" >&2; exit 2; }

prepare() {
    local python=${PYTHON:-.venv/bin/python}
    local gym farama
    gym=$("$python" -c "import importlib.metadata as m; print(m.version('gymnasium'))")
    farama=$("$python" -c "import importlib.metadata as m; print(m.version('farama-notifications'))")
    "$python" -m pip download -q --no-deps --only-binary=:all: -d .whl \
        "gymnasium==$gym" "farama-notifications==$farama"
    # the tuning's: Stable-Baselines3, SB3-Contrib, Optuna and what the node lacks of their needs
    # (SQLAlchemy's wheel is compiled: the node's Python 3.12 and platform)
    local package versions=()
    for package in stable-baselines3 sb3-contrib optuna alembic sqlalchemy mako colorlog; do
        versions+=("$package==$("$python" -c "import importlib.metadata as m; print(m.version('$package'))")")
    done
    "$python" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
        --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
        -d .whl "${versions[@]}"
    "$python" -m tactile_braille.cli data  # the default datasets, generated or checked in the cache
    local cache
    cache=$("$python" -c "from tactile_braille.datasets.cache import data_dir; print(data_dir())")
    mkdir -p .data && cp -u "$cache"/*.h5 .data/
    du -sh .whl .data
}

check_budget() { [[ $1 =~ ^[0-9]+$ ]] || fail "$2 must be whole seconds, got '$1'"; }
check_command() {
    [[ $SWEEP_COMMAND =~ ^(benchmark|sweep)$ ]] || fail "SWEEP_COMMAND must be benchmark or sweep, got '$SWEEP_COMMAND'"
}

# the carried wheels installed, and the environment that finds them, the package and the datasets
setup() {
    ls .whl/*.whl > /dev/null 2>&1 || fail "no wheels in .whl/: run 'prepare' on a machine with network and carry .whl"
    [ -d .data ] || fail "no .data/: run 'prepare' on a machine with network and carry .data"
    PYTHON=${PYTHON:-python3}
    local site=${SITE:-/tmp/site}
    "$PYTHON" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$site" .whl/*.whl
    export PYTHON PYTHONPATH="$PWD/src:$site${PYTHONPATH:+:$PYTHONPATH}" TACTILE_BRAILLE_DATA="$PWD/.data"
}

root_of() {  # the benchmark's --root among its arguments
    local root=runs/paper-benchmark args=("$@") i
    [ "$SWEEP_COMMAND" = benchmark ] || root=runs/sweep
    for ((i = 0; i < ${#args[@]} - 1; i++)); do [ "${args[i]}" = --root ] && root=${args[i + 1]}; done
    echo "$root"
}

epochs() {  # each trial under ROOT: epochs done and mean seconds an epoch
    "$PYTHON" - "$1" <<'PYTHON'
import csv, sys
from pathlib import Path
print("trial\tepochs\tmean_epoch_s")
for progress in sorted(Path(sys.argv[1]).glob("*/*/progress.csv")) + sorted(Path(sys.argv[1]).glob("*/progress.csv")):
    rows = list(csv.DictReader(progress.open()))
    seconds = [float(r["time_s"]) for r in rows if r.get("time_s")]
    mean = f"{sum(seconds) / len(seconds):.2f}" if seconds else "-"
    print(f"{progress.parent}\t{len(rows)}\t{mean}")
PYTHON
}

sweep() {  # DEST BUDGET_S ARCHIVE BENCHMARK_ARGS...: the sweep, its records and epochs into DEST
    local dest=$1 budget=$2 archive=$3
    shift 3
    local status=0
    # appended, not truncated on open: a worker's resource tracker that outlives the sweep then writes
    # after the exit status line below, not over it
    : > "$dest/sweep.log"
    timeout --kill-after=20 "$budget" "$PYTHON" -m tactile_braille.cli "$SWEEP_COMMAND" "$@" --archive "$archive" \
        --device "${DEVICE:-cuda}" --threads 1 --jobs "${JOBS:-14}" --ray no >> "$dest/sweep.log" 2>&1 || status=$?
    echo "$SWEEP_COMMAND exit status $status (124: stopped at the budget of $budget s)" >> "$dest/sweep.log"
    epochs "$(root_of "$@")" > "$dest/epochs.tsv"
    mkdir -p "$archive"  # none finished: an empty archive still comes back, with the log
    tar czf "$dest/records.tgz" "$archive" -C "$dest" sweep.log
    cat "$dest/epochs.tsv"
}

run() {
    [ $# -ge 3 ] || usage
    check_budget "$1" BUDGET_S
    check_command
    [ -n "${OUT:-}" ] || fail "OUT is not set: where should the records go?"
    setup
    sweep "$OUT" "$@"
}

start() {
    [ $# -ge 3 ] || usage
    check_budget "$1" BUDGET_S
    check_command
    if [ -f "$STATE/pid" ] && kill -0 "$(cat "$STATE/pid")" 2> /dev/null; then
        fail "a sweep started here is still running (process $(cat "$STATE/pid")): collect it first"
    fi
    setup
    rm -rf "$STATE" && mkdir -p "$STATE"
    root_of "$@" > "$STATE/root"
    setsid nohup bash "$0" _sweep "$STATE" "$@" > "$STATE/start.log" 2>&1 < /dev/null &
    echo $! > "$STATE/pid"
    sleep "${START_WAIT_S:-20}"
    echo "sweep started (process $(cat "$STATE/pid")); its log so far:"
    tail -c 1500 "$STATE/sweep.log" 2> /dev/null || true
}

collect() {
    [ $# -eq 1 ] || usage
    check_budget "$1" WAIT_S
    [ -n "${OUT:-}" ] || fail "OUT is not set: where should the records go?"
    [ -f "$STATE/pid" ] || fail "no sweep was started in $STATE: run 'start' first, on this same node"
    PYTHON=${PYTHON:-python3}
    local pid waited=0
    pid=$(cat "$STATE/pid")
    while kill -0 "$pid" 2> /dev/null && [ "$waited" -lt "$1" ]; do sleep 1; waited=$((waited + 1)); done
    local root
    root=$(cat "$STATE/root")
    if kill -0 "$pid" 2> /dev/null; then
        echo "the sweep is still running after $waited s: what is done so far comes back; collect again later"
        epochs "$root" > "$OUT/epochs.tsv"
        cp "$STATE/sweep.log" "$OUT/" 2> /dev/null || true
    else
        echo "the sweep ended (waited $waited s)"
        cp "$STATE/records.tgz" "$STATE/epochs.tsv" "$OUT/"
    fi
    local progress=""  # none yet where the sweep has not made its root folder
    [ ! -d "$root" ] || progress=$(cd "$root" && find . -name progress.csv | sort)
    [ -z "$progress" ] || (cd "$root" && tar czf "$OUT/progress.tgz" $progress)
    cat "$OUT/epochs.tsv"
}

tune() {  # SEARCH_S FINAL_S TASK ALGO TRIALS [ARGS...]
    [ $# -ge 5 ] || usage
    check_budget "$1" SEARCH_S
    check_budget "$2" FINAL_S
    [[ $5 =~ ^[1-9][0-9]*$ ]] || fail "TRIALS must be a whole number of trials, got '$5'"
    [ -n "${OUT:-}" ] || fail "OUT is not set: where should the records go?"
    local search=$1 final=$2 task=$3 algo=$4 trials=$5
    [ "$final" -gt 0 ] || fail "FINAL_S must be more than 0 seconds (the final seeds' limit)"
    shift 5
    setup
    local study=${STUDY:-runs/tune} results logs i seed name
    local -a steps=() final_steps=() search_command run_command
    if [ -n "${PRESET:-}" ]; then  # one of this project's agents, from a preset
        results=${RESULTS:-results/tuned}
        name="${task}__${algo}__${PRESET}"
        search_command=(-m tactile_braille.cli tune search "$task" "$algo" --preset "$PRESET" --threads 1)
        run_command=(-m tactile_braille.cli tune run "$task" "$algo" --preset "$PRESET" --threads 1
            --root "${ROOT:-runs/tuned}")
        [ -z "${EPOCHS:-}" ] || steps=(--epochs "$EPOCHS")
        [ -z "${FINAL_EPOCHS:-}" ] || final_steps=(--epochs "$FINAL_EPOCHS")
    else  # Stable-Baselines3 or SB3-Contrib
        results=${RESULTS:-results/leaderboard/sb3-tuned}
        name="${task}__${algo}"
        search_command=(-m tactile_braille.baselines.sb3 tune "$task" "$algo")
        run_command=(-m tactile_braille.baselines.sb3 run "$task" "$algo")
        [ -z "${STEPS:-}" ] || steps=(--steps "$STEPS")
        [ -z "${FINAL_STEPS:-}" ] || final_steps=(--steps "$FINAL_STEPS")
    fi
    logs=$(mktemp -d)
    local jobs=$((${JOBS:-14} < trials ? ${JOBS:-14} : trials))
    [ "$search" -gt 0 ] || jobs=0  # `timeout 0` would not stop a search: 0 means none
    for ((i = 0; i < jobs; i++)); do  # SIGINT: a stopped trial is marked failed, not left running
        timeout --signal=INT --kill-after=20 "$search" "$PYTHON" "${search_command[@]}" \
            --trials "$trials" --study "$study" --device "${DEVICE:-cuda}" "${steps[@]}" "$@" \
            > "$logs/search_$i.log" 2>&1 &
        sleep 2  # each takes its trial before the next counts them
    done
    wait || true
    for seed in ${SEEDS:-0 1 2 3 4}; do
        timeout --signal=INT --kill-after=20 "$final" "$PYTHON" "${run_command[@]}" \
            --study "$study" --seeds "$seed" --into "$results" --device "${DEVICE:-cuda}" \
            "${final_steps[@]}" "$@" \
            > "$logs/final_$seed.log" 2>&1 &
    done
    wait || true
    mkdir -p "$results"
    tar czf "$OUT/tuning.tgz" "$study/$name".* "$results" -C "$logs" .
    tail -n 3 "$logs"/*.log
}

case ${1:-} in
    prepare) prepare ;;
    run) shift; run "$@" ;;
    start) shift; start "$@" ;;
    collect) shift; collect "$@" ;;
    tune) shift; tune "$@" ;;
    _sweep) shift; dest=$1; shift; sweep "$dest" "$@" ;;
    *) usage ;;
esac
