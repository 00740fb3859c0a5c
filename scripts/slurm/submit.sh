#!/bin/bash
# Submits a series' bake as a SLURM job array of TASKS tasks, then a job that rebuilds the
# manifest once every task has succeeded (docs/slurm.md). Prints the two job ids.
#
#   scripts/slurm/submit.sh TASKS CASE OUT [sbatch options --] [bake flags]
#
# Logs go to OUT.logs/. Resubmitting after a failure or a cancel bakes only what is missing.
set -euo pipefail
if [ $# -lt 3 ]; then
    echo "usage: submit.sh TASKS CASE OUT [sbatch options --] [bake flags]" >&2
    exit 2
fi
tasks=$1
case_file=$2
out=$3
shift 3
sbatch_options=()
if [[ " $* " == *" -- "* ]]; then
    while [ "$1" != "--" ]; do
        sbatch_options+=("$1")
        shift
    done
    shift
fi
here=$(dirname "$(readlink -f "$0")")
mkdir -p "$out.logs"
array=$(sbatch --parsable "${sbatch_options[@]}" --array="0-$((tasks - 1))" \
    --output="$out.logs/bake-%A_%a.out" "$here/bake-array.sh" "$case_file" "$out" "$@")
manifest=$(sbatch --parsable --dependency="afterok:$array" --job-name=slosh-manifest \
    --output="$out.logs/manifest-%j.out" \
    --wrap "'${SLOSH:-slosh}' bake --manifest-only '$out'")
echo "$array $manifest"
