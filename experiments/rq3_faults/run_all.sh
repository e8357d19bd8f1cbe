#!/usr/bin/env bash
# The whole RQ3 experiment: three sweeps of 45 runs (5 magnitudes x 9 target drones) on the
# simulator, two runs at a time, then the diagnosis tables and timeline figures.
#   experiments/rq3_faults/run_all.sh [OUT_ROOT]
set -euo pipefail
cd "$(dirname "$0")/../.."
root="${1:-results/rq3_faults/$(date +%Y-%m-%d_%H-%M-%S)}"
for kind in drift latency loss; do
  start=$(date +%s)
  python -m swarmbox.run -m "+experiment=rq3_${kind}" "hydra.sweep.dir=${root}/${kind}" "~hydra.callbacks.analyze"
  echo "rq3_${kind}: $(( $(date +%s) - start )) s wall" | tee -a "${root}/wall_times.txt"
done
start=$(date +%s)
python -m swarmbox.analysis.faults "${root}/drift" "${root}/latency" "${root}/loss" --out "${root}/report"
echo "analysis: $(( $(date +%s) - start )) s wall" | tee -a "${root}/wall_times.txt"
