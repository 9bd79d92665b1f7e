#!/usr/bin/env bash
# Part of a benchmark sweep on a lent GPU machine, inside one command (docs/evaluation.md, "On a lent
# GPU machine"). Those machines lack gymnasium, reach no network, and are given back about 30 seconds
# after a command ends, taking the run folders with them: so the sweep runs for a fixed budget inside
# the command, and what comes back is the archive of the trials that finished and the epochs and
# seconds of every trial (finished or not), the GPU wall-clock.
#
#   tools/lent_gpu_sweep.sh prepare
#       here, once: the wheels the machine lacks in .whl/, the default datasets in .data/ (both ignored
#       by git; name them in the device tool's `carry`)
#   tools/lent_gpu_sweep.sh run BUDGET_S ARCHIVE BENCHMARK_ARGS...
#       there: `tactile-braille benchmark BENCHMARK_ARGS --archive ARCHIVE` on CUDA (DEVICE to change),
#       JOBS trials side by side (default 14), stopped after BUDGET_S seconds; then ARCHIVE and the
#       sweep's log as $OUT/records.tgz, and $OUT/epochs.tsv: each trial's folder, epochs done and
#       mean seconds an epoch. Unpack records.tgz in the repository here and commit the records.
#
# e.g. tools/lent_gpu_sweep.sh run 500 results/table3-v2 --paper --presets released \
#          --tasks DiscreteAlphabet-v0 --algos dqn --seeds 1 2 3 4 --precision bf16 --root runs/table3-v2
set -euo pipefail
cd "$(dirname "$0")/.."

usage() { sed -n '2,19p' "$0" >&2; exit 2; }

prepare() {
    local python=${PYTHON:-.venv/bin/python}
    local gym farama
    gym=$("$python" -c "import importlib.metadata as m; print(m.version('gymnasium'))")
    farama=$("$python" -c "import importlib.metadata as m; print(m.version('farama-notifications'))")
    "$python" -m pip download -q --no-deps --only-binary=:all: -d .whl \
        "gymnasium==$gym" "farama-notifications==$farama"
    "$python" -m tactile_braille.cli data  # the default datasets, generated or checked in the cache
    local cache
    cache=$("$python" -c "from tactile_braille.datasets.cache import data_dir; print(data_dir())")
    mkdir -p .data && cp -u "$cache"/*.h5 .data/
    du -sh .whl .data
}

run() {
    [ $# -ge 3 ] || usage
    local budget=$1 archive=$2
    shift 2
    [[ $budget =~ ^[0-9]+$ ]] || { echo "BUDGET_S must be whole seconds, got '$budget'" >&2; exit 2; }
    [ -n "${OUT:-}" ] || { echo "OUT is not set: where should the records go?" >&2; exit 2; }
    ls .whl/*.whl > /dev/null 2>&1 || { echo "no wheels in .whl/: run 'prepare' here and carry .whl" >&2; exit 2; }
    [ -d .data ] || { echo "no .data/: run 'prepare' here and carry .data" >&2; exit 2; }
    local python=${PYTHON:-python3} site=${SITE:-/tmp/site}
    "$python" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target "$site" .whl/*.whl
    export PYTHONPATH="$PWD/src:$site${PYTHONPATH:+:$PYTHONPATH}" TACTILE_BRAILLE_DATA="$PWD/.data"
    local root=runs/paper-benchmark args=("$@") i
    for ((i = 0; i < ${#args[@]} - 1; i++)); do [ "${args[i]}" = --root ] && root=${args[i + 1]}; done
    local status=0
    # appended, not truncated on open: a worker's resource tracker that outlives the sweep then writes
    # after the exit status line below, not over it
    : > "$OUT/sweep.log"
    timeout --kill-after=20 "$budget" "$python" -m tactile_braille.cli benchmark "$@" --archive "$archive" \
        --device "${DEVICE:-cuda}" --threads 1 --jobs "${JOBS:-14}" --ray no >> "$OUT/sweep.log" 2>&1 || status=$?
    echo "benchmark exit status $status (124: stopped at the budget of $budget s)" >> "$OUT/sweep.log"
    "$python" - "$root" > "$OUT/epochs.tsv" <<'PYTHON'
import csv, sys
from pathlib import Path
print("trial\tepochs\tmean_epoch_s")
for progress in sorted(Path(sys.argv[1]).glob("*/*/progress.csv")) + sorted(Path(sys.argv[1]).glob("*/progress.csv")):
    rows = list(csv.DictReader(progress.open()))
    seconds = [float(r["time_s"]) for r in rows if r.get("time_s")]
    mean = f"{sum(seconds) / len(seconds):.2f}" if seconds else "-"
    print(f"{progress.parent}\t{len(rows)}\t{mean}")
PYTHON
    mkdir -p "$archive"  # none finished: an empty archive still comes back, with the log
    tar czf "$OUT/records.tgz" "$archive" -C "$OUT" sweep.log
    cat "$OUT/epochs.tsv"
}

case ${1:-} in
    prepare) prepare ;;
    run) shift; run "$@" ;;
    *) usage ;;
esac
