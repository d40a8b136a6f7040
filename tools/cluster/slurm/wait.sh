#!/usr/bin/env bash
# Waits until Slurm jobs (or a pipeline.sh pipeline) leave the queue.
set -euo pipefail

usage() {
    cat <<'EOF'
Usage: wait.sh [--timeout SECONDS] WORK
       wait.sh [--timeout SECONDS] JOBID...

Waits until the jobs leave Slurm's queue, polling squeue every second (no
fixed sleeps), then prints each job's (each array task's) final state from
`scontrol show job`.

WORK: the work directory of pipeline.sh. Its jobs are those of the last
submission in WORK/jobs, including the ones the pipeline's check jobs
submit while it runs (a further coding): the wait ends only when a
re-read of WORK/jobs adds no job.

Exit status: 0 when every job COMPLETED (and, for WORK, WORK/scene.ltm
exists); 1 when a job ended otherwise (FAILED, CANCELLED, TIMEOUT, ...: a
failed task's afterok dependents are cancelled) or a job's state is
unknown; 124 after --timeout seconds (default 3600), with the jobs
left in the queue.
EOF
}

timeout=3600
args=()
while [ $# -gt 0 ]; do
    case "$1" in
        -h | --help) usage; exit 0 ;;
        --timeout) timeout="${2:?--timeout needs a number of seconds}"; shift 2 ;;
        -*) echo "wait.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
        *) args+=("$1"); shift ;;
    esac
done
[ ${#args[@]} -gt 0 ] || { echo "wait.sh: give a pipeline WORK directory or job ids (see --help)" >&2; exit 2; }
work=""
if [ ${#args[@]} -eq 1 ] && [ -d "${args[0]}" ]; then
    work="${args[0]}"
    [ -f "$work/jobs" ] || { echo "wait.sh: $work/jobs: no such file (not a pipeline.sh work directory?)" >&2; exit 2; }
fi

# The job ids to wait for, one a line: those of WORK/jobs after its last
# "# submitted" line, or the arguments.
jobs() {
    if [ -n "$work" ]; then
        awk '/^#/ { n = 0; delete ids; next } NF >= 2 { ids[n++] = $2 } END { for (i = 0; i < n; i++) print ids[i] }' "$work/jobs"
    else
        printf '%s\n' "${args[@]}"
    fi
}

deadline=$((SECONDS + timeout))
while :; do
    ids="$(jobs)"
    # The array (or plain) job id of every job in the queue, in any state
    # (pending, running, requeued, completing, ...).
    if queued="$(squeue -h -o '%F' 2>&1)"; then
        left="$(grep -Fxf <(printf '%s\n' "$queued") <(printf '%s\n' "$ids") || true)"
        if [ -z "$left" ] && [ "$(jobs)" = "$ids" ]; then
            break
        fi
    else
        left="(squeue failed: $queued)"
    fi
    if [ $SECONDS -ge $deadline ]; then
        echo "wait.sh: timed out after ${timeout} s; still queued: ${left//$'\n'/ }" >&2
        squeue -a 2>/dev/null >&2 || true
        exit 124
    fi
    sleep 1
done

status=0
for id in $ids; do
    if ! info="$(scontrol show job -o "$id" 2>/dev/null)"; then
        echo "$id: state unknown (no longer known to slurmctld: MinJobAge)"
        status=1
        continue
    fi
    while read -r line; do
        field() { grep -o "\b$1=[^ ]*" <<<"$line" | head -n 1 | cut -d= -f2 || true; }
        name="$(field JobName)" state="$(field JobState)" exit_code="$(field ExitCode)"
        task="$(field ArrayTaskId)"
        echo "$name ${id}${task:+_$task} $state (exit $exit_code)"
        [ "$state" = COMPLETED ] || status=1
    done <<<"$info"
done
if [ -n "$work" ]; then
    if [ -f "$work/scene.ltm" ] && [ $status = 0 ]; then
        echo "pipeline done: $work/scene.ltm"
    else
        echo "pipeline failed: see $work/logs" >&2
        status=1
    fi
fi
exit $status
