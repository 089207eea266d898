#!/usr/bin/env bash
# Interaction latency of `splatray view` (docs/viewer.md): input to the first
# refreshed frame drawn, median and 95th percentile, over 40 drag steps in
# headless chromium (examples/viewer_latency.rs), on the bundled bunny and on
# a 1.5M-splat bunny. The big one is made once into out/ (git-ignored):
# 10M points sampled from the bunny mesh, splatted with epsilon 2e-5
# (1,531,550 splats; about 3 minutes on 2 cores, 360 MB of points removed
# after). Other scenes or clouds: give them as arguments ("big" names that one).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
cargo build --release --bin splatray --example viewer_latency
bin=target/release/splatray
scenes=("$@")
[ ${#scenes[@]} -gt 0 ] || scenes=(scenes/bunny.toml big)
for s in "${scenes[@]}"; do
    if [ "$s" = big ]; then
        s=out/bunny-1.5m-splats.ply
        if [ ! -e "$s" ]; then
            mkdir -p out
            "$bin" sample scenes/data/bunny-mesh.ply -n 10000000 -o out/bunny-10m.ply
            "$bin" splat out/bunny-10m.ply --epsilon 0.00002 -o "$s"
            rm -f out/bunny-10m.ply
        fi
    fi
    target/release/examples/viewer_latency "$s" --drags 40 | head -1
done
