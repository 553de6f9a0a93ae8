#!/bin/bash
# The job-array example for sweeps (docs/studies.md, "Slurm"): four shards of
# one sweep, one array task each; `binpick merge` joins them once all four have finished.
#SBATCH --job-name=binpick-sweep
#SBATCH --array=1-4
#SBATCH --cpus-per-task=1
#SBATCH --output=slurm-%A_%a.out
binpick sweep --set sensor.latency_s=0.3,0.7,1.1 --deterministic --jobs 1 \
  --shard ${SLURM_ARRAY_TASK_ID}/4 --out /shared/runs
# then, once all four have finished (e.g. sbatch --dependency=afterok:JOBID):
#   binpick merge /shared/runs/sweep-sensor.latency_s-ABCDEF-seeds1-picks21-det-shard*of4 --out /shared/runs
