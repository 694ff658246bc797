#!/usr/bin/env bash
# The main job: shape-completion demo on built-in synthetic data.
# generate -> train -> test best checkpoint -> evaluate from the checkpoint (tables + PNGs).
set -euo pipefail
BIN=${VENV:-.venv}/bin
OUT=${DEMO_DIR:-logs/demo}
EXP=${EXPERIMENT:-completion_demo}  # e.g. EXPERIMENT=completion_cpu DEMO_DIR=logs/completion_cpu
rm -rf "$OUT/train" "$OUT/eval" "$OUT/eval_recgan"
"$BIN/lit3d-data" experiment="$EXP" hydra.run.dir="$OUT/data" --show 8
"$BIN/lit3d-train" experiment="$EXP" hydra.run.dir="$OUT/train" "$@"
CKPT=$(ls "$OUT"/train/checkpoints/best-*.ckpt | head -n 1)
"$BIN/lit3d-eval" task=completion ckpt_path="$CKPT" hydra.run.dir="$OUT/eval"
SAMPLE=../shared/data/recgan_sample
if [ -d "$SAMPLE" ]; then
  # the same checkpoint on the real 3D-RecGAN++ sample (max-pooled to the demo's 64^3 grid)
  "$BIN/lit3d-eval" task=completion ckpt_path="$CKPT" data=recgan data.root="$SAMPLE" hydra.run.dir="$OUT/eval_recgan"
fi
echo
echo "demo done:"
echo "  data preview     $OUT/data/completion_samples.png"
echo "  training run     $OUT/train  (checkpoints/, metrics.json, config.yaml, wandb/)"
echo "  evaluation       $OUT/eval/results.md  $OUT/eval/metrics.json  $OUT/eval/*.png"
[ -d "$OUT/eval_recgan" ] && echo "  real sample      $OUT/eval_recgan/results.md"
cat "$OUT/eval/results.md"
