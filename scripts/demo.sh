#!/usr/bin/env bash
# The main job end to end on the embedded default (procedural motion, no downloads needed):
# generate + verify the default dataset, preview a sample, reconstruct a held-out test capture with
# pseudo-triangulation, DLOE and the bundled GTT-Net under no sequencing, then the smoke evaluation.
set -euo pipefail
DATA=${GTT_DEMO_DATA:-data/gttdata/default}
RUN=${GTT_DEMO_RUN:-runs/demo}
mkdir -p "$RUN"

gttdata generate recipes/gttdata/default.yaml --out "$DATA" --workers 2 --resume --preview 1
gttdata verify "$DATA"
gttdata inspect "$DATA"

test_shard="$DATA/test/shard-00000.h5"
for method in pseudo dloe gttnet; do
  gttnet reconstruct "$test_shard" --sample 0 --method "$method" --sequencing none \
    --out "$RUN/test0_${method}.h5" --overwrite --json | tee "$RUN/test0_${method}.json"
done

gttnet evaluate recipes/gttnet/eval_smoke.yaml --out "$RUN/eval_smoke" --resume
echo "demo finished: dataset in $DATA, reconstructions and evaluation in $RUN"
