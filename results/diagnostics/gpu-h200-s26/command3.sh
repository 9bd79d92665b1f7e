#!/usr/bin/env bash
# (SWEEP_COMMAND was named COMMAND when this ran)
# (tools/offline_gpu_sweep.sh was named tools/lent_gpu_sweep.sh when this ran)
# The third command, on a fresh node (carry .whl and .data; 221 s): the control, the
# same recipe with the paper's batch of 32 on CUDA, seeds 0 and 100.
SWEEP_COMMAND=sweep bash tools/offline_gpu_sweep.sh run 235 results/s26-gpu-control --tasks DiscreteAlphabet-v0 \
    --algos dqn --preset paper --replay.relabel all --variant relabel-all_cuda --seeds 0 100 --epochs 40 \
    --precision bf16 --root runs/gpuc
(cd runs/gpuc && tar czf "$OUT/progress.tgz" $(find . -name progress.csv))
