#!/usr/bin/env bash
# The main job end to end on the embedded default (procedural motion).
set -euo pipefail
gttdata generate recipes/gttdata/default.yaml
