#!/usr/bin/env bash
# Starts a single-node Slurm on this machine (Debian or Ubuntu), for
# tools/tests/slow/slurm.rs and for trying tools/cluster/slurm/pipeline.sh.
set -euo pipefail

usage() {
    cat <<'EOF'
Usage: start-local-slurm.sh [--timeout SECONDS]

Starts a single-node Slurm cluster on this machine: one node (this host,
all its CPUs, 90 % of its memory) in one partition, "local".

- Installs munge, slurmctld, slurmd and slurm-client with apt-get when
  they are missing (through sudo when not root).
- Writes /etc/slurm/slurm.conf (only when it is missing or was written by
  this script): proctrack/linuxproc, task/none, no cgroups, no accounting
  daemon, select/cons_tres with CR_CPU so that 1-CPU array tasks share the
  node. SlurmUser is root: slurmd has to run as root anyway to start jobs
  as the submitting user, and root may submit jobs too.
- Creates the munge key when missing; starts munged, slurmctld and slurmd
  (no systemd needed); waits until the node is idle, polling sinfo, for
  at most --timeout seconds (default 60), and fails with the node's state,
  its reason and the daemons' log tails otherwise.

Idempotent: when the node already answers, it does nothing. State and
logs go to $LTM_SLURM_STATE (default /var/tmp/ltm-slurm).
stop-local-slurm.sh stops the daemons.
EOF
}

timeout=60
while [ $# -gt 0 ]; do
    case "$1" in
        -h | --help) usage; exit 0 ;;
        --timeout) timeout="${2:?--timeout needs a number of seconds}"; shift 2 ;;
        *) echo "start-local-slurm.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done

state="${LTM_SLURM_STATE:-/var/tmp/ltm-slurm}"
conf=/etc/slurm/slurm.conf
marker="# Written by ltm tools/cluster/slurm/start-local-slurm.sh"
sudo=""
if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi

# The node's state as sinfo prints it (idle, mixed, down*, ...), or nothing.
node_state() { sinfo -h -N -o '%T' 2>/dev/null | head -n 1 || true; }

case "$(command -v sinfo >/dev/null 2>&1 && node_state)" in
    idle | mixed | allocated | completing)
        echo "Slurm is already up: $(sinfo -h -N -o '%N %T %c CPUs')"
        exit 0 ;;
esac

missing=()
for tool in munged slurmctld slurmd sinfo; do
    command -v "$tool" >/dev/null 2>&1 || missing+=("$tool")
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "== installing munge and Slurm (missing: ${missing[*]})"
    command -v apt-get >/dev/null 2>&1 || {
        echo "start-local-slurm.sh: ${missing[*]} missing and apt-get is not available" >&2
        exit 1
    }
    pkgs=(munge slurmctld slurmd slurm-client)
    if ! DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y --no-install-recommends "${pkgs[@]}"; then
        $sudo apt-get update
        DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y --no-install-recommends "${pkgs[@]}"
    fi
fi

host="$(hostname -s)"
cpus="$(nproc --all)"
mem_mb=$(($(awk '/^MemTotal:/ {print $2}' /proc/meminfo) * 9 / 10240))

if [ -e "$conf" ] && ! grep -qF "$marker" "$conf"; then
    echo "start-local-slurm.sh: $conf exists and was not written by this script; not touching it" >&2
    echo "(this machine seems to have its own Slurm: use it, or move $conf away)" >&2
    exit 1
fi
$sudo mkdir -p "$state/ctld" "$state/d" /etc/slurm
new_conf="$(cat <<EOF
$marker
# (single node, for tests; see tools/cluster/slurm/README.md).
ClusterName=ltm-local
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
# Start a dependent job as soon as the one it waits on ends (the default
# delays batch scheduling by 3 s, at every stage of a pipeline).
SchedulerParameters=batch_sched_delay=0
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SlurmdParameters=config_overrides
ReturnToService=2
StateSaveLocation=$state/ctld
SlurmdSpoolDir=$state/d
SlurmctldPidFile=$state/slurmctld.pid
SlurmdPidFile=$state/slurmd.pid
SlurmctldLogFile=$state/slurmctld.log
SlurmdLogFile=$state/slurmd.log
# Finished jobs stay visible to scontrol for 10 minutes (the wait helper
# reads their final state).
MinJobAge=600
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
)"
conf_changed=""
if [ ! -e "$conf" ] || [ "$new_conf" != "$(cat "$conf")" ]; then
    printf '%s\n' "$new_conf" | $sudo tee "$conf" >/dev/null
    conf_changed=1
fi

# munge: a key readable only by its user, then the daemon (as that user).
if [ ! -s /etc/munge/munge.key ]; then
    echo "== creating the munge key"
    if command -v mungekey >/dev/null 2>&1; then
        $sudo mungekey --create --keyfile=/etc/munge/munge.key
    else
        $sudo dd if=/dev/urandom of=/etc/munge/munge.key bs=1 count=1024 status=none
    fi
    $sudo chown munge:munge /etc/munge/munge.key
    $sudo chmod 0400 /etc/munge/munge.key
fi
$sudo mkdir -p /run/munge /var/log/munge /var/lib/munge
$sudo chown munge:munge /run/munge /var/log/munge /var/lib/munge
if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
    echo "== starting munged"
    $sudo runuser -u munge -- /usr/sbin/munged
    for _ in $(seq 50); do
        munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && break
        sleep 0.2
    done
    munge -n | unmunge >/dev/null || { echo "start-local-slurm.sh: munged does not answer" >&2; exit 1; }
fi

# A daemon is running when its pid file names a live process.
running() { [ -s "$1" ] && $sudo kill -0 "$(cat "$1")" 2>/dev/null; }
if ! running "$state/slurmctld.pid"; then
    echo "== starting slurmctld"
    $sudo slurmctld
elif [ -n "$conf_changed" ]; then
    echo "== slurmctld reads the new $conf"
    $sudo scontrol reconfigure
fi
if ! running "$state/slurmd.pid"; then
    echo "== starting slurmd"
    $sudo slurmd
fi

echo "== waiting (at most ${timeout} s) for node $host to be idle"
deadline=$((SECONDS + timeout))
while :; do
    s="$(node_state)"
    case "$s" in
        idle | mixed | allocated | completing)
            echo "Slurm is up: $(sinfo -h -N -o '%N %T %c CPUs, partition %P')"
            exit 0 ;;
    esac
    if [ $SECONDS -ge $deadline ]; then
        echo "start-local-slurm.sh: node $host is not idle after ${timeout} s (state: ${s:-no answer from slurmctld})" >&2
        sinfo -R >&2 2>/dev/null || true
        for log in slurmctld slurmd; do
            echo "-- $state/$log.log (last lines)" >&2
            $sudo tail -n 15 "$state/$log.log" >&2 2>/dev/null || true
        done
        exit 1
    fi
    # A node that came up down (e.g. an earlier run's state) is resumed.
    case "$s" in
        down* | drain*) $sudo scontrol update NodeName="$host" State=RESUME 2>/dev/null || true ;;
    esac
    sleep 0.5
done
