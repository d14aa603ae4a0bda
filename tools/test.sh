#!/usr/bin/env bash
# Installs what is missing (tools/setup.sh) and runs the whole test suite: `cargo fmt --check`
# (the renderer and the Python bindings), `cargo clippy` (warnings denied), `cargo test` (GPU
# tests run on the Vulkan device, lavapipe when there is no GPU; extra arguments go to it, e.g.
# --release), then the Python package's tests: the package is built and installed with
# `pip install .` into a virtual environment in target/python-env (under CARGO_TARGET_DIR when
# set), and pytest runs
# python/tests against it and against the command line built by `cargo test`; last, a 4-task
# Slurm job array of shards and its merge on a single-node cluster (tools/slurm_test.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
. tools/setup.sh
gatetrace_setup
gatetrace_setup_display
gatetrace_setup_python
gatetrace_setup_slurm
# Formatting first (two seconds): the renderer and the Python bindings' crate; then clippy on
# every target of the renderer with warnings denied (the lints turned off, and why, are in
# Cargo.toml's [lints.clippy]).
cargo fmt --check
(cd python && cargo fmt --check)
cargo clippy --all-targets -- -D warnings
cargo test "$@"

profile=debug
maturin_profile=dev
for arg in "$@"; do
    if [ "$arg" = "--release" ]; then profile=release; maturin_profile=release; fi
done
target_dir="${CARGO_TARGET_DIR:-$PWD/target}"
env_dir="$target_dir/python-env"
if [ ! -x "$env_dir/bin/python" ]; then
    python3 -m venv "$env_dir"
fi
# The extension module is built in the profile cargo test just used, so it reuses its build
# of the renderer.
MATURIN_PEP517_ARGS="--profile $maturin_profile" "$env_dir/bin/python" -m pip install --quiet --disable-pip-version-check ".[test]"
GATETRACE_BIN="$target_dir/$profile/gatetrace" "$env_dir/bin/python" -m pytest -q python/tests
tools/slurm_test.sh "$target_dir/$profile/gatetrace"
