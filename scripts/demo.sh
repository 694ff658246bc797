#!/usr/bin/env bash
# make demo [TASK=all|completion|quality|canonical]: each task at demo scale on built-in data.
#   completion  scripts/demo_completion.sh  generate -> train -> evaluate the checkpoint   ($DEMO_DIR/{data,train,eval})
#   quality     scripts/demo_quality.sh     one reference, 5 distorted versions, lit3d-score  ($DEMO_DIR/quality)
#   canonical   scripts/demo_canonical.sh   generate -> train -> test + contact sheets       ($DEMO_DIR/canonical)
# DEMO_DIR (default logs/demo) moves every output. Each task writes $DEMO_DIR/summary_<task>.txt;
# the closing summary below lists them all.
set -euo pipefail
TASK=${1:-${TASK:-all}}
export DEMO_DIR=${DEMO_DIR:-logs/demo}
case "$TASK" in
  all) TASKS="completion quality canonical" ;;
  completion|quality|canonical) TASKS=$TASK ;;
  *) echo "make demo: TASK=$TASK: expected all, completion, quality or canonical" >&2; exit 2 ;;
esac
mkdir -p "$DEMO_DIR"
T0=$(date +%s)
for t in $TASKS; do
  echo
  echo "=== demo: $t (scripts/demo_$t.sh) ==="
  s=$(date +%s)
  rm -f "$DEMO_DIR/summary_$t.txt"
  bash "scripts/demo_$t.sh"
  echo "  ($t: $(( $(date +%s) - s )) s)" >> "$DEMO_DIR/summary_$t.txt"
done
echo
echo "=== demo done ($TASKS): $(( $(date +%s) - T0 )) s; outputs ==="
for t in $TASKS; do cat "$DEMO_DIR/summary_$t.txt"; done
