#!/usr/bin/env bash
# Makes the project's virtualenv (called by the Makefile): make_venv.sh PYTHON DIR.
# PYTHON must be >= 3.11 with the venv module; on Debian/Ubuntu that is the python3-venv package, which is
# installed here when it is missing and we are root (CI), else named in the error.
set -uo pipefail
PY=${1:-python3}
DIR=${2:-.venv}
if ! command -v "$PY" >/dev/null 2>&1; then
  echo "make_venv: $PY not found; install Python >= 3.11 (e.g. apt-get install python3 python3-venv)" >&2
  exit 1
fi
if ! "$PY" -c 'import sys; sys.exit(sys.version_info < (3, 11))'; then
  echo "make_venv: $PY is Python $("$PY" -c 'import platform; print(platform.python_version())'), gtt needs >= 3.11; run make BASE_PYTHON=python3.11 (or newer)" >&2
  exit 1
fi
if ! "$PY" -c 'import ensurepip, venv' >/dev/null 2>&1; then
  pkg="python$("$PY" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')-venv"
  if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "make_venv: installing $pkg (the venv module of $PY)"
    export DEBIAN_FRONTEND=noninteractive
    { apt-get install -y -qq --no-install-recommends "$pkg" || { apt-get update -qq && apt-get install -y -qq --no-install-recommends "$pkg"; }; } >/dev/null
  fi
  if ! "$PY" -c 'import ensurepip, venv' >/dev/null 2>&1; then
    echo "make_venv: $PY has no venv/ensurepip module; install it (Debian/Ubuntu: sudo apt-get install $pkg) or activate a virtualenv of your own and rerun make" >&2
    exit 1
  fi
fi
echo "make_venv: creating $DIR with $PY ($("$PY" -c 'import platform; print(platform.python_version())'))"
if ! "$PY" -m venv "$DIR"; then
  rm -rf "$DIR"  # no half-made venv: the next make starts again
  echo "make_venv: '$PY -m venv $DIR' failed" >&2
  exit 1
fi
