#!/usr/bin/env bash
# Runs ltm's sharded pipeline on Kubernetes, one stage's Job after another.
set -euo pipefail

usage() {
    cat <<'USAGE'
Usage: run.sh [--timeout DURATION] [--max-codings K]

Runs the Jobs of this folder in order in the current kubectl namespace,
waiting for each to complete (kubectl wait, at most --timeout each,
default 24h):

  bake → merge → analyze → plan → (code → check)… → assemble

code and check repeat until check's last log line is "assemble" (at most
--max-codings times, default 8). Apply settings.yaml first and put the
binary at /work/bin/ltm and the scene under /work/scene on the volume (see
README.md). A Job that fails (backoffLimit reached) stops the run; the
Jobs of earlier runs are deleted before each is created again, and a
rerun skips every task whose output exists on the volume.
USAGE
}

timeout=24h max_codings=8
while [ $# -gt 0 ]; do
    case "$1" in
        -h | --help) usage; exit 0 ;;
        --timeout) timeout="${2:?--timeout needs a duration}"; shift 2 ;;
        --max-codings) max_codings="${2:?--max-codings needs a number}"; shift 2 ;;
        *) echo "run.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"

# Runs stage $1's Job to completion; fails as soon as the Job fails.
stage() {
    kubectl delete job "ltm-$1" --ignore-not-found --wait=true >/dev/null
    kubectl create -f "$here/$1.yaml"
    # Complete or Failed, whichever comes first.
    kubectl wait --for=condition=complete --timeout="$timeout" "job/ltm-$1" &
    local complete=$!
    kubectl wait --for=condition=failed --timeout="$timeout" "job/ltm-$1" >/dev/null 2>&1 &
    local failed=$!
    wait -n "$complete" "$failed" || true
    kill "$complete" "$failed" 2>/dev/null || true
    wait "$complete" "$failed" 2>/dev/null || true
    if [ "$(kubectl get "job/ltm-$1" -o jsonpath='{.status.succeeded}')" != \
        "$(kubectl get "job/ltm-$1" -o jsonpath='{.spec.completions}')" ]; then
        echo "run.sh: job ltm-$1 did not complete: kubectl logs job/ltm-$1; kubectl describe job ltm-$1" >&2
        exit 1
    fi
}

for s in bake merge analyze plan; do stage "$s"; done
for ((k = 1; ; k++)); do
    stage code
    stage check
    decision="$(kubectl logs "job/ltm-check" | tail -n 1)"
    echo "coding $k: $decision"
    [ "$decision" = assemble ] && break
    if [ "$k" -ge "$max_codings" ]; then
        echo "run.sh: coding $k still misses the error target (--max-codings $max_codings)" >&2
        exit 1
    fi
done
stage assemble
echo "done: /work/scene.ltm on volume ltm-work"
