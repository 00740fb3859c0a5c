#!/bin/bash
# What a host gives independent work, whatever the bake does: N copies of one single-threaded
# `slosh bake --jobs 1`, each pinned to its own core, started at once; prints each copy's wall
# seconds, sorted. A copy's time against one copy alone is what N busy cores give each core.
# (docs/results-bake.md, "What the host gives").
#
#   SLOSH=target/release/slosh scripts/host_scaling.sh [POINTS] [STEPS] [COPIES...]
set -euo pipefail
slosh=$(readlink -f "${SLOSH:-slosh}")
points=${1:-100000}
steps=${2:-4}
shift $(($# < 2 ? $# : 2))
counts=("${@:-1 2 4 8 16}")
work=$(mktemp -d /tmp/slosh-host.XXXXXX)
trap 'rm -rf "$work"' EXIT
"$slosh" gen sphere --points "$points" --steps "$steps" --out "$work/in" > /dev/null
for n in ${counts[@]}; do
    for k in $(seq 0 $((n - 1))); do
        /usr/bin/time -f "%e" -o "$work/t$k" taskset -c "$k" \
            "$slosh" bake "$work/in/sphere.case" --out "$work/c$k" --quiet --jobs 1 > /dev/null 2>&1 &
    done
    wait
    echo "$points points x $steps steps, $n copies: $(for k in $(seq 0 $((n - 1))); do cat "$work/t$k"; done | sort -n | tr '\n' ' ')"
    rm -rf "$work"/c*
done
