#!/usr/bin/env bash
# The incremental test loop, measured: after a one-line change in
# codec/src, relight/src and tools/src (a function appended to the crate's
# root, then taken back: new code and new metadata, so every crate above
# it is compiled again, as after a real edit), the wall time of a test
# command: its build alone (`--no-run`), and the build and run together.
#
# Usage: tools/validate/test_loop.sh [--runs] [COMMAND...]
#   COMMAND   the test command (default: cargo test --workspace); e.g.
#             `cargo fast` for the fast tier
#   --runs    also time the command with its tests run (default: the
#             build only)
# Run it in a checkout whose target/ is already built for COMMAND (the
# first build is not the loop), on a quiet machine. Prints one line per
# crate: the build's seconds, and with --runs the whole command's.
set -euo pipefail
cd "$(dirname "$0")/../.."

runs=""
if [ "${1:-}" = --runs ]; then runs=1; shift; fi
cmd=("$@")
[ ${#cmd[@]} -eq 0 ] && cmd=(cargo test --workspace)

files=(codec/src/lib.rs relight/src/lib.rs tools/src/main.rs)
restore() { git checkout -- "${files[@]}" 2>/dev/null || true; }
trap restore EXIT

# Warm: the command's build as it stands.
"${cmd[@]}" --no-run >/dev/null 2>&1

# Appends a one-line function returning $2 to $1.
change() {
    echo "#[allow(dead_code, missing_docs)] #[doc(hidden)] pub fn test_loop_probe() -> u64 { $2 }" >>"$1"
}

timed() { # prints the seconds "$@" took (fails if it fails)
    local t0 t1
    t0=$(date +%s.%N)
    "$@" >/tmp/test_loop.$$ 2>&1 || { cat /tmp/test_loop.$$ >&2; rm -f /tmp/test_loop.$$; return 1; }
    t1=$(date +%s.%N)
    rm -f /tmp/test_loop.$$
    awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.1f\n", b - a }'
}

echo "command: ${cmd[*]}   ($(nproc) cores, $(date -u +%Y-%m-%d))"
for f in "${files[@]}"; do
    change "$f" 1
    build=$(timed "${cmd[@]}" --no-run)
    line="$(printf '%-20s build %6.1f s' "$f" "$build")"
    if [ -n "$runs" ]; then
        restore
        change "$f" 2
        total=$(timed "${cmd[@]}")
        line="$line   build and run $(printf '%6.1f' "$total") s"
    fi
    echo "$line"
    restore
done
# Leave target/ built for the files as they are.
"${cmd[@]}" --no-run >/dev/null 2>&1
