#!/usr/bin/env bash
# Makes offscreen OpenGL available for `gttdata preview`: Mesa's EGL (llvmpipe, CPU) and OSMesa as a fallback.
# Debian's Mesa packages are usually present already; install them when missing and we are root.
set -uo pipefail
need=()
for p in libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1 libosmesa6; do
  dpkg -s "$p" >/dev/null 2>&1 || need+=("$p")
done
if [ ${#need[@]} -eq 0 ]; then
  echo "gl_deps: Mesa EGL/OSMesa present"
  exit 0
fi
if [ "$(id -u)" -ne 0 ]; then
  echo "gl_deps: missing ${need[*]} and not root; 3D preview tests will skip" >&2
  exit 0
fi
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq && apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null \
  && echo "gl_deps: installed ${need[*]}"
