#!/usr/bin/env bash
# Set up beacon-sim on a fresh Debian machine: a libLLVM >= 16 for Mitsuba's fast CPU
# backend (installed with apt-get when missing), a Python 3.11 virtual environment in
# .venv, and the project with its dependencies. Safe to run again: each step checks
# first and does nothing when already done.
set -euo pipefail
cd "$(dirname "$0")/.."

have_llvm() {
    # libLLVM 16 or newer anywhere the variant selector looks (scenes/mitsuba_variant.py).
    local f v
    for f in /usr/lib/x86_64-linux-gnu/libLLVM*.so* /usr/lib/aarch64-linux-gnu/libLLVM*.so* \
             /usr/lib/llvm-*/lib/libLLVM*.so*; do
        [ -e "$f" ] || continue
        v=$(basename "$f" | grep -oE '[0-9]+' | head -n1)
        [ -n "$v" ] && [ "$v" -ge 16 ] && return 0
    done
    return 1
}

if ! have_llvm; then
    if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null; then
        echo "setup: no libLLVM >= 16 found; installing libllvm19 with apt-get"
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq
        apt-get install -y -qq libllvm19 >/dev/null
    else
        echo "setup: no libLLVM >= 16 and no root apt-get; Mitsuba will use its slow scalar variants"
    fi
fi

# Headless Chromium for the report tests (opened through Playwright, no browser download).
if ! command -v chromium >/dev/null && [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null; then
    echo "setup: installing Debian's chromium for the report tests"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq chromium >/dev/null
fi

PY=${PYTHON:-}
if [ -z "$PY" ]; then
    for c in python3.11 python3; do
        if command -v "$c" >/dev/null && "$c" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
            PY=$c; break
        fi
    done
fi
if [ -z "$PY" ]; then
    echo "setup: Python 3.11 not found; installing it with apt-get"
    apt-get update -qq && apt-get install -y -qq python3.11 python3.11-venv >/dev/null
    PY=python3.11
fi
if ! "$PY" -c 'import venv, ensurepip' 2>/dev/null; then
    apt-get update -qq && apt-get install -y -qq python3-venv >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
    "$PY" -m venv .venv
fi
# The stamp holds a hash of pyproject.toml as installed: a changed dependency list is
# installed even where the file's modification time is older than the stamp (a tree laid
# with preserved times, a branch switched back), and an unchanged one is not reinstalled.
stamp=.venv/.beacon-sim-installed
want=$(sha256sum pyproject.toml | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
    .venv/bin/python -m pip install -q --upgrade pip
    .venv/bin/python -m pip install -q -e '.[dev]'
    echo "$want" > "$stamp"
fi
echo "setup: ready (.venv, $(.venv/bin/python --version))"
