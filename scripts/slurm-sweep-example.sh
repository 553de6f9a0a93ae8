#!/bin/bash
# Runs the Slurm job-array example for sweeps (docs/studies.md) on a real scheduler: a single-node Slurm
# (Debian's slurm-wlm, with munge) on this machine, set up here if it is not running; then the
# job array (scripts/slurm-sweep-job.sh, as docs/studies.md shows it), the merge as a dependent job,
# and one local run of the same sweep; the merged sweep.csv must equal the local one byte for byte.
#
# Usage (as root, on Debian 12): scripts/slurm-sweep-example.sh [BINPICK_BINARY]
# The binary defaults to $CARGO_TARGET_DIR/release/binpick (or target/release/binpick).
# /shared/runs is where the example writes (a symlink to a fresh temporary folder here).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
bin=${1:-${CARGO_TARGET_DIR:-$here/../target}/release/binpick}
bin=$(readlink -f "$bin")
[ -x "$bin" ] || { echo "no binpick binary at $bin (cargo build --release first)" >&2; exit 1; }

# --- a single-node Slurm ------------------------------------------------------------------------
if ! command -v slurmctld >/dev/null; then
  DEBIAN_FRONTEND=noninteractive apt-get install -y slurm-wlm munge
fi
node=$(hostname -s)
cpus=$(nproc)
mem=$(awk '/MemTotal/ {print int($2 / 1024 * 0.9)}' /proc/meminfo)
if ! scontrol ping 2>/dev/null | grep -q UP; then
  mkdir -p /etc/slurm /var/spool/slurmctld /var/spool/slurmd /var/log/slurm /run/munge
  [ -s /etc/munge/munge.key ] || mungekey --create --keyfile /etc/munge/munge.key
  chown -R munge:munge /etc/munge /run/munge /var/lib/munge /var/log/munge 2>/dev/null || true
  chmod 0400 /etc/munge/munge.key
  pgrep -x munged >/dev/null || su -s /bin/sh munge -c /usr/sbin/munged
  cat > /etc/slurm/slurm.conf <<CONF
ClusterName=binpick
SlurmctldHost=$node
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MpiDefault=none
NodeName=$node CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=main Nodes=$node Default=YES MaxTime=INFINITE State=UP
CONF
  slurmctld
  slurmd
  for _ in $(seq 30); do scontrol ping 2>/dev/null | grep -q UP && break; sleep 1; done
  scontrol update nodename="$node" state=resume 2>/dev/null || true
fi
sinfo

# --- the documented example, as written ----------------------------------------------------------
work=$(mktemp -d /tmp/binpick-slurm.XXXXXX)
mkdir -p "$work/runs" "$work/bin"
mkdir -p /shared
ln -sfn "$work/runs" /shared/runs.new && mv -T /shared/runs.new /shared/runs
ln -s "$bin" "$work/bin/binpick"
export PATH="$work/bin:$PATH"
start=$(date +%s)
array=$(sbatch --parsable --chdir="$work" --export=ALL "$here/slurm-sweep-job.sh")
merge=$(sbatch --parsable --chdir="$work" --export=ALL --dependency=afterok:"$array" --kill-on-invalid-dep=yes --wait \
  --wrap 'binpick merge /shared/runs/sweep-sensor.latency_s-ABCDEF-seeds1-picks21-det-shard*of4 --out /shared/runs')
echo "job array $array and merge $merge finished in $(( $(date +%s) - start )) s"
sacct -j "$array,$merge" --format=JobID,State,ExitCode,Elapsed 2>/dev/null || squeue
cat "$work"/slurm-*.out | grep -v '^$' | tail -n 20 || true

# --- one local run of the same sweep, and the comparison -----------------------------------------
binpick sweep --set sensor.latency_s=0.3,0.7,1.1 --deterministic --jobs "$cpus" --out "$work/local" >/dev/null
merged=/shared/runs/sweep-sensor.latency_s-ABCDEF-seeds1-picks21-det/sweep.csv
local=$work/local/sweep-sensor.latency_s-ABCDEF-seeds1-picks21-det/sweep.csv
if cmp "$merged" "$local"; then
  echo "IDENTICAL: the merged sweep.csv of the Slurm job array equals the local run's ($(wc -l < "$local") lines)"
else
  echo "DIFFERENT: $merged vs $local" >&2
  exit 1
fi
