#!/usr/bin/env bash
# (SWEEP_COMMAND was named COMMAND when this ran)
# (tools/offline_gpu_sweep.sh was named tools/lent_gpu_sweep.sh when this ran)
# The first command on one H200 node without network, 2026-11-27 (carry .whl and .data; 96 s): the
# variant's sweep, started.
set -e
nvidia-smi --query-gpu=name,memory.used --format=csv > "$OUT/smi.txt"
SWEEP_COMMAND=sweep START_WAIT_S=95 PYTHONUNBUFFERED=1 bash tools/offline_gpu_sweep.sh start 650 results/s26-gpu \
    --tasks DiscreteAlphabet-v0 --algos dqn --preset paper --replay.relabel all --agent.batch-size 256 \
    --variant relabel-all_batch256 --seeds 0 1 2 3 4 100 --epochs 40 --precision bf16 --root runs/gpu
nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv >> "$OUT/smi.txt"
