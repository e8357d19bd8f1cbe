#!/usr/bin/env bash
# CI: build the wheel, install it into a clean virtual environment, and fly the default mission
# from an empty directory with the `swarmbox` console command (no source tree on the path).
# PYTHON (default python3) builds the wheel.
set -euo pipefail
PYTHON=${PYTHON:-python3}
repo="$(cd "$(dirname "$0")/.." && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
"$PYTHON" -m pip wheel --quiet --disable-pip-version-check --no-deps -w "$work/dist" "$repo"
python3 -m venv "$work/venv"
"$work/venv/bin/pip" install --quiet --disable-pip-version-check "$work"/dist/swarmbox-*.whl
mkdir "$work/empty"
cd "$work/empty"
env -u PYTHONPATH "$work/venv/bin/swarmbox" run
env -u PYTHONPATH "$work/venv/bin/python" -c "import json, pathlib, sys
runs = list(pathlib.Path('results/runs').glob('*/run.json'))
status = json.loads(runs[0].read_text())['status'] if len(runs) == 1 else 'missing'
print('wheel run:', status); sys.exit(status != 'ok')"
env -u PYTHONPATH "$work/venv/bin/swarmbox" analyze results/runs/* --no-figures > /dev/null
# A user project (docs/user-projects.md) in its own folder, against the installed wheel: one command.
mkdir "$work/my_project"
cd "$work/my_project"
env -u PYTHONPATH "$work/venv/bin/python" - "$repo/docs/user-projects.md" <<'PY'
import pathlib, re, sys
doc = pathlib.Path(sys.argv[1]).read_text()
for path, body in re.findall(r"```(?:python|yaml)\n# (\S+)\n(.*?)```", doc, flags=re.S):
    pathlib.Path(path).parent.mkdir(parents=True, exist_ok=True)
    pathlib.Path(path).write_text(body)
pathlib.Path("my_lab/__init__.py").write_text("")
PY
env -u PYTHONPATH "$work/venv/bin/swarmbox" run --config-dir conf algo=flock run.out_dir=out
grep -q '"status": "ok"' out/run.json
echo "wheel OK: clean venv, default mission from an empty directory, a user project with one command"
