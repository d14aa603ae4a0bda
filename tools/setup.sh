#!/usr/bin/env bash
# Prepares a Debian/Ubuntu machine to build and run gatetrace, installing what is missing:
#   - a Vulkan driver: when none is installed, Mesa's CPU implementation lavapipe
#     (mesa-vulkan-drivers) is installed with apt-get (through sudo when not root);
#   - a C toolchain (build-essential: cargo needs a linker) and curl;
#   - a Rust toolchain (1.95 or newer), with rustup, when cargo is missing;
#   - for the viewer's test (tools/test.sh): xvfb-run and the X11 libraries a window needs;
#   - for the Python package's tests (tools/test.sh): python3 with venv and pip;
#   - for the job-scheduler test (tools/slurm_test.sh): Slurm (slurm-wlm) and munge.
# tools/render.sh and tools/test.sh source this file, so cargo is on PATH for them afterwards.
# Running it directly does the same installs. Safe to repeat: it does nothing when all is there.

gatetrace_as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi
}

gatetrace_apt_install() {
    echo "setup: installing $* with apt-get" >&2
    if [ -z "${GATETRACE_APT_UPDATED:-}" ]; then
        gatetrace_as_root apt-get update -qq || return 1
        GATETRACE_APT_UPDATED=1
    fi
    gatetrace_as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@" >/dev/null
}

gatetrace_have_vulkan_driver() {
    ldconfig -p 2>/dev/null | grep -q 'libvulkan\.so\.1' || return 1
    [ -n "${VK_DRIVER_FILES:-}${VK_ICD_FILENAMES:-}" ] && return 0
    for dir in /usr/share/vulkan/icd.d /etc/vulkan/icd.d /usr/local/share/vulkan/icd.d; do
        ls "$dir"/*.json >/dev/null 2>&1 && return 0
    done
    return 1
}

gatetrace_setup() {
    if ! gatetrace_have_vulkan_driver; then
        echo "setup: no Vulkan driver found; installing Mesa's lavapipe" >&2
        gatetrace_apt_install mesa-vulkan-drivers libvulkan1 || return 1
    fi
    if ! command -v cc >/dev/null 2>&1; then
        gatetrace_apt_install build-essential || return 1
    fi
    if [ -f "$HOME/.cargo/env" ]; then
        . "$HOME/.cargo/env"
    fi
    if ! command -v cargo >/dev/null 2>&1; then
        command -v curl >/dev/null 2>&1 || gatetrace_apt_install curl ca-certificates || return 1
        echo "setup: no Rust toolchain; installing one with rustup" >&2
        curl --proto '=https' --tlsv1.2 -sSf https://sh.rustup.rs | sh -s -- -y --profile minimal -c rustfmt -c clippy || return 1
        . "$HOME/.cargo/env"
    fi
    # The suite checks formatting and lints: a toolchain without rustfmt or clippy (rustup's
    # minimal profile) gets them.
    if ! cargo fmt --version >/dev/null 2>&1 && command -v rustup >/dev/null 2>&1; then
        rustup component add rustfmt || return 1
    fi
    if ! cargo clippy --version >/dev/null 2>&1 && command -v rustup >/dev/null 2>&1; then
        rustup component add clippy || return 1
    fi
}

# What the viewer needs in a window, and the viewer's test under a virtual X server: xvfb-run
# and the X11 client libraries winit loads at run time.
gatetrace_setup_display() {
    local missing=()
    command -v xvfb-run >/dev/null 2>&1 || missing+=(xvfb xauth)
    local pair
    for pair in libX11.so.6:libx11-6 libX11-xcb.so.1:libx11-xcb1 libXcursor.so.1:libxcursor1 libXrandr.so.2:libxrandr2 \
                libXi.so.6:libxi6 libxkbcommon-x11.so.0:libxkbcommon-x11-0; do
        ldconfig -p 2>/dev/null | grep -q "${pair%%:*}" || missing+=("${pair#*:}")
    done
    if [ ${#missing[@]} -gt 0 ]; then
        gatetrace_apt_install "${missing[@]}" || return 1
    fi
}

# The Python package's tests (tools/test.sh): python3 with venv (and pip) support, to build and
# install the package into a virtual environment.
gatetrace_setup_python() {
    local missing=()
    command -v python3 >/dev/null 2>&1 || missing+=(python3)
    python3 -c 'import ensurepip, venv' >/dev/null 2>&1 || missing+=(python3-venv python3-pip)
    if [ ${#missing[@]} -gt 0 ]; then
        gatetrace_apt_install "${missing[@]}" || return 1
    fi
}

# The job-scheduler test (tools/slurm_test.sh): Slurm's daemons and commands, and munge.
gatetrace_setup_slurm() {
    if ! command -v slurmctld >/dev/null 2>&1 || ! command -v munged >/dev/null 2>&1; then
        gatetrace_apt_install slurm-wlm munge || return 1
    fi
}

if [ "${BASH_SOURCE[0]}" = "$0" ]; then
    set -euo pipefail
    gatetrace_setup
fi
