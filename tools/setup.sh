#!/usr/bin/env bash
# Prepares a Debian/Ubuntu machine to build and run gatetrace:
#   - a Vulkan driver: when none is installed, Mesa's CPU implementation lavapipe
#     (package mesa-vulkan-drivers) is installed with apt-get (through sudo when not root);
#   - a Rust toolchain (1.95 or newer): checked, and installed with rustup when missing.
# Safe to run repeatedly; it does nothing when everything is present.
set -euo pipefail

as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi
}

have_vulkan_driver() {
    ldconfig -p 2>/dev/null | grep -q 'libvulkan\.so\.1' || return 1
    for dir in /usr/share/vulkan/icd.d /etc/vulkan/icd.d /usr/local/share/vulkan/icd.d; do
        ls "$dir"/*.json >/dev/null 2>&1 && return 0
    done
    [ -n "${VK_DRIVER_FILES:-}${VK_ICD_FILENAMES:-}" ]
}

if ! have_vulkan_driver; then
    echo "setup: no Vulkan driver found; installing Mesa lavapipe (mesa-vulkan-drivers)" >&2
    as_root apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq mesa-vulkan-drivers libvulkan1 >/dev/null
fi

if ! command -v cargo >/dev/null 2>&1; then
    if [ -x "$HOME/.cargo/bin/cargo" ]; then
        echo "setup: cargo is in ~/.cargo/bin; add it to PATH (source ~/.cargo/env)" >&2
    else
        echo "setup: no Rust toolchain; installing one with rustup" >&2
        curl --proto '=https' --tlsv1.2 -sSf https://sh.rustup.rs | sh -s -- -y --profile minimal
        echo "setup: Rust installed; run \`source ~/.cargo/env\` (or open a new shell) and repeat the command" >&2
    fi
    exit 1
fi
