#!/bin/bash
# (tools/offline_gpu_sweep.sh was named tools/lent_gpu_sweep.sh when this ran)
# The first command on one H200 node without network (2026-11-27): five sweeps side by side (16 cores),
# each through tools/offline_gpu_sweep.sh, then one tarball back.  BUDGET seconds of sweep.
set -u
cd "$(dirname "$0")/../../.."  # the repository root
B=${BUDGET:-470}
S=tools/offline_gpu_sweep.sh
D=${DEV:-cuda}
nvidia-smi -L 2>/dev/null; nproc
python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site_pre .whl/*.whl || exit 3
PYTHONPATH=src:/tmp/site_pre TACTILE_BRAILLE_DATA=$PWD/.data python3 -c "import torch, gymnasium, tactile_braille.cli, tactile_braille.sweep; print('preflight', torch.__version__, torch.cuda.is_available())" || exit 3
sweep() { local name=$1 dev=$2 jobs=$3; shift 3
  mkdir -p "$OUT/$name"
  OUT=$OUT/$name SITE=/tmp/site_$name DEVICE=$dev JOBS=$jobs $S run "$B" "$@" > "$OUT/$name/run.log" 2>&1 &
}
sweep a $D 1 results/table3-v2 --paper --presets released --tasks DiscreteAlphabet-v0 --algos dqn --seeds 4 --root runs/gA
sweep b $D 5 results/table3-v2 --paper --presets released --tasks DiscreteAlphabet-v0 ContinuousArrows-v0 ContinuousAlphabet-v0 --algos sac_discrete sac td3 --seeds 0 --root runs/gB
sweep c $D 2 results/table3 --paper --presets paper --tasks ContinuousAlphabet-v0 --seeds 0 --root runs/gC
sweep d $D 2 gpucheck/$D --paper --presets paper --tasks DiscreteArrows-v0 --seeds 0 --root runs/gD
sweep e cpu 1 gpucheck/cpu --paper --presets paper --tasks DiscreteArrows-v0 --algos dqn --seeds 0 --root runs/gE
( sleep $((B / 2)); nvidia-smi > "$OUT/smi.txt" 2>&1; uptime >> "$OUT/smi.txt" ) &
wait
for n in a b c d e; do echo "== $n"; cat "$OUT/$n/epochs.tsv" 2>/dev/null; tail -n 2 "$OUT/$n/run.log"; done
tar czf "$OUT/all.tgz" -C "$OUT" a b c d e $(ls "$OUT" | grep -q smi.txt && echo smi.txt) && rm -rf "$OUT"/a "$OUT"/b "$OUT"/c "$OUT"/d "$OUT"/e
ls -la "$OUT"
