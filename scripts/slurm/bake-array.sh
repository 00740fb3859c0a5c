#!/bin/bash
# One task of a SLURM job array bakes its shard of a series (docs/slurm.md):
#
#   sbatch --array=0-15 --cpus-per-task=16 scripts/slurm/bake-array.sh CASE OUT [bake flags]
#
# Steps are dealt to tasks round-robin (`--shard slurm` reads SLURM_ARRAY_TASK_ID and
# SLURM_ARRAY_TASK_COUNT); a resubmitted array keeps every step already baked. $SLOSH names
# the binary (default: slosh on PATH).
#SBATCH --job-name=slosh-bake
set -euo pipefail
if [ $# -lt 2 ]; then
    echo "usage: sbatch --array=0-N bake-array.sh CASE OUT [bake flags]" >&2
    exit 2
fi
case_file=$1
out=$2
shift 2
# One step at a time; its stages use every CPU the task was given.
exec "${SLOSH:-slosh}" bake "$case_file" --out "$out" --shard slurm --jobs 1 "$@"
