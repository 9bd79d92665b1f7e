#!/bin/bash
# The second command on that node (2026-11-27): wait up to WAIT seconds for command1.sh's sweep to end, then bring
# back its records (records.tgz: the archive of the trials that finished, and the sweep's log), its
# epochs.tsv, every trial's progress.csv (progress.tgz) and the GPU's state half-way (smi.txt).
set -u
W=${WAIT:-590}
pid=$(cat /tmp/g/a.pid)
for ((i = 0; i < W; i++)); do kill -0 "$pid" 2> /dev/null || break; sleep 1; done
echo "waited $i s; sweep $(kill -0 "$pid" 2> /dev/null && echo 'still running' || echo ended); $(( $(date +%s) - $(cat /tmp/g/start) )) s since its start"
cp /tmp/g/a/records.tgz /tmp/g/a/epochs.tsv /tmp/g/smi.txt "$OUT"/ 2> /dev/null
(cd /tmp/g && tar czf "$OUT/progress.tgz" $(ls runs/*/*/progress.csv runs/*/*/typing.json 2> /dev/null) a/sweep.log)
cat /tmp/g/a/epochs.tsv 2> /dev/null; tail -n 3 /tmp/g/a/sweep.log; ls -la "$OUT"
