#!/usr/bin/env bash
# Stops the single-node Slurm that start-local-slurm.sh started.
set -euo pipefail

case "${1:-}" in
    -h | --help)
        cat <<'EOF'
Usage: stop-local-slurm.sh

Stops slurmd, slurmctld and munged as started by start-local-slurm.sh
(their pid files under $LTM_SLURM_STATE, default /var/tmp/ltm-slurm, and
munged's under /run/munge). Jobs still running are killed. The
configuration and state are kept: start-local-slurm.sh starts it again.
Harmless when nothing is running.
EOF
        exit 0 ;;
    "") ;;
    *) echo "stop-local-slurm.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
esac

state="${LTM_SLURM_STATE:-/var/tmp/ltm-slurm}"
sudo=""
if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi

# Stops the process named by pid file $1 (waits up to 10 s for it to exit).
stop() {
    local pidfile="$1" pid
    [ -s "$pidfile" ] || return 0
    pid="$(cat "$pidfile")"
    if $sudo kill "$pid" 2>/dev/null; then
        for _ in $(seq 100); do
            $sudo kill -0 "$pid" 2>/dev/null || break
            sleep 0.1
        done
        echo "stopped $(basename "$pidfile" .pid) ($pid)"
    fi
    $sudo rm -f "$pidfile"
}

stop "$state/slurmd.pid"
stop "$state/slurmctld.pid"
stop /run/munge/munged.pid
