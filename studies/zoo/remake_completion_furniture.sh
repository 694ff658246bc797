#!/usr/bin/env bash
# Remakes the zoo's completion-furniture model (docs/models.md): data from the installed catalogues
# (make install unpacks them), training, then the test splits and the real 3D-RecGAN++ sample from the
# best checkpoint.   OUT=logs/zoo_completion SEED=42 bash studies/zoo/remake_completion_furniture.sh
set -euo pipefail
BIN=${VENV:-.venv}/bin
OUT=${OUT:-logs/zoo_completion}
SEED=${SEED:-42}
mkdir -p "$OUT"
"$BIN/lit3d-data" experiment=completion_furniture data.prepare.workers=2 hydra.run.dir="$OUT/data" --show 8 > "$OUT/data_summary.json"
"$BIN/lit3d-train" experiment=completion_furniture seed="$SEED" logger=csv hydra.run.dir="$OUT/train" test_after_fit=false "$@"
CKPT=$(ls "$OUT"/train/checkpoints/best-*.ckpt | head -n 1)
echo "completion-furniture checkpoint: $CKPT"
"$BIN/lit3d-eval" task=completion ckpt_path="$CKPT" hydra.run.dir="$OUT/eval"
SAMPLE=../shared/data/recgan_sample
if [ -d "$SAMPLE" ]; then
  "$BIN/lit3d-eval" task=completion ckpt_path="$CKPT" data=recgan data.root="$SAMPLE" hydra.run.dir="$OUT/eval_recgan"
fi
