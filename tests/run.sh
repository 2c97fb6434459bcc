#!/usr/bin/env bash
# The test command of the README, on a fresh Debian machine: bash tests/run.sh [PYTEST ARGS...]
# (the fast subset, about 40 seconds on two workers: bash tests/run.sh -m "not slow"; markers in pyproject.toml)
#
# 1. Installs the Debian packages the tests need, if missing (dpkg -s): libtbb12 (Intel TBB's
#    runtime, libtbb.so.12, for Ecos: ecospy and the ecos program), wine64 (runs the native
#    FMUs' Windows binaries), qemu-user and libc6-arm64-cross (run their aarch64 Linux binaries
#    under qemu-aarch64 with the arm64 C library as sysroot), libminizip1 and libxml2 (the
#    third-party FMI tools in ../shared/tools: fmusim, OMSimulator), clang and libclang-rt-14-dev
#    (libFuzzer, AddressSanitizer and UndefinedBehaviorSanitizer for the native FMUs' fuzz
#    targets and sanitizer builds; TAPMP_FUZZ_SECONDS sets the seconds per fuzz target,
#    default 30), chromium (renders the documentation inside the native FMUs headless: one slow
#    test, so not for a run whose arguments say "not slow"), and python3-dev if this Python has
#    no C headers (Python.h, for the pythonfmu FMUs' binary). The FMUs' binaries need no system
#    compiler: zig cc from PyPI's ziglang package builds them for every platform. As root
#    directly, else through sudo; `apt-get update` only if installing fails (empty or stale
#    package lists). The README lists the packages with their download sizes.
# 2. Creates .venv with the package and its test extras and runs every test with pytest, on one
#    pytest-xdist worker per CPU (at most 4).
# Each setup step prints a line when it starts, one every TAPMP_HEARTBEAT_S seconds (default 20)
# while it runs and one with its time when it ends.
set -euo pipefail
cd "$(dirname "$0")/.."
export DEBIAN_FRONTEND=noninteractive
PACKAGES=(libtbb12 wine64 qemu-user libc6-arm64-cross libminizip1 libxml2 clang libclang-rt-14-dev)
# chromium is for one slow test (tests/fmu/test_fmu_documentation.py): not for the fast subset
case " $* " in *"not slow"*) ;; *) PACKAGES+=(chromium) ;; esac
HEARTBEAT_S=${TAPMP_HEARTBEAT_S:-20}

step() {  # step DESCRIPTION COMMAND...: runs COMMAND, saying so before, every HEARTBEAT_S s and after
    local what=$1 start=$SECONDS beat rc=0
    shift
    echo "tests/run.sh: $what" >&2
    # sleep holds no pipe of ours: once the loop is killed, nothing of it keeps the output open
    ( while sleep "$HEARTBEAT_S" </dev/null >/dev/null 2>&1; do echo "tests/run.sh: $what (still running, $((SECONDS - start)) s)" >&2; done ) &
    beat=$!
    "$@" || rc=$?
    kill "$beat" 2>/dev/null || true
    wait "$beat" 2>/dev/null || true
    [ "$rc" -ne 0 ] || echo "tests/run.sh: $what: done in $((SECONDS - start)) s" >&2
    return "$rc"
}

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
    install() { as_root apt-get install -y "${missing[@]}"; }
    step "installing the Debian packages ${missing[*]} (apt-get)" install \
        || { step "updating the package lists (apt-get update)" as_root apt-get update \
             && step "installing the Debian packages ${missing[*]} (apt-get, after the update)" install; }
fi

step "creating .venv (python3 -m venv)" python3 -m venv .venv
step "installing the package and its test extras into .venv (pip install -e '.[test]': about 250 MB of wheels the first time)" \
    .venv/bin/pip install -e '.[test]'
# pytest-xdist workers, one per CPU this process may use (nproc), at most 4 (TAPMP_TEST_WORKERS
# to choose; 0 runs every test in this process); each test file runs whole on one worker, so a
# module's fixtures are set up once (--dist loadfile); the FMUs are built once for every worker
# (tests/conftest.py). Arguments given here come after, so `-n 0` wins.
cpus=$(nproc)
workers=${TAPMP_TEST_WORKERS:-$((cpus < 4 ? cpus : 4))}
echo "tests/run.sh: running the tests (pytest -q -n $workers --dist loadfile $*)" >&2
exec .venv/bin/python -m pytest -q -n "$workers" --dist loadfile "$@"
