#!/bin/bash
# (tools/offline_gpu_sweep.sh was named tools/lent_gpu_sweep.sh when this ran)
# The first command on one H200 node without network (2026-11-27): install the carried wheels, check, then start one sweep in its own
# process session (it outlives this command) of JOBS trials on CUDA for BUDGET seconds, and return.
# command2.sh, issued at once after, waits for it and brings the records back.
set -u
cd "$(dirname "$0")/../../.."  # the repository root
B=${BUDGET:-600}
nvidia-smi -L 2>/dev/null; nproc
python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site_pre .whl/*.whl || exit 3
PYTHONPATH=src:/tmp/site_pre TACTILE_BRAILLE_DATA=$PWD/.data python3 -c "import torch, gymnasium, tactile_braille.cli; print('preflight', torch.__version__, torch.cuda.is_available())" || exit 3
mkdir -p /tmp/g/a
date +%s > /tmp/g/start
OUT=/tmp/g/a SITE=/tmp/site_a DEVICE=cuda JOBS=${JOBS:-3} setsid nohup bash tools/offline_gpu_sweep.sh run "$B" /tmp/g/archive \
    --paper --presets released --tasks ContinuousArrows-v0 --algos td3 --seeds ${SEEDS:-0 1 2} --root /tmp/g/runs \
    > /tmp/g/a/run.log 2>&1 < /dev/null &
echo $! > /tmp/g/a.pid
setsid nohup bash -c 'sleep 240; nvidia-smi > /tmp/g/smi.txt 2>&1; uptime >> /tmp/g/smi.txt' > /dev/null 2>&1 < /dev/null &
sleep 25
tail -c 1500 /tmp/g/a/sweep.log; ls /tmp/g/runs/*/ 2>/dev/null
