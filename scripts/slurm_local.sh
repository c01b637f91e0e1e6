#!/usr/bin/env bash
# A one-node Slurm cluster on this machine, at 127.0.0.1: to run the Snakefile through
# `--executor slurm` (profiles/slurm) without a real cluster. Debian/Ubuntu, as root (munged and slurmd must be).
#
#   bash scripts/slurm_local.sh start    # install Slurm + munge if missing, start munged, slurmctld, slurmd;
#                                        # returns when `sinfo` shows the node idle; prints `started`, or
#                                        # `running` when it already was (then stop is someone else's to do)
#   bash scripts/slurm_local.sh status   # the node's state, the queue
#   bash scripts/slurm_local.sh stop     # stop what `start` started (munged only if it started it)
#
#   ORCA_SLURM_DIR   where its state, logs and pid files live (default /tmp/orca-slurm)
#
# The node is this host (its short name, its CPUs and memory as `slurmd -C` measures them) at 127.0.0.1, in one
# partition `local`; the controller is at 127.0.0.1 too. (slurmctld and slurmd still listen on every interface,
# ports 6817 and 6818: Slurm has no setting for the address they bind; munge authenticates every message with
# this machine's key.) The config goes where every Slurm command looks for it, /etc/slurm/slurm.conf (Snakemake's
# job step drops SLURM_* variables, SLURM_CONF included, before its srun), and is removed by stop; a slurm.conf
# that this script did not write is left alone and start refuses. Jobs run as root, without cgroups
# (proctrack/linuxproc, task/none) and without an accounting database: job states come from `squeue` (kept
# MIN_JOB_AGE seconds after a job ends; the Snakemake plugin's `--slurm-status-command squeue`) and each finished
# job's record from the job completion log $ORCA_SLURM_DIR/jobcomp.log (sacct would need slurmdbd and MySQL).
set -euo pipefail

DIR="${ORCA_SLURM_DIR:-/tmp/orca-slurm}"
CONF=/etc/slurm/slurm.conf
MARK="# Written by scripts/slurm_local.sh: a one-node loopback cluster."
NODE="$(hostname -s)"
PARTITION="local"
MIN_JOB_AGE=300     # seconds squeue still shows a finished job: the plugin's squeue status check needs >= 120
IDLE_TIMEOUT=60     # seconds to wait for the node to register idle
# slurm-wlm's daemons and commands, without the metapackage's development files and extra plugins
PACKAGES=(slurmctld slurmd slurm-client munge)
BOLD=""; PLAIN=""
if [ -t 2 ]; then BOLD=$'\033[1m'; PLAIN=$'\033[0m'; fi
say() { printf '%s[slurm_local]%s %s\n' "$BOLD" "$PLAIN" "$*" >&2; }
die() { say "$*"; exit 1; }

install_packages() {
    command -v slurmctld >/dev/null && command -v slurmd >/dev/null && command -v munged >/dev/null && return
    [ "$(id -u)" -eq 0 ] || die "Slurm and munge are not installed and this is not root: apt-get install ${PACKAGES[*]}"
    command -v apt-get >/dev/null || die "Slurm and munge are not installed and there is no apt-get"
    say "installing Debian packages ${PACKAGES[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq || die "apt-get update failed"
    apt-get install -y -qq "${PACKAGES[@]}" >/dev/null || die "apt-get install ${PACKAGES[*]} failed"
}

munge_works() { munge -n 2>/dev/null | unmunge >/dev/null 2>&1; }

start_munge() {
    if munge_works; then
        return
    fi
    if [ ! -s /etc/munge/munge.key ]; then
        say "creating /etc/munge/munge.key"
        dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
    fi
    chown munge:munge /etc/munge/munge.key && chmod 400 /etc/munge/munge.key
    mkdir -p /run/munge /var/lib/munge /var/log/munge
    chown munge:munge /run/munge /var/lib/munge /var/log/munge
    chmod 755 /run/munge
    runuser -u munge -- /usr/sbin/munged || die "munged did not start (see /var/log/munge/munged.log)"
    touch "$DIR/munged.ours"
    for _ in $(seq 20); do munge_works && return; sleep 0.5; done
    die "munge does not answer (see /var/log/munge/munged.log)"
}

write_conf() {
    # slurmd -C: "NodeName=vm CPUs=2 Boards=1 SocketsPerBoard=1 CoresPerSocket=2 ThreadsPerCore=1 RealMemory=24105"
    local node_line
    node_line="$(slurmd -C | head -n 1)"
    [[ "$node_line" == NodeName=* ]] || die "slurmd -C did not describe this node: $node_line"
    mkdir -p "$DIR/ctld" "$DIR/d" "$(dirname "$CONF")"
    cat > "$CONF" <<EOF
$MARK
ClusterName=orca
SlurmctldHost=$NODE(127.0.0.1)
SlurmUser=root
AuthType=auth/munge
StateSaveLocation=$DIR/ctld
SlurmdSpoolDir=$DIR/d
SlurmctldPidFile=$DIR/slurmctld.pid
SlurmdPidFile=$DIR/slurmd.pid
SlurmctldLogFile=$DIR/slurmctld.log
SlurmdLogFile=$DIR/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$DIR/jobcomp.log
MpiDefault=none
ReturnToService=2
MinJobAge=$MIN_JOB_AGE
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
$node_line NodeAddr=127.0.0.1 State=UNKNOWN
PartitionName=$PARTITION Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
}

ours() { [ "$(head -n 1 "$CONF" 2>/dev/null)" = "$MARK" ]; }

node_state() { sinfo -h -N -n "$NODE" -o %t 2>/dev/null | head -n 1; }

start() {
    install_packages
    mkdir -p "$DIR"
    if [ -f "$CONF" ] && ! ours; then
        die "$CONF exists and was not written by this script: this machine has a Slurm of its own; not touching it"
    fi
    if [ -f "$CONF" ] && [ "$(node_state)" = idle ]; then
        say "already running ($CONF)"
        echo running
        return
    fi
    start_munge
    write_conf
    # -c: a fresh cluster each start, no jobs or node states left from an earlier one (job ids start again)
    rm -f "$DIR/jobcomp.log"
    slurmctld -c -f "$CONF" || die "slurmctld did not start (see $DIR/slurmctld.log)"
    slurmd -f "$CONF" || die "slurmd did not start (see $DIR/slurmd.log)"
    local state=""
    for _ in $(seq $((IDLE_TIMEOUT * 2))); do
        state="$(node_state)"
        [ "$state" = idle ] && break
        sleep 0.5
    done
    if [ "$state" != idle ]; then
        say "the node is '${state:-not listed}' after ${IDLE_TIMEOUT}s; last lines of the logs:"
        tail -n 5 "$DIR/slurmctld.log" "$DIR/slurmd.log" >&2 || true
        stop
        exit 1
    fi
    say "node $NODE idle in partition $PARTITION: $(sed -n 's/^NodeName=[^ ]* //p' "$CONF")"
    echo started
}

stop_daemon() {  # name pidfile
    local pid
    [ -f "$2" ] || return 0
    pid="$(cat "$2")"
    if kill "$pid" 2>/dev/null; then
        for _ in $(seq 20); do kill -0 "$pid" 2>/dev/null || break; sleep 0.5; done
        say "stopped $1 ($pid)"
    fi
    rm -f "$2"
}

stop() {
    stop_daemon slurmd "$DIR/slurmd.pid"
    stop_daemon slurmctld "$DIR/slurmctld.pid"
    if [ -f "$DIR/munged.ours" ]; then
        stop_daemon munged /run/munge/munged.pid
        rm -f "$DIR/munged.ours"
    fi
    if ours; then
        rm -f "$CONF"
    fi
}

status() {
    sinfo -N -o "%N %t %c %m" && squeue
}

case "${1:-}" in
    start) start ;;
    stop) stop ;;
    status) status ;;
    *) echo "usage: $0 start|status|stop" >&2; exit 2 ;;
esac
