#!/usr/bin/env bash
# CI's newest-releases job: the newest release of every dependency (within pyproject's bounds), then
# the default tests, so a dependency's new release that breaks SwarmBox fails CI the day it ships.
#
#   .ci/newest.sh          # a fresh venv: pip install --upgrade --upgrade-strategy eager -e '.[test]'
#   .ci/newest.sh VENV     # that venv (CI passes the README job's, fresh this run): the same upgrade;
#                          # the tests run again only if it changed a version (otherwise the README
#                          # job's test run was already the newest releases' run)
set -euo pipefail
ci="$(cd "$(dirname "$0")" && pwd)"
source "$ci/lib.sh"
cd "$ci/.."
if [ -n "${1:-}" ]; then
  venv="$1"
else
  venv="$(mktemp -d "${TMPDIR:-/tmp}/swarmbox-newest.XXXXXX")/venv"
  trap 'rm -rf "$(dirname "$venv")"' EXIT
  fresh_venv "$venv"
fi
before="$("$venv/bin/pip" freeze --exclude-editable 2>/dev/null)"
"$venv/bin/pip" install --quiet --upgrade --upgrade-strategy eager -e '.[test]'
after="$("$venv/bin/pip" freeze --exclude-editable 2>/dev/null)"
echo "newest: $(grep -Ei '^(hydra-core|joblib|cloudpickle|numpy|pandas|pyarrow)==' <<< "$after" | tr '\n' ' ')"
if [ -n "${1:-}" ] && [ "$before" = "$after" ]; then
  echo "newest: no newer release than the README job installed: its test run covered the newest releases"
  exit 0
fi
diff <(echo "$before") <(echo "$after") || true
"$venv/bin/python" -m pytest -p no:cacheprovider -n auto   # as the README runs them
