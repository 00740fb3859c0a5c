#!/bin/bash
# The GPU figures the open issues' goals name (docs/results-scrub.md, docs/results-bake.md),
# in parts that each fit one 10-minute command on a GPU host with 16 cores. Reports and
# printed output go to OUT; series are written under /tmp and reused.
#
#   scripts/gpu_figures.sh OUT scrub|scale|raw|bake|bake-before|before|series
#
# slosh is $SLOSH, else .dev/slosh, else the one on PATH. Where the repo holds .gl and .whl
# (scripts/gpu_prepare.sh makes them), the loaders are unpacked and pysplashsurf installed
# first. SMALL=1 runs every command at sizes a 2-core machine takes in minutes (a check of
# the script and its flags, not figures). A device command returns only a few files from
# its $OUT, so give the script a folder of its own and pack that:
#   scripts/gpu_figures.sh /tmp/w scrub; tar czf $OUT/scrub.tgz -C /tmp/w .
# (the 'before' part writes 17 files; a call that returned them loose kept 8.)
#
# scrub: `bench scrub` 100k and 1M (page cache), `bench gpu` (table 4.6, 100k and 1M).
# scale: `bench scrub` 4M, 500 steps of 1M resident (8 distinct shapes), the raw EnSight
#        case at 1M with the GPU bake.
# raw:   the scale part's raw EnSight case alone (1M, baked on the GPU as played).
# bake:  `bench bake` 100k and 1M with the GPU column, 64 steps of 1M through the batch,
#        one 4M step baked on the GPU with its device memory sampled every 50 ms.
# bake-before: `bench bake` at 1M and two 4M steps through `slosh bake --device gpu`, the
#        baseline binary $BEFORE and slosh alternated, twice each.
# series: 64 steps of 1M through `slosh bake --device gpu` at 8, 16, 24 and 32 jobs, with the
#        CPU seconds they took (the baseline $BEFORE at 8 jobs too, where set).
# before: the baseline binary $BEFORE (the one an issue's "now" column came from) on this
#        card: `bench gpu` alternated with slosh (before, after, before, after), and its
#        `bench scrub` of the scrub and scale parts' 100k, 1M and 4M series.
set -euo pipefail
# OUT and $SLOSH are the caller's paths; the rest is the repo's.
out=$(readlink -m "${1:?OUT}")
part=${2:?scrub, scale, raw, bake, bake-before, before or series}
case $part in
scrub | scale | raw | bake | bake-before | before | series) ;;
*)
    echo "unknown part '$part': scrub, scale, raw, bake, bake-before, before or series" >&2
    exit 2
    ;;
esac
[ -n "${SLOSH:-}" ] && SLOSH=$(readlink -f "$(command -v "$SLOSH")")
[ -n "${BEFORE:-}" ] && BEFORE=$(readlink -f "$(command -v "$BEFORE")")
cd "$(dirname "$0")/.."
default=slosh
[ -x .dev/slosh ] && default=.dev/slosh
slosh=$(readlink -f "$(command -v "${SLOSH:-$default}")")
mkdir -p "$out"
# (grep reads all of ldconfig's list: with -q it could stop early, and pipefail would then
# take ldconfig's broken pipe for "not found".)
if ls .gl/*.deb > /dev/null 2>&1 && ! ldconfig -p | grep libvulkan > /dev/null; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
fi
if ls .whl/*.whl > /dev/null 2>&1 && ! python3 -c 'import pysplashsurf' 2> /dev/null; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
        --target /tmp/site .whl/*.whl
    export PYTHONPATH=/tmp/site
fi
# Sizes: the issues' own, or SMALL ones for a check of the script here.
if [ -n "${SMALL:-}" ]; then
    p100k=2000 p1m=5000 p4m=10000 resident=24 threads=2 series=4 tmp=/tmp/slosh-small
    series_jobs="1 2"
else
    p100k=100000 p1m=1000000 p4m=4000000 resident=500 threads=16 series=64 tmp=/tmp
    series_jobs="8 16 24 32"
fi
# run NAME ARGS: slosh ARGS, its output to OUT/NAME.txt; with BIN set, that binary instead.
run() {
    local name=$1
    shift
    local bin=${BIN:-$slosh}
    echo "== $name: $(basename "$bin") $*"
    local TIMEFORMAT="$name: %R s wall"
    { time "$bin" "$@"; } 2>&1 | tee "$out/$name.txt"
}
# The raw EnSight case at 1M, baked on the GPU as the timeline needs each step.
run_raw() {
    run scrub-raw bench scrub --points $p1m --steps 24 --jumps 30 --raw-case \
        --raw-case-gpu --dir $tmp/slosh-sd --out "$out/scrub-raw.md"
}
case $part in
scrub)
    run scrub bench scrub --points $p100k,$p1m --dir $tmp/slosh-sd --cold --out "$out/scrub.md"
    run gpu bench gpu --tables 4.6 --points $p100k,$p1m --max-iterations 2 \
        --out "$out/gpu.md"
    ;;
scale)
    run scrub-4m bench scrub --points $p4m --steps 24 --distinct 4 --pool-steps 8 \
        --jumps 40 --dir $tmp/slosh-sd --out "$out/scrub-4m.md"
    # The resident jumps fill a pool that holds the whole series first.
    run scrub-resident bench scrub --points $p1m --steps $resident --distinct 8 \
        --jumps 100 --dir $tmp/slosh-sd --out "$out/scrub-resident.md"
    run_raw
    ;;
raw)
    run_raw
    ;;
bake)
    run bake bench bake --points $p100k,$p1m --runs 3 --threads $threads --series 0 \
        --out "$out/bake.md"
    run bake-series bench bake --points $p1m --runs 1 --threads $threads --series $series \
        --out "$out/bake-series.md"
    [ -e $tmp/slosh-s4m/sphere.case ] ||
        "$slosh" gen sphere --points $p4m --steps 1 --out $tmp/slosh-s4m > /dev/null
    rm -rf $tmp/slosh-c4m
    if command -v nvidia-smi > /dev/null; then
        nvidia-smi --query-gpu=memory.used --format=csv,noheader,nounits -lms 50 \
            > "$out/bake-4m-memory.txt" &
        sampler=$!
    fi
    run bake-4m bake $tmp/slosh-s4m/sphere.case --out $tmp/slosh-c4m --device gpu
    if [ -n "${sampler:-}" ]; then
        kill "$sampler"
        echo "bake-4m: device memory used, MiB: idle $(head -1 "$out/bake-4m-memory.txt"), peak $(sort -n "$out/bake-4m-memory.txt" | tail -1)"
    fi
    ;;
bake-before)
    [ -x "${BEFORE:-}" ] || { echo "bake-before: BEFORE names no binary" >&2; exit 2; }
    # The GPU bake's stages, this binary against the baseline on the same card, alternated:
    # `bench bake` at 1M (its GPU table and the stages still on the CPU), then two 4M steps
    # through `slosh bake` (the second warm).
    [ -e $tmp/slosh-s4m2/sphere.case ] ||
        "$slosh" gen sphere --points $p4m --steps 2 --out $tmp/slosh-s4m2 > /dev/null
    for round in 1 2; do
        for side in before after; do
            bin=$slosh
            [ $side = before ] && bin=$BEFORE
            BIN=$bin run bake-$side-$round bench bake --points $p1m --runs 2 --threads $threads \
                --series 0 --out "$out/bake-$side-$round.md"
            rm -rf $tmp/slosh-c4m2
            BIN=$bin run bake-4m-$side-$round bake $tmp/slosh-s4m2/sphere.case \
                --out $tmp/slosh-c4m2 --device gpu
        done
    done
    ;;
series)
    [ -e $tmp/slosh-s64/sphere.case ] ||
        "$slosh" gen sphere --points $p1m --steps $series --out $tmp/slosh-s64 > /dev/null
    runs=()
    for jobs in $series_jobs; do runs+=("$slosh $jobs"); done
    [ -n "${BEFORE:-}" ] && runs+=("$BEFORE 8")
    for r in "${runs[@]}"; do
        read -r bin jobs <<< "$r"
        rm -rf $tmp/slosh-c64
        TIMEFORMAT="series, $(basename "$bin"), $jobs jobs: %R s wall, %U s user, %S s system"
        { time "$bin" bake $tmp/slosh-s64/sphere.case --out $tmp/slosh-c64 --device gpu \
            --jobs "$jobs" > "$out/series-$(basename "$bin")-$jobs.txt" 2>&1; } 2>&1 |
            tee -a "$out/series.txt"
    done
    ;;
before)
    [ -x "${BEFORE:-}" ] || { echo "before: BEFORE names no binary" >&2; exit 2; }
    gpu=(bench gpu --tables 4.6 --points $p100k,$p1m --max-iterations 2)
    for round in 1 2; do
        BIN=$BEFORE run gpu-before-$round "${gpu[@]}" --out "$out/gpu-before-$round.md"
        run gpu-after-$round "${gpu[@]}" --out "$out/gpu-after-$round.md"
    done
    BIN=$BEFORE run scrub-before bench scrub --points $p100k,$p1m --dir $tmp/slosh-sd-before \
        --out "$out/scrub-before.md"
    BIN=$BEFORE run scrub-4m-before bench scrub --points $p4m --steps 24 --distinct 4 \
        --pool-steps 8 --jumps 40 --dir $tmp/slosh-sd-before --out "$out/scrub-4m-before.md"
    ;;
esac
