#!/usr/bin/env bash
# Shape quality: score a reference mesh against 5 distorted versions of it with lit3d-score
# (renders from 12 views in 4 MatCap styles, image measures, contact sheets), then one table and
# one labelled figure. The reference is QUALITY_REF if set, else ../shared/data/meshes/bunny.obj when
# that exists, else the built-in procedural shape 'bumpy'.
set -euo pipefail
BIN=${VENV:-.venv}/bin
OUT=${DEMO_DIR:-logs/demo}/quality
STYLES=${QUALITY_STYLES:-clay_studio,ceramic_lightbulb,jade,toon}
REF=${QUALITY_REF:-}
if [ -z "$REF" ] && [ -f ../shared/data/meshes/bunny.obj ]; then REF=../shared/data/meshes/bunny.obj; fi
rm -rf "$OUT"
mkdir -p "$OUT/scores"
"$BIN/python" scripts/demo_quality.py prepare "$OUT" ${REF:+--ref "$REF"} > /dev/null
while IFS=$'\t' read -r name path text; do
  [ "$name" = reference ] && continue
  echo "lit3d-score reference.obj $name.obj   ($text)"
  "$BIN/lit3d-score" "$OUT/meshes/reference.obj" "$path" --styles "$STYLES" --json \
    --save-views "$OUT/views/$name" > "$OUT/scores/$name.json"
done < "$OUT/pairs.tsv"
echo "lit3d-score $OUT/meshes/reference.obj $OUT/meshes/noise_strong.obj --styles $STYLES   (its summary; cached)"
"$BIN/lit3d-score" "$OUT/meshes/reference.obj" "$OUT/meshes/noise_strong.obj" --styles "$STYLES" | tee "$OUT/noise_strong_summary.txt"
"$BIN/python" scripts/demo_quality.py report "$OUT" > /dev/null
cat "$OUT/results.md"
{
  echo "quality (rendering-based score of a shape against its reference; 1 = identical)"
  echo "  meshes           $OUT/meshes/  (reference.obj + 5 distorted; list: $OUT/pairs.tsv)"
  echo "  scores           $OUT/results.md  (ranked table)  $OUT/scores/*.json  (every feature, lit3d-score --json)"
  echo "  figure           $OUT/quality_demo.png"
  echo "  contact sheets   $OUT/views/<name>/contact_{flat,smooth}.png"
} > "$(dirname "$OUT")/summary_quality.txt"
cat "$(dirname "$OUT")/summary_quality.txt"
