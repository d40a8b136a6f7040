#!/usr/bin/env bash
# Issue 30's per-mesh figures for atlas-layout scenes: the atlas's quality
# and the bake time, the size at 1 % (adaptive and 2d), the relight time at
# N = 256 (median of 5 frames) and one 512² view's time (median of 3).
#
# Usage: tools/validate/atlas_figures.sh SCENE.toml [SCENE.toml ...]
# (e.g. the atlas.toml files that mitsuba_atlas.py writes under --out).
# Needs a release build: cargo build --release -p ltm-tools.
set -euo pipefail
ltm="${LTM:-$(dirname "$0")/../../target/release/ltm}"
env_map="$(dirname "$0")/../../assets/envmaps/courtyard.exr"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
for scene in "$@"; do
    name="$(basename "$(dirname "$scene")")/$(basename "$scene" .toml)"
    echo "== $name"
    start=$(date +%s.%N)
    "$ltm" bake "$scene" -o "$work/t.raw" 2>&1 | grep -E "^(texture|atlas|  )"
    echo "bake: $(echo "$(date +%s.%N) - $start" | bc) s"
    for mode in adaptive 2d; do
        "$ltm" compress "$work/t.raw" -o "$work/$mode.ltm" --mode "$mode" --max-error 0.01 2>&1 \
            | sed -n "s/^wrote [^:]*: \([0-9]*\) bytes (\([0-9.]*x\) smaller.*relative L2 error \([0-9.]*\).*/$mode 1 %: \1 bytes, \2, error \3/p"
    done
    "$ltm" relight "$work/adaptive.ltm" --env "$env_map" --terms 256 --frames 5 --json -o "$work/r.exr" \
        | python3 -c "import json,sys; j=json.loads(sys.stdin.readline()); print('relight N = 256: median frame', j.get('frame_ms'), 'ms')"
    # The scene's own camera: eye, target and field of view.
    read -r eye target fov < <(python3 -c "import tomllib,sys; c=tomllib.load(open(sys.argv[1],'rb'))['camera']; print(','.join(map(str,c['eye'])), ','.join(map(str,c['target'])), c['fov'])" "$scene")
    "$ltm" render "$work/adaptive.ltm" --env "$env_map" --terms all --camera "$eye" --target "$target" \
        --fov "$fov" --size 512x512 --views 3 -o "$work/v.exr" 2>&1 | grep -E "drew"
done
