#!/usr/bin/env bash
# The leaderboard's rows from other libraries' agents: Stable-Baselines3 with HER on every task and the
# single-file CleanRL-style DQN + HER on the discrete ones, at the budgets and seeds below (one CPU thread
# per run). A results file that exists is kept, so a stopped run of this script goes on where it was.
# Usage: examples/baselines.sh [FILTER]   (FILTER: part of a task or algorithm name)
set -euo pipefail
PY=${PY:-.venv/bin/python}
OUT=${OUT:-results/leaderboard}
FILTER=${1:-}

run() {  # TASK ALGO ENV_STEPS SEEDS [FILE_SUFFIX]
    [[ -z $FILTER || "$1 $2" == *$FILTER* ]] || return 0
    for seed in $4; do
        case $2 in
            cleanrl) file="$OUT/cleanrl/$1__dqn_her__$seed.json"
                command=(examples/cleanrl_dqn_her.py --task "$1" --her sampled) ;;
            cleanrl-paper) file="$OUT/cleanrl/$1__dqn_paper_her__$seed.json"
                command=(examples/cleanrl_dqn_her.py --task "$1" --her paper) ;;
            *) file="$OUT/sb3/$1__$2__$seed${5:-}.json"
                command=(examples/sb3_her.py "$1" "$2") ;;
        esac
        [[ -f $file ]] || "$PY" "${command[@]}" --steps "$3" --seed "$seed" --output "$file"
    done
}

# Settings fixed before any run (seed 0). The paper's relabelling in the CleanRL-style script was added
# after seed 0 of the sampled one: it is reported on fresh seeds only.
run DiscreteArrows-v0 dqn 6000 "0 1 2"
run DiscreteArrows-v0 dqn 20000 0 __20000steps
run DiscreteArrows-v0 cleanrl 6000 0
run DiscreteArrows-v0 cleanrl-paper 6000 "1 2 3 4"
run DiscreteAlphabet-v0 dqn 15000 0
run DiscreteAlphabet-v0 cleanrl 15000 0
run DiscreteAlphabet-v0 cleanrl-paper 15000 1
run ContinuousArrows-v0 sac 4000 0
run ContinuousArrows-v0 td3 4000 0
run ContinuousAlphabet-v0 sac 4000 0
run ContinuousAlphabet-v0 td3 4000 0

# Tuned by the benchmark's protocol (docs/benchmark.md, "The tuning protocol"): an Optuna search on tuning
# seed 100 at the task's official budget, or at SEARCH_STEPS where given (its journal under runs/tune: a
# stopped search goes on; two processes may share it), then the best settings on fresh seeds 0-4 at the
# official budget. A finished search's record is committed in results/searches/: on a machine without
# runs/tune, `run ... --study results/searches`. A trial of the continuous tasks' 25,000 steps takes over an
# hour on one CPU core (SB3's SAC), so their searches train 7,500 steps a trial; on a GPU node,
# `tools/offline_gpu_sweep.sh tune SEARCH_S FINAL_S TASK ALGO TRIALS` runs a search and its final seeds
# in one job (docs/evaluation.md).
tuned() {  # TASK ALGO TRIALS [SEARCH_STEPS]
    [[ -z $FILTER || "$1 $2" == *$FILTER* ]] || return 0
    "$PY" -m tactile_braille.baselines.sb3 tune "$1" "$2" --trials "$3" --study runs/tune ${4:+--steps "$4"}
    "$PY" -m tactile_braille.baselines.sb3 run "$1" "$2" --study runs/tune --seeds 0 1 2 3 4 --into "$OUT/sb3-tuned"
}
tuned DiscreteArrows-v0 dqn 16
tuned DiscreteAlphabet-v0 dqn 16
tuned DiscreteArrows-v0 qrdqn 16
tuned ContinuousArrows-v0 sac 12 7500
tuned ContinuousArrows-v0 tqc 12 7500
