#!/usr/bin/env bash
# CI's README job: the two commands of README.md's "Two commands" section, verbatim (extracted by
# .ci/readme_commands.py, so a README edit changes what CI runs), in a fresh virtual environment
# activated as a user would, from the clone's root.
#
#   .ci/readme.sh [CLONE [VENV]]   # defaults: this clone; a temporary venv removed at the end
#
# Fails when the block is missing, a command fails, or a pytest command passes no test.
set -euo pipefail
ci="$(cd "$(dirname "$0")" && pwd)"
source "$ci/lib.sh"
clone="$(cd "${1:-$ci/..}" && pwd)"
if [ -n "${2:-}" ]; then
  venv="$2"
else
  venv="$(mktemp -d "${TMPDIR:-/tmp}/swarmbox-readme.XXXXXX")/venv"
  trap 'rm -rf "$(dirname "$venv")"' EXIT
fi
commands="$(python3 "$ci/readme_commands.py" "$clone/README.md")"   # exit 2 without the block
fresh_venv "$venv"
source "$venv/bin/activate"
cd "$clone"
log="$(dirname "$venv")/readme-command.log"
while IFS= read -r command; do
  step "README: $command"
  started=$SECONDS
  bash -o pipefail -c "$command" < /dev/null 2>&1 | tee "$log"
  echo "README command took $((SECONDS - started)) s (venv: $(venv_size "$venv"))"
  if [[ "$command" == *pytest* ]] && ! grep -Eq '[0-9]+ passed' "$log"; then
    echo "readme: '$command' passed no test" >&2
    exit 1
  fi
done <<< "$commands"
echo "readme: both commands of README.md passed in a fresh venv"
