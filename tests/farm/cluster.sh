#!/usr/bin/env bash
# A private single-node Slurm cluster for the farm tests, from Debian's packages (slurm-wlm, munge): its own munge
# key and socket, its own slurm.conf, state and logs in DIR, and a port pair no other cluster on the machine uses.
# Nothing under /etc is read or written. Needs root (slurmd runs the jobs as their user).
#   cluster.sh start DIR   start it; prints the SLURM_CONF line to export for the client programs
#   cluster.sh stop DIR    cancel its jobs and stop its daemons
# Besides the default partition `main` (this machine), partition `elsewhere` names a node that is another machine
# (never up), so that a test can submit to a partition whose nodes cannot see this machine's local disks.
set -euo pipefail
command=${1:?usage: cluster.sh start|stop DIR}
dir=$(realpath -m "${2:?usage: cluster.sh start|stop DIR}")
export SLURM_CONF="$dir/slurm.conf"

wait_for() {  # wait_for SECONDS DESCRIPTION COMMAND...: poll until COMMAND succeeds
  local deadline=$((SECONDS + $1)) what=$2
  shift 2
  until "$@" >/dev/null 2>&1; do
    if ((SECONDS > deadline)); then
      echo "cluster.sh: $what did not happen within the time allowed" >&2
      return 1
    fi
    sleep 0.2
  done
}

port_free() { ! (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null; }

stop_daemon() {  # stop_daemon PIDFILE
  [ -f "$1" ] || return 0
  local pid
  pid=$(cat "$1")
  kill "$pid" 2>/dev/null || return 0
  wait_for 20 "the exit of process $pid" bash -c "! kill -0 $pid" || kill -9 "$pid" 2>/dev/null || true
}

case "$command" in
start)
  for program in munged slurmctld slurmd sbatch; do
    command -v "$program" >/dev/null || { echo "cluster.sh: $program is missing (apt-get install slurm-wlm)" >&2; exit 77; }
  done
  [ "$(id -u)" -eq 0 ] || { echo "cluster.sh: a Slurm cluster needs root to run jobs" >&2; exit 77; }
  mkdir -p "$dir"/{munge,state,spool,log}
  chmod 700 "$dir/munge"
  head -c 1024 /dev/urandom >"$dir/munge/munge.key"
  chmod 400 "$dir/munge/munge.key"
  munged --force --key-file="$dir/munge/munge.key" --socket="$dir/munge/munge.sock" \
    --pid-file="$dir/munge/munged.pid" --log-file="$dir/munge/munged.log" --seed-file="$dir/munge/seed" \
    --origin=127.0.0.1
  # Two free ports in a range ganache's tests keep to, starting from a spot that differs per cluster folder.
  port=$((17000 + $(cksum <<<"$dir" | cut -d' ' -f1) % 2000 * 2))
  while ! port_free "$port" || ! port_free $((port + 1)); do port=$((port + 2)); done
  host=$(hostname -s)
  cpus=$(nproc)
  memory=$(awk '/MemTotal/ { m = int($2 / 1024 * 0.8); print (m > 16000 ? 16000 : m) }' /proc/meminfo)
  cat >"$SLURM_CONF" <<CONF
ClusterName=ganachetest
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
AuthType=auth/munge
AuthInfo=socket=$dir/munge/munge.sock
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
# No cgroups: with them, jobs on a machine without a delegated cgroup tree end COMPLETED having run nothing.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
DefMemPerCPU=500
SchedulerType=sched/backfill
SchedulerParameters=bf_interval=1
MpiDefault=none
SwitchType=switch/none
ReturnToService=2
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$memory State=UNKNOWN
NodeName=elsewhere NodeAddr=127.0.0.2 CPUs=$cpus RealMemory=$memory State=DOWN
PartitionName=main Nodes=$host Default=YES MaxTime=INFINITE State=UP
PartitionName=elsewhere Nodes=elsewhere MaxTime=INFINITE State=UP
CONF
  slurmctld -f "$SLURM_CONF"
  slurmd -f "$SLURM_CONF"
  wait_for 60 "node $host idle" bash -c "sinfo -h -p main -o %T | grep -q idle" || {
    tail -n 20 "$dir"/log/*.log >&2
    exit 1
  }
  echo "export SLURM_CONF=$SLURM_CONF"
  ;;
stop)
  if [ -f "$dir/slurmctld.pid" ]; then
    scancel --full $(squeue -h -o %i 2>/dev/null) 2>/dev/null || true
    wait_for 30 "the end of every job" bash -c '[ -z "$(squeue -h -t running,completing 2>/dev/null)" ]' || true
  fi
  stop_daemon "$dir/slurmd.pid"
  stop_daemon "$dir/slurmctld.pid"
  stop_daemon "$dir/munge/munged.pid"
  ;;
*)
  echo "usage: cluster.sh start|stop DIR" >&2
  exit 2
  ;;
esac
