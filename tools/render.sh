#!/usr/bin/env bash
# Installs what is missing (tools/setup.sh), builds gatetrace in release mode and runs
# `gatetrace render` with the given arguments, e.g. tools/render.sh --out cornell_box.exr
set -euo pipefail
cd "$(dirname "$0")/.."
. tools/setup.sh
gatetrace_setup
exec cargo run --release -- render "$@"
