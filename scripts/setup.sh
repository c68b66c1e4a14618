#!/usr/bin/env bash
# Set up everything mitsuba-veg needs on a fresh Debian machine:
#   1. a system libLLVM >= 16 (Mitsuba's llvm_* variants abort with "LLVM ERROR: Cannot select"
#      on LLVM 14/15); Debian's libllvm19 is installed when none is found;
#   2. ffmpeg (MP4 animations), when missing and apt is available;
#   3. a virtual environment .venv with the package, its test extras and the Dask extra
#      (sweeps on Dask).
#
#   bash scripts/setup.sh docs   # also the docs extra (Sphinx, MyST, furo, numpydoc, gallery)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}

have_llvm() {
    # any libLLVM with a major version >= 16 known to the dynamic linker or in the usual places
    { ldconfig -p 2>/dev/null | grep -oE 'libLLVM(-|\.so\.)[0-9]+' ;
      ls /usr/lib/*/libLLVM* /usr/lib/llvm-*/lib/libLLVM* 2>/dev/null | grep -oE 'libLLVM(-|\.so\.)[0-9]+' ; } \
      | grep -oE '[0-9]+$' | awk '$1 >= 16 {found=1} END {exit !found}'
}

apt_install() {
    if [ "$(id -u)" -ne 0 ]; then SUDO=sudo; else SUDO=; fi
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "$@"
}

if [ -z "${DRJIT_LIBLLVM_PATH:-}" ] && ! have_llvm; then
    echo "[setup] no libLLVM >= 16 found: installing Debian's libllvm19"
    apt_install libllvm19
fi
if ! command -v ffmpeg >/dev/null 2>&1 && command -v apt-get >/dev/null 2>&1; then
    echo "[setup] installing ffmpeg (MP4 animations)"
    apt_install ffmpeg || echo "[setup] ffmpeg could not be installed: animations fall back to GIF"
fi

if [ ! -x .venv/bin/python ]; then
    echo "[setup] creating .venv"
    "$PY" -m venv .venv
fi
stamp=.venv/.mitsuba-veg-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    echo "[setup] installing mitsuba-veg and its dependencies into .venv"
    .venv/bin/python -m pip install -q --upgrade pip
    .venv/bin/python -m pip install -q -e ".[test,distributed]"
    touch "$stamp"
fi
if [ "${1:-}" = "docs" ]; then
    docs_stamp=.venv/.mitsuba-veg-docs-installed
    if [ ! -f "$docs_stamp" ] || [ pyproject.toml -nt "$docs_stamp" ]; then
        echo "[setup] installing the docs extra into .venv"
        .venv/bin/python -m pip install -q -e ".[test,distributed,docs]"
        touch "$docs_stamp"
    fi
fi
# the package's bytecode, as a regular install compiles it: an editable install leaves the
# sources to be compiled by the first import, and where PYTHONDONTWRITEBYTECODE is set every
# command would compile them again (about half a second a command)
.venv/bin/python -m compileall -q mitsuba_veg integrators >/dev/null
.venv/bin/python -c "import mitsuba_veg as mv; print('[setup] ready:', mv.__version__, mv.variant())"
