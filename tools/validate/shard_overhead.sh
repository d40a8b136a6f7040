#!/usr/bin/env bash
# The cost of sharding on one machine: wall time of a one-machine bake and
# compress of a scene against the same work run as N shards one after
# another (bake --shard + merge; compress --analyze --shard, plan, compress
# --plan --shard per coding, assemble), and a check that both give the same
# raw store and .ltm file byte for byte. The shards share this machine's
# cores, so the ratio measures overhead, not speedup.
#
#   tools/validate/shard_overhead.sh [SCENE] [SIZE] [FACE_RES] [SHARDS]
#
# Defaults: assets/scenes/default.toml 128x96 16 4. LTM names the binary
# (default target/release/ltm). Prints a Markdown table.
set -euo pipefail
cd "$(dirname "$0")/../.."
scene=${1:-assets/scenes/default.toml}
size=${2:-128x96}
face_res=${3:-16}
shards=${4:-4}
ltm=${LTM:-target/release/ltm}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

now() { date +%s.%N; }
# Runs a command quietly; appends its wall seconds to the named variable.
timed() {
    local var=$1 start
    shift
    start=$(now)
    "$@" >"$work/last.out" 2>"$work/last.err" || { cat "$work/last.err" >&2; exit 1; }
    printf -v "$var" '%s' "$(echo "${!var:-0} + $(now) - $start" | bc -l)"
}

bake_args=(--size "$size" --face-res "$face_res")
one_bake=0 one_compress=0 sh_bake=0 sh_merge=0 sh_analyze=0 sh_plan=0 sh_code=0 sh_assemble=0
timed one_bake "$ltm" bake "$scene" "${bake_args[@]}" -o "$work/one.raw"
timed one_compress "$ltm" compress "$work/one.raw" -o "$work/one.ltm"

parts=()
for ((i = 0; i < shards; i++)); do
    timed sh_bake "$ltm" bake "$scene" "${bake_args[@]}" --shard "$i/$shards" -o "$work/part-$i.raw"
    parts+=("$work/part-$i.raw")
done
timed sh_merge "$ltm" merge "${parts[@]}" -o "$work/sharded.raw"
cmp -s "$work/one.raw" "$work/sharded.raw" || { echo "merged store differs" >&2; exit 1; }

analyses=()
for ((i = 0; i < shards; i++)); do
    timed sh_analyze "$ltm" compress "$work/sharded.raw" --analyze --shard "$i/$shards" -o "$work/a-$i.json"
    analyses+=("$work/a-$i.json")
done
coded=()
k=1
while :; do
    timed sh_plan "$ltm" plan "${analyses[@]}" "${coded[@]}" -o "$work/plan-$k.json"
    [ "$(cat "$work/last.out")" = assemble ] && break
    coded=()
    for ((i = 0; i < shards; i++)); do
        timed sh_code "$ltm" compress "$work/sharded.raw" --plan "$work/plan-$k.json" --shard "$i/$shards" -o "$work/c-$k-$i.part"
        coded+=("$work/c-$k-$i.part")
    done
    k=$((k + 1))
done
timed sh_assemble "$ltm" assemble "${coded[@]}" -o "$work/sharded.ltm"
cmp -s "$work/one.ltm" "$work/sharded.ltm" || { echo "assembled file differs" >&2; exit 1; }

sh_total_bake=$(echo "$sh_bake + $sh_merge" | bc -l)
sh_total_compress=$(echo "$sh_analyze + $sh_plan + $sh_code + $sh_assemble" | bc -l)
f() { printf '%.2f' "$1"; }
echo "| $scene at $size, n = $face_res, $shards shards ($((k - 1)) codings) | one machine (s) | $shards shards in turn (s) | ratio |"
echo "|---|---|---|---|"
echo "| bake (+ merge) | $(f "$one_bake") | $(f "$sh_bake") + $(f "$sh_merge") | $(f "$(echo "$sh_total_bake / $one_bake" | bc -l)") |"
echo "| compress (analyze + plan + code + assemble) | $(f "$one_compress") | $(f "$sh_analyze") + $(f "$sh_plan") + $(f "$sh_code") + $(f "$sh_assemble") | $(f "$(echo "$sh_total_compress / $one_compress" | bc -l)") |"
echo
echo "raw store and .ltm file byte-identical to one machine's: yes"
