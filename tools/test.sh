#!/usr/bin/env bash
# Installs what is missing (tools/setup.sh) and runs the whole test suite; GPU tests run on the
# Vulkan device (lavapipe when there is no GPU). Extra arguments go to `cargo test`.
set -euo pipefail
cd "$(dirname "$0")/.."
. tools/setup.sh
gatetrace_setup
gatetrace_setup_display
exec cargo test "$@"
