#!/usr/bin/env bash
# CI's real-PX4 job: the px4 bridge against PX4 SITL (SIH) instances, when a build is there
# (../shared/px4-sitl next to the clone, or $SWARMBOX_PX4_BUILD). The bridge's conformance checks,
# the real-PX4 scenarios (slow ones included: the general slow step leaves this file to this job, where
# a missing build fails instead of skipping) and a 4-drone formation run at PX4_SIM_SPEED (default 2) x real time.
# A bridge that breaks (a wrong type mask, frame or command) fails here: the vehicles do not follow.
# PYTHON (default python3): the environment with SwarmBox and its test extra.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON=${PYTHON:-python3}
build="${SWARMBOX_PX4_BUILD:-../shared/px4-sitl}"
if [ ! -x "$build/bin/px4" ] && [ ! -x "$build/build/px4_sitl_default/bin/px4" ]; then
    echo "px4: no PX4 SITL build at $build: real-PX4 job skipped"
    exit 0
fi
export SWARMBOX_PX4_BUILD="$(cd "$build" && pwd)"
export SWARMBOX_REQUIRE_PX4=1           # a test that cannot find PX4 fails instead of skipping
export PX4_SIM_SPEED="${PX4_SIM_SPEED:-2}"
echo "px4: $SWARMBOX_PX4_BUILD at ${PX4_SIM_SPEED}x; load average: $(cut -d' ' -f1-3 /proc/loadavg)"
"$PYTHON" -m pytest -p no:cacheprovider -m "slow or not slow" tests/hal/test_px4_real.py tests/hal/test_px4_sitl.py \
    tests/hal/test_px4_bridge.py tests/hal/test_px4_codec.py
