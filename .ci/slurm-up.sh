#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, for the test of the Slurm job-array scripts
# (tests/e2e/cluster.rs, scripts/slurm/). Installs Debian's slurm-wlm and munge,
# writes /etc/slurm/slurm.conf for one node (this machine's CPUs and memory, reached as
# localhost), starts munged, slurmctld and slurmd by hand (CI machines have no systemd) and
# waits until `sinfo` shows the node ready for jobs.
#
# Idempotent: when `sinfo` already answers with the node up, it does nothing. Root only.
# Logs: /var/log/slurm/. Stop it with `.ci/slurm-up.sh --down`.
set -euo pipefail

readonly CONF=/etc/slurm/slurm.conf
readonly NODE=localhost
readonly STATE=/var/spool/slurmctld
readonly SPOOL=/var/spool/slurmd
readonly LOGS=/var/log/slurm
readonly RUN=/run/slurm

say() { echo "slurm-up: $*" >&2; }

# The node is usable when sinfo answers and shows it idle, mixed or allocated.
node_ready() {
  local state
  state="$(timeout 10 sinfo --noheader --nodes="$NODE" --format=%T 2>/dev/null | head -n 1)" || return 1
  case "$state" in
    idle* | mixed* | allocated* | completing*) return 0 ;;
    *) return 1 ;;
  esac
}

pid_alive() { [[ -s "$1" ]] && kill -0 "$(cat "$1")" 2>/dev/null; }

down() {
  local f
  for f in "$RUN/slurmd.pid" "$RUN/slurmctld.pid" /run/munge/munged.pid; do
    if pid_alive "$f"; then kill "$(cat "$f")"; fi
  done
  say "stopped"
}

install_packages() {
  if command -v slurmctld >/dev/null && command -v slurmd >/dev/null && command -v sbatch >/dev/null \
    && command -v munged >/dev/null; then
    return
  fi
  say "installing slurm-wlm munge"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends slurm-wlm munge >/dev/null
}

# One node: the CPUs and memory slurmd detects here (`slurmd -C`), named localhost so the
# file does not depend on the machine's hostname. Memory is a consumable resource, so a job's
# --mem is checked against the node's RealMemory when it is scheduled. No cgroups
# (proctrack/linuxproc, task/none): containers rarely allow them; nothing enforces the limits.
write_conf() {
  local detected cpus mem
  detected="$(slurmd -C | head -n 1)"
  cpus="$(sed -n 's/.* CPUs=\([0-9]*\).*/\1/p' <<<"$detected")"
  mem="$(sed -n 's/.* RealMemory=\([0-9]*\).*/\1/p' <<<"$detected")"
  [[ -n "$cpus" && -n "$mem" ]] || { say "cannot read CPUs/RealMemory from: $detected"; exit 1; }
  mkdir -p /etc/slurm
  cat >"$CONF.tmp" <<EOF
# Written by voxlod's .ci/slurm-up.sh: a single-node cluster on localhost.
ClusterName=voxlod-ci
SlurmctldHost=$NODE
AuthType=auth/munge
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$STATE
SlurmdSpoolDir=$SPOOL
SlurmctldPidFile=$RUN/slurmctld.pid
SlurmdPidFile=$RUN/slurmd.pid
SlurmctldLogFile=$LOGS/slurmctld.log
SlurmdLogFile=$LOGS/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
# A node that was down comes back by itself once slurmd answers again.
ReturnToService=2
# Finished jobs stay visible to scontrol for 10 minutes (there is no accounting database).
MinJobAge=600
NodeName=$NODE NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=main Nodes=$NODE Default=YES MaxTime=INFINITE State=UP
EOF
  mv "$CONF.tmp" "$CONF"
  say "wrote $CONF (CPUs=$cpus RealMemory=${mem}M)"
}

start_munge() {
  if pid_alive /run/munge/munged.pid && munge -n </dev/null | unmunge >/dev/null 2>&1; then
    return
  fi
  mkdir -p /run/munge /var/log/munge /var/lib/munge
  chown munge:munge /run/munge /var/log/munge /var/lib/munge
  chmod 0755 /run/munge
  if [[ ! -s /etc/munge/munge.key ]]; then
    mungekey --create --keyfile=/etc/munge/munge.key
  fi
  chown munge:munge /etc/munge/munge.key
  chmod 0400 /etc/munge/munge.key
  runuser -u munge -- munged
  munge -n </dev/null | unmunge >/dev/null
}

start_daemons() {
  mkdir -p "$STATE" "$SPOOL" "$LOGS" "$RUN"
  if ! pid_alive "$RUN/slurmctld.pid"; then slurmctld; fi
  if ! pid_alive "$RUN/slurmd.pid"; then slurmd -N "$NODE"; fi
}

wait_ready() {
  local i
  for i in $(seq 1 60); do
    if node_ready; then
      say "node $NODE ready after ${i} polls: $(sinfo --noheader --format='%P %a %D %T %c CPUs %m MB')"
      return
    fi
    # A node that registered as down (e.g. from an older state file) is put back to work.
    if timeout 5 sinfo --noheader --nodes="$NODE" --format=%T 2>/dev/null | grep -Eq '^(down|drain)'; then
      scontrol update NodeName="$NODE" State=RESUME 2>/dev/null || true
    fi
    sleep 0.5
  done
  say "the node did not become ready in 30 s; sinfo says:"
  sinfo >&2 || true
  tail -n 20 "$LOGS/slurmctld.log" "$LOGS/slurmd.log" >&2 || true
  exit 1
}

main() {
  if [[ "${1:-}" == "--down" ]]; then
    down
    exit 0
  fi
  if command -v sinfo >/dev/null && [[ -f "$CONF" ]] && node_ready; then
    say "already running"
    exit 0
  fi
  [[ "$(id -u)" == 0 ]] || { say "must run as root (it installs packages and starts daemons)"; exit 1; }
  install_packages
  write_conf
  start_munge
  start_daemons
  wait_ready
}

main "$@"
