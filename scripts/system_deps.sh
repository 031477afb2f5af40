#!/usr/bin/env bash
# System packages the tests and previews use: the Debian mocap clips and an EGL/OSMesa GL stack.
# Needs apt; on a system without it, the dependent tests skip with a reason.
set -uo pipefail
if ! command -v apt-get >/dev/null 2>&1; then
  echo "system_deps: apt-get not found; mocap and GL tests will skip" >&2
  exit 0
fi
# A fresh machine may have no package lists yet; `apt-get download` needs them (refreshing needs root).
if [ "$(id -u)" -eq 0 ] && [ -z "$(ls -A /var/lib/apt/lists 2>/dev/null | grep -v -e '^lock$' -e '^partial$' -e '^auxfiles$')" ]; then
  apt-get update -qq || echo "system_deps: apt-get update failed" >&2
fi
gttdata motions fetch || echo "system_deps: 'gttdata motions fetch' failed; mocap tests will skip" >&2
if [ -x scripts/gl_deps.sh ]; then
  bash scripts/gl_deps.sh || echo "system_deps: GL stack unavailable; 3D preview tests will skip" >&2
fi
