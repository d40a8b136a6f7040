#!/usr/bin/env bash
# One stage of ltm's Slurm pipeline. pipeline.sh copies this file into the
# work directory and submits it; see README.md. Not meant to be run by hand
# except through pipeline.sh.
#
#   stage.sh WORK start          submit bake → merge → analyze → plan →
#                                code 1 → check 1 (run by pipeline.sh)
#   stage.sh WORK bake           one array task: shard of the bake
#   stage.sh WORK merge          join the bake's parts into scene.raw
#   stage.sh WORK analyze        one array task: analyze a column range
#   stage.sh WORK plan           plan the first coding from the analyses
#   stage.sh WORK code K         one array task: code a column range with plan K
#   stage.sh WORK check K        measure coding K: submit coding K+1 and its
#                                check, or assemble scene.ltm
#
# Settings come from WORK/pipeline.env (written by pipeline.sh). Every job
# id submitted is appended to WORK/jobs ("NAME ID" lines), which wait.sh
# follows. Array tasks whose output exists skip their work: outputs are
# written atomically, so an existing one is complete (this is what makes a
# second pipeline.sh in the same work directory resume).
set -euo pipefail

work="${1:?usage: stage.sh WORK STAGE [K]}"
stage="${2:?usage: stage.sh WORK STAGE [K]}"
k="${3:-}"
# shellcheck source=/dev/null
source "$work/pipeline.env" # LTM SCENE SHARDS MAX_CODINGS BAKE_OPTS COMPRESS_OPTS SBATCH_OPTS

# The files of shards 0..SHARDS-1: files PREFIX SUFFIX.
files() {
    local i
    for ((i = 0; i < SHARDS; i++)); do printf '%s\n' "$1$i$2"; done
}

# submit NAME yes|no DEPENDENCY STAGE [K]: submits a stage (a SHARDS-task
# array when yes) that starts when job DEPENDENCY (if any) has completed
# successfully, and is cancelled when it failed; prints its id.
submit() {
    local name="$1" array="$2" dep="$3" id
    shift 3
    local opts=(--parsable --requeue --job-name="ltm-$name" "${SBATCH_OPTS[@]}")
    if [ "$array" = yes ]; then
        opts+=(--array="0-$((SHARDS - 1))" --output="$work/logs/$name-%a.out")
    else
        opts+=(--output="$work/logs/$name.out")
    fi
    if [ -n "$dep" ]; then
        opts+=(--dependency="afterok:$dep" --kill-on-invalid-dep=yes)
    fi
    id="$(sbatch "${opts[@]}" "$work/stage.sh" "$work" "$@")"
    id="${id%%;*}" # "ID;CLUSTER" on a federation
    echo "$name $id" >>"$work/jobs"
    echo "$id"
}

# The array task's shard index, for file names (ltm itself reads
# --shard auto from the same variables).
shard_index() {
    local id="${SLURM_ARRAY_TASK_ID:?not a Slurm array task}"
    echo $((id - ${SLURM_ARRAY_TASK_MIN:-0}))
}

# Runs ltm unless OUT exists already: skip_or_run OUT ARGS...
skip_or_run() {
    local out="$1"
    shift
    if [ -e "$out" ]; then
        echo "$out exists (a complete output of an earlier run): skipped"
        return 0
    fi
    echo "+ ltm $*"
    "$LTM" "$@"
}

# ltm's threads: the CPUs Slurm gave this task.
if [ -z "${RAYON_NUM_THREADS:-}" ] && [ -n "${SLURM_CPUS_PER_TASK:-}" ]; then
    export RAYON_NUM_THREADS="$SLURM_CPUS_PER_TASK"
fi

case "$stage" in
    start)
        mkdir -p "$work/logs" "$work/bake" "$work/analyze" "$work/code"
        bake=$(submit bake yes "" bake)
        merge=$(submit merge no "$bake" merge)
        analyze=$(submit analyze yes "$merge" analyze)
        plan=$(submit plan no "$analyze" plan)
        code=$(submit code-1 yes "$plan" code 1)
        check=$(submit check-1 no "$code" check 1)
        printf 'bake %s\nmerge %s\nanalyze %s\nplan %s\ncode-1 %s\ncheck-1 %s\n' \
            "$bake" "$merge" "$analyze" "$plan" "$code" "$check"
        ;;
    bake)
        i="$(shard_index)"
        skip_or_run "$work/bake/part-$i.raw" \
            bake "$SCENE" --shard auto "${BAKE_OPTS[@]}" -o "$work/bake/part-$i.raw"
        ;;
    merge)
        mapfile -t parts < <(files "$work/bake/part-" .raw)
        skip_or_run "$work/scene.raw" merge "${parts[@]}" -o "$work/scene.raw"
        ;;
    analyze)
        i="$(shard_index)"
        skip_or_run "$work/analyze/a-$i.json" \
            compress "$work/scene.raw" --analyze --shard auto "${COMPRESS_OPTS[@]}" \
            -o "$work/analyze/a-$i.json"
        ;;
    plan)
        mapfile -t analyses < <(files "$work/analyze/a-" .json)
        echo "+ ltm plan ${analyses[*]} -o $work/code/plan-1.json"
        decision="$("$LTM" plan "${analyses[@]}" -o "$work/code/plan-1.json")"
        if [ "$decision" != code ]; then
            echo "stage.sh: ltm plan printed \"$decision\", expected \"code\"" >&2
            exit 1
        fi
        ;;
    code)
        i="$(shard_index)"
        skip_or_run "$work/code/c-$k-$i.part" \
            compress "$work/scene.raw" --plan "$work/code/plan-$k.json" --shard auto \
            -o "$work/code/c-$k-$i.part"
        ;;
    check)
        mapfile -t analyses < <(files "$work/analyze/a-" .json)
        mapfile -t parts < <(files "$work/code/c-$k-" .part)
        next=$((k + 1))
        echo "+ ltm plan ${analyses[*]} ${parts[*]} -o $work/code/plan-$next.json"
        decision="$("$LTM" plan "${analyses[@]}" "${parts[@]}" -o "$work/code/plan-$next.json")"
        case "$decision" in
            assemble)
                echo "+ ltm assemble ${parts[*]} -o $work/scene.ltm"
                "$LTM" assemble "${parts[@]}" -o "$work/scene.ltm"
                ;;
            code)
                if [ "$next" -gt "$MAX_CODINGS" ]; then
                    echo "stage.sh: coding $k missed the target and $MAX_CODINGS codings is the limit (--max-codings)" >&2
                    exit 1
                fi
                code=$(submit "code-$next" yes "" code "$next")
                check=$(submit "check-$next" no "$code" check "$next")
                echo "coding $k missed the target: submitted code-$next ($code) and check-$next ($check)"
                ;;
            *)
                echo "stage.sh: ltm plan printed \"$decision\", expected \"code\" or \"assemble\"" >&2
                exit 1
                ;;
        esac
        ;;
    *)
        echo "stage.sh: unknown stage $stage" >&2
        exit 2
        ;;
esac
