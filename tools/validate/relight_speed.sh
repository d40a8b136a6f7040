#!/usr/bin/env bash
# Relighting speed against error: compresses one raw store in 2d, 4d and
# adaptive mode at the same decoded-matrix error, computes the exact image
# T·L, and relights each file at several N, printing a markdown table
# (median frame time over FRAMES frames, its split, nonzeros/s, relit error).
#   tools/validate/relight_speed.sh RAW ENV.exr [MAX_ERROR] [BITS] [WEIGHTING]
set -euo pipefail
raw=$1 env=$2 target=${3:-0.01} bits=${4:-12} weighting=${5:-transport}
ltm=${LTM:-target/release/ltm}
frames=${FRAMES:-21}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$ltm" reference "$raw" --env "$env" -o "$tmp/ref.exr" 2>/dev/null
for mode in 2d 4d adaptive; do
  "$ltm" compress "$raw" -o "$tmp/$mode.ltm" --mode "$mode" --bits "$bits" --max-error "$target" 2>&1 | grep -E "^wrote|warning" >&2
done
echo "| mode | N | frame ms | transform | select | multiply | inverse | nonzeros | G nnz/s | relit error |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for n in 10 50 100 200 500 1000 2000; do
  for mode in 2d 4d adaptive; do
    "$ltm" relight "$tmp/$mode.ltm" --env "$env" --terms "$n" --weighting "$weighting" -o "$tmp/out.exr" \
      --frames "$frames" --reference "$tmp/ref.exr" --json 2>/dev/null | python3 -c "
import json, sys
d = json.loads(sys.stdin.read())
rate = d['nonzeros'] / d['multiply_ms'] / 1e6 if d['multiply_ms'] > 0 else 0
print(f\"| $mode | $n | {d['frame_ms']:.2f} | {d['light_transform_ms']:.3f} | {d['selection_ms']:.3f} | {d['multiply_ms']:.2f} | {d['inverse_ms']:.3f} | {d['nonzeros']} | {rate:.2f} | {d['relative_error']:.5f} |\")"
  done
done
