#!/usr/bin/env bash
# The leaderboard's rows from other libraries' agents: Stable-Baselines3 with HER on every task and the
# single-file CleanRL-style DQN + HER on the discrete ones, at the budgets below (one CPU thread per run).
# A results file that exists is kept, so a stopped run of this script goes on where it was.
# Usage: examples/baselines.sh [FILTER]   (FILTER: part of a task or algorithm name; SEEDS="0 1 2")
set -euo pipefail
PY=${PY:-.venv/bin/python}
OUT=${OUT:-results/leaderboard}
SEEDS=${SEEDS:-0}
FILTER=${1:-}

run() {  # TASK ALGO ENV_STEPS
    [[ -z $FILTER || "$1 $2" == *$FILTER* ]] || return 0
    for seed in $SEEDS; do
        if [[ $2 == cleanrl ]]; then
            local file="$OUT/cleanrl/$1__dqn_her__$seed.json"
            [[ -f $file ]] || "$PY" examples/cleanrl_dqn_her.py --task "$1" --steps "$3" --seed "$seed" --output "$file"
        else
            local file="$OUT/sb3/$1__$2__$seed.json"
            [[ -f $file ]] || "$PY" examples/sb3_her.py "$1" "$2" --steps "$3" --seed "$seed" --output "$file"
        fi
    done
}

run DiscreteArrows-v0 dqn 6000
run DiscreteArrows-v0 cleanrl 6000
run DiscreteAlphabet-v0 dqn 15000
run DiscreteAlphabet-v0 cleanrl 15000
run ContinuousArrows-v0 sac 4000
run ContinuousArrows-v0 td3 4000
run ContinuousAlphabet-v0 sac 4000
run ContinuousAlphabet-v0 td3 4000
