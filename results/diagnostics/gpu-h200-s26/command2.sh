#!/usr/bin/env bash
# Session 26, second device command, issued at once (carry .whl and .data; 357 s): the sweep collected.
bash tools/lent_gpu_sweep.sh collect 565
cp /tmp/lent_gpu_sweep/sweep.log "$OUT/" 2> /dev/null
nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv > "$OUT/smi2.txt"
