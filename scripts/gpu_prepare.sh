#!/bin/bash
# Makes, in the repo's root, the ignored folders a GPU host's commands carry (the host has no
# toolchain, no network and no Vulkan loader):
#   .gl   the Vulkan and EGL loaders (the device README's recipe);
#   .whl  pysplashsurf for `bench bake`'s peer (numpy is there already);
#   .dev  a stripped release binary, slosh.
# Then each device command carries [".gl", ".whl", ".dev"] and runs
#   scripts/gpu_figures.sh OUT scrub|scale|bake
# which unpacks .gl and installs .whl itself.
set -euo pipefail
cd "$(dirname "$0")/.."
mkdir -p .gl .whl .dev /tmp/amd64/partial
if ! ls .gl/libvulkan1_*.deb > /dev/null 2>&1; then
    o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
    # shellcheck disable=SC2086
    apt-get $o update > /dev/null
    # shellcheck disable=SC2086
    (cd .gl && apt-get $o download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
fi
if ! ls .whl/pysplashsurf-*.whl > /dev/null 2>&1; then
    python3 -m pip download --quiet --no-deps --only-binary=:all: --python-version 3.12 \
        --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 \
        --platform manylinux2014_x86_64 -d .whl pysplashsurf==0.14.1
fi
cargo build --release --locked --bin slosh
target=${CARGO_TARGET_DIR:-target}
strip -o .dev/slosh "$target/release/slosh"
du -sh .gl .whl .dev
