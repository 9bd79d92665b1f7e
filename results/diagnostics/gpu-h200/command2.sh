#!/bin/bash
# (tools/offline_gpu_sweep.sh was named tools/lent_gpu_sweep.sh when this ran)
# The second command on that node (2026-11-27): uncontended seconds an epoch, one trial on the GPU and one on the CPU.
set -u
cd "$(dirname "$0")/../../.."  # the repository root
B=${BUDGET:-120}
S=tools/offline_gpu_sweep.sh
sweep() { local name=$1 dev=$2; shift 2
  mkdir -p "$OUT/$name"
  OUT=$OUT/$name SITE=/tmp/site_$name DEVICE=$dev JOBS=1 $S run "$B" "$@" > "$OUT/$name/run.log" 2>&1 &
}
sweep f cuda gpucheck/alone --paper --presets released --tasks DiscreteAlphabet-v0 --algos sac_discrete --seeds 0 --root runs/gF
sweep g cpu gpucheck/alone-cpu --paper --presets paper --tasks DiscreteArrows-v0 --algos dqn --seeds 0 --root runs/gG
wait
for n in f g; do echo "== $n"; cat "$OUT/$n/epochs.tsv"; done
tar czf "$OUT/all2.tgz" -C "$OUT" f g && rm -rf "$OUT"/f "$OUT"/g
