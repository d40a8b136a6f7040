#!/usr/bin/env bash
# Size against decoded-matrix error for 2d, 4d and adaptive compression of one
# raw store, over bit depths and target errors. Prints one JSON object per
# line (mode, bits, target, file_bytes, ratio, achieved_error, seconds).
#   tools/validate/size_error.sh RAW [LTM_BINARY]
set -euo pipefail
raw=$1
ltm=${2:-target/release/ltm}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for mode in ${MODES:-2d 4d adaptive}; do
  for bits in 6 8 9 10 12; do
    for target in 0.003 0.01 0.03 0.1; do
      start=$(date +%s.%N)
      "$ltm" compress "$raw" -o "$tmp/x.ltm" --mode "$mode" --bits "$bits" --max-error "$target" 2>/dev/null
      end=$(date +%s.%N)
      "$ltm" inspect "$tmp/x.ltm" --json | python3 -c "
import json, sys
d = json.load(sys.stdin)
print(json.dumps({'mode': '$mode', 'bits': $bits, 'target': $target, 'file_bytes': d['file_bytes'],
  'ratio': round(d['compression_ratio'], 2), 'achieved_error': round(d['achieved_error'], 6),
  'seconds': round($end - $start, 3)}))"
    done
  done
done
