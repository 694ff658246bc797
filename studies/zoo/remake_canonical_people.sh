#!/usr/bin/env bash
# Remakes the zoo's canonical-people model (docs/models.md): Anny data, stage 1 (12 epochs), stage 2
# (8 identity epochs from stage 1's best net), then the FAUST evaluation when ../shared/data/faust_a is there.
#   OUT=logs/zoo_people SEED=42 bash studies/zoo/remake_canonical_people.sh
# On 2 cores (one thread): about 1 h 40 min of training.
set -euo pipefail
BIN=${VENV:-.venv}/bin
OUT=${OUT:-logs/zoo_people}
SEED=${SEED:-42}
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
mkdir -p "$OUT"
"$BIN/lit3d-data" experiment=canonical_people hydra.run.dir="$OUT/data" --show 16 > "$OUT/data_summary.json"
"$BIN/lit3d-train" experiment=canonical_people seed="$SEED" logger=csv hydra.run.dir="$OUT/stage1" "$@"
STAGE1=$(ls "$OUT"/stage1/checkpoints/best-*.ckpt | head -n 1)
"$BIN/lit3d-train" experiment=canonical_people_identity seed="$SEED" logger=csv task.init_weights="$STAGE1" \
  hydra.run.dir="$OUT/stage2" "$@"
CKPT=$(ls "$OUT"/stage2/checkpoints/best-*.ckpt | head -n 1)
echo "canonical-people checkpoint: $CKPT"
FAUST=../shared/data/faust_a
if [ -d "$FAUST" ]; then
  "$BIN/lit3d-eval" task=canonical ckpt_path="$CKPT" data=faust data.root="$FAUST" hydra.run.dir="$OUT/eval_faust"
fi
