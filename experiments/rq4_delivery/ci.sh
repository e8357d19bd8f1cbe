#!/usr/bin/env bash
# CI-sized RQ4 regression gate: the nine delivery algorithms x 2 seeds on 15 packages
# (conf/experiment/rq4_delivery_ci.yaml), analyzed, then compared metric by metric with the
# committed baseline results/baselines/rq4_ci/summary.csv. The simulator is deterministic, so every
# mission metric must equal the baseline to float noise (tolerances.yaml); wall time and real-time
# factor are not gated. Exit 0: no change; 1: a metric moved (worse, or better: an improvement the
# baseline does not record yet); 2: bad input; anything else: the sweep or the analysis failed.
#
#   experiments/rq4_delivery/ci.sh                    # check
#   experiments/rq4_delivery/ci.sh --update-baseline  # after an intended change: rewrite the baseline
set -euo pipefail
cd "$(dirname "$0")/../.."
BASELINE=results/baselines/rq4_ci
PYTHON=${PYTHON:-python3}
work=$(mktemp -d "${TMPDIR:-/tmp}/rq4_ci.XXXXXX")
trap 'rm -rf "$work"' EXIT

"$PYTHON" -m swarmbox.run -m +experiment=rq4_delivery_ci "~hydra.callbacks.analyze" "hydra.sweep.dir=$work/sweep" \
  >"$work/sweep.log" 2>&1 \
  || { tail -n 40 "$work/sweep.log"; echo "rq4 ci: the sweep failed" >&2; exit 3; }
tail -n 1 "$work/sweep.log"
"$PYTHON" -m swarmbox.analyze "$work/sweep" --no-figures --n-boot 200 >"$work/analyze.log" 2>&1 \
  || { tail -n 40 "$work/analyze.log"; echo "rq4 ci: the analysis failed" >&2; exit 3; }

if [[ "${1:-}" == "--update-baseline" ]]; then
  cp "$work/sweep/tables/summary.csv" "$BASELINE/summary.csv"
  echo "baseline updated: $BASELINE/summary.csv"
  exit 0
fi
"$PYTHON" -m swarmbox.compare "$BASELINE/summary.csv" "$work/sweep/tables/summary.csv" \
  --config "$BASELINE/tolerances.yaml"
# compare passes an improvement; on a deterministic simulator it is still a moved number
"$PYTHON" - "$BASELINE" "$work/sweep/tables/summary.csv" <<'PY'
import sys
from pathlib import Path
from swarmbox.analysis.compare import compare, load_config, load_summary
base = Path(sys.argv[1])
verdicts = compare(load_summary(base / "summary.csv"), load_summary(Path(sys.argv[2])),
                   load_config(base / "tolerances.yaml"))
better = verdicts[verdicts["verdict"] == "better"]
if len(better):
    print(better.to_string(index=False))
    print(f"rq4 ci: {len(better)} metric(s) improved: regenerate the baseline (--update-baseline) in this "
          "commit and say in experiments/rq4_delivery/README.md what moved and why", file=sys.stderr)
    sys.exit(1)
PY
