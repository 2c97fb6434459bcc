#!/usr/bin/env bash
# The test command of the README, on a fresh Debian machine: bash tests/run.sh [PYTEST ARGS...]
# (the fast subset, under a minute: bash tests/run.sh -m "not slow"; markers in pyproject.toml)
#
# 1. Installs the Debian packages the tests need, if missing (dpkg -s): libtbb12 (Intel TBB's
#    runtime, libtbb.so.12, for Ecos: ecospy and the ecos program), wine64 (runs the native
#    FMUs' Windows binaries), qemu-user and libc6-arm64-cross (run their aarch64 Linux binaries
#    under qemu-aarch64 with the arm64 C library as sysroot), libminizip1 and libxml2 (the
#    third-party FMI tools in ../shared/tools: fmusim, OMSimulator), clang and libclang-rt-14-dev
#    (libFuzzer, AddressSanitizer and UndefinedBehaviorSanitizer for the native FMUs' fuzz
#    targets and sanitizer builds; TAPMP_FUZZ_SECONDS sets the seconds per fuzz target,
#    default 60), chromium (renders the documentation inside the native FMUs headless), and python3-dev if this Python has no C headers (Python.h, for the pythonfmu
#    FMUs' binary). The FMUs' binaries need no system compiler: zig cc from PyPI's ziglang
#    package builds them for every platform. As root directly, else through sudo;
#    `apt-get update` only if installing fails (empty or stale package lists).
# 2. Creates .venv with the package and its test extras and runs every test with pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
export DEBIAN_FRONTEND=noninteractive
PACKAGES=(libtbb12 wine64 qemu-user libc6-arm64-cross libminizip1 libxml2 clang libclang-rt-14-dev chromium)

missing=()
for package in "${PACKAGES[@]}"; do
    dpkg -s "$package" >/dev/null 2>&1 || missing+=("$package")
done
headers=$(python3 -c 'import sysconfig; print(sysconfig.get_paths()["include"])')
[ -f "$headers/Python.h" ] || missing+=(python3-dev)

as_root() {
    if [ "$(id -u)" -eq 0 ]; then
        "$@"
    else
        sudo DEBIAN_FRONTEND=noninteractive "$@"
    fi
}

if [ "${#missing[@]}" -gt 0 ]; then
    if [ "$(id -u)" -ne 0 ] && ! command -v sudo >/dev/null 2>&1; then
        echo "tests/run.sh: the Debian packages ${missing[*]} are missing and this user is not root and has no sudo: install them as root (apt-get install ${missing[*]}) and run this again" >&2
        exit 1
    fi
    as_root apt-get install -y "${missing[@]}" \
        || { as_root apt-get update && as_root apt-get install -y "${missing[@]}"; }
fi

python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && exec .venv/bin/python -m pytest -q "$@"
