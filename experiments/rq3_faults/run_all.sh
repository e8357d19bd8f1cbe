#!/usr/bin/env bash
# The whole RQ3 experiment on the simulator, one run at a time (resumable):
#   1. the paper's study: 3 faults x 5 magnitudes x 9 target drones (135 runs) -> Tables 2, 4, 5;
#   2. the diagnosis benchmark: 6 fault models around the default detector's floor, 9 and 36 drones,
#      ideal and wifi networks, healthy, composed and swarm-wide runs, calibration and report seeds
#      -> detection rates with intervals, false alarms, held-out tuned settings, ROC.
# Every run is diagnosed without its fault events, then scored against them.
#   experiments/rq3_faults/run_all.sh [OUT_ROOT]
set -euo pipefail
cd "$(dirname "$0")/../.."
root="${1:-results/rq3_faults/$(date +%Y-%m-%d_%H-%M-%S)}"
here=experiments/rq3_faults
for which in rq3 bench; do
  start=$(date +%s)
  nice -n 10 python "${here}/sweep.py" "${which}" "${root}/${which}"
  python "${here}/report.py" "${which}" "${root}/${which}" --out "${root}/${which}_report"
  echo "${which}: $(( $(date +%s) - start )) s wall" | tee -a "${root}/wall_times.txt"
done
