#!/usr/bin/env bash
# Throughput regression gate: the tests/bench/test_bench_scale.py benchmarks against the committed
# baseline in tests/bench/baseline/. Loose on purpose (a shared 2-core machine is noisy): a benchmark
# fails only when its fastest round is more than 3x slower than the baseline's fastest round.
#
#   .ci/bench.sh                    # compare (exit 1 on a regression)
#   .ci/bench.sh --update-baseline  # after an intended change: replace the baseline
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
STORAGE=file://tests/bench/baseline
ARGS=(tests/bench/test_bench_scale.py -q -p no:cacheprovider -m slow --benchmark-enable --benchmark-storage="$STORAGE"
      --benchmark-columns=min,mean,max,rounds)
if [[ "${1:-}" == "--update-baseline" ]]; then
  rm -rf tests/bench/baseline
  "$PYTHON" -m pytest "${ARGS[@]}" --benchmark-save=baseline
  exit 0
fi
"$PYTHON" -m pytest "${ARGS[@]}" --benchmark-compare=0001 --benchmark-compare-fail=min:200%
