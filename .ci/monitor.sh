#!/usr/bin/env bash
# The live-dashboard test drives a real terminal through tmux: install it when the machine lacks it.
set -euo pipefail
if ! command -v tmux > /dev/null; then
  if [ "$(id -u)" = 0 ]; then SUDO=""; else SUDO="sudo"; fi
  $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq tmux > /dev/null
fi
tmux -V
