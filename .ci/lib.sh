# Sourced by the CI scripts: fresh virtual environments and timed, labelled steps.
# Every environment is new (python3 -m venv: no system or user site-packages); pip's download cache
# is kept, as it only saves downloads.
export PYTHONNOUSERSITE=1
unset PYTHONPATH
CI_START=${CI_START:-$SECONDS}
export CI_START

# step LABEL...: a header with the time since CI started and the machine's load.
step() {
  printf '\n== ci: %s  [%d s; load %s]\n' "$*" $((SECONDS - CI_START)) "$(cut -d' ' -f1-3 /proc/loadavg)"
}

# fresh_venv DIR: a new, empty virtual environment at DIR (whatever was there is removed).
fresh_venv() {
  rm -rf "$1"
  python3 -m venv "$1"
  "$1/bin/python" -c 'import sys; assert sys.prefix != sys.base_prefix, "not a venv"'
}

# venv_size DIR: its size on disk, for the log.
venv_size() {
  du -sh "$1" | cut -f1
}
