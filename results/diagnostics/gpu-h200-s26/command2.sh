#!/usr/bin/env bash
# (tools/offline_gpu_sweep.sh was named tools/lent_gpu_sweep.sh, its state /tmp/lent_gpu_sweep, when this ran)
# The second command on that node, issued at once (carry .whl and .data; 357 s): the sweep collected.
bash tools/offline_gpu_sweep.sh collect 565
cp /tmp/offline_gpu_sweep/sweep.log "$OUT/" 2> /dev/null
nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv > "$OUT/smi2.txt"
