#!/usr/bin/env bash
# Shape completion in the 3D-RecGAN++ geometry: real Sweet Home 3D furniture for the seen categories when
# the catalogues are installed (the bootstrap installs them), else procedural shapes (said in one line):
# generate -> train -> evaluate the best checkpoint from its file (tables + PNGs).
#   EXPERIMENT=completion_cpu DEMO_DIR=logs/completion_cpu bash scripts/demo_completion.sh   (the longer CPU run)
#   COMPLETION_SOURCE=synth|sweethome3d  (default auto: sweethome3d when installed)
set -euo pipefail
BIN=${VENV:-.venv}/bin
OUT=${DEMO_DIR:-logs/demo}
EXP=${EXPERIMENT:-completion_demo}
SOURCE=${COMPLETION_SOURCE:-auto}
CATALOGUES=/usr/share/sweethome3d/furniture
if [ "$SOURCE" = auto ]; then
  if compgen -G "$CATALOGUES/*.sh3f" >/dev/null; then SOURCE=sweethome3d; else
    SOURCE=synth
    echo "note: no Sweet Home 3D furniture in $CATALOGUES (apt-get install sweethome3d-furniture): completion uses procedural shapes"
  fi
fi
DATA=(data.source="$SOURCE" "data.data_dir=\${paths.data_dir}/${EXP}_$SOURCE")
rm -rf "$OUT/train" "$OUT/eval" "$OUT/eval_recgan"
mkdir -p "$OUT"
"$BIN/lit3d-data" experiment="$EXP" "${DATA[@]}" data.prepare.workers=2 hydra.run.dir="$OUT/data" --show 8 > "$OUT/data_summary.json"
# test_after_fit=false: lit3d-eval below tests the same best checkpoint from its file (once, not twice)
"$BIN/lit3d-train" experiment="$EXP" "${DATA[@]}" hydra.run.dir="$OUT/train" test_after_fit=false "$@"
CKPT=$(ls "$OUT"/train/checkpoints/best-*.ckpt | head -n 1)
"$BIN/lit3d-eval" task=completion ckpt_path="$CKPT" hydra.run.dir="$OUT/eval"
SAMPLE=../shared/data/recgan_sample
if [ -d "$SAMPLE" ]; then
  # the same checkpoint on the real 3D-RecGAN++ sample (max-pooled to the demo's 64^3 grid)
  "$BIN/lit3d-eval" task=completion ckpt_path="$CKPT" data=recgan data.root="$SAMPLE" hydra.run.dir="$OUT/eval_recgan"
fi
HEADLINE=$("$BIN/python" - "$OUT/eval/metrics.json" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))
print("; ".join(f"{s} {m[f'test/{s}/iou']:.3f} (input {m[f'test/{s}/iou_input']:.3f})"
                for s in ("same", "cross", "unseen") if f"test/{s}/iou" in m))
PY
)
{
  echo "completion (shape completion from one depth view; test IoU: $HEADLINE)"
  echo "  data preview     $OUT/data/completion_samples.png   (counts: $OUT/data_summary.json)"
  echo "  training run     $OUT/train   (checkpoints/, curves.png, config.yaml, wandb/)"
  echo "  evaluation       $OUT/eval/results.md  $OUT/eval/metrics.json"
  echo "  figures          $(ls "$OUT"/eval/*.png | tr '\n' ' ')"
  if [ -d "$OUT/eval_recgan" ]; then echo "  real sample      $OUT/eval_recgan/results.md  (3D-RecGAN++ sample, same checkpoint)"; fi
} > "$OUT/summary_completion.txt"
cat "$OUT/summary_completion.txt"
