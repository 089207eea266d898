#!/usr/bin/env bash
# The test suite, as CI runs it: every test once with Embree's default
# kernels (the widest ISA this CPU has), then every test that builds
# Embree (not the fuzzer) again with Embree forced to each of its ISAs this
# CPU runs (sse4.2, avx2, avx512), through SPLATRAY_EMBREE_CONFIG, then the
# octree's render suites on each of its SIMD paths (SPLATRAY_SIMD), then the
# conformance suite and the fuzzer with a fresh seed per run
# (SPLATRAY_SEED, from /dev/urandom), printed to replay. Floats that
# Embree computes are compared with a tolerance; candidate hits must stay
# identical.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

# cli/ holds argument parsing and printing only: every function of it
# under 60 lines (issue 40; the work is in the library's workflow/).
python3 scripts/fnlen.py --max 59 src/cli >/dev/null
# Generation's stages stay readable: no function in src/splat over 100
# lines (issue 54).
python3 scripts/fnlen.py --max 100 src/splat >/dev/null
# No import circle among src/'s files (a file names another that names it
# back, directly or through others): the graph and its circles printed.
# Generation's files never name their own facade (splat/mod.rs); the data
# types (data/) sit below reading, writing, generation and tracing: io,
# data and accel name nothing of generation.
python3 scripts/imports.py src --no-up splat --forbid io:splat --forbid data:splat \
    --forbid data:io --forbid accel:splat

# docs/DESIGN.md says how splatray is built now, to be read in one
# sitting: at most 40 KB (issue 56; the history and the measurements are
# in the notebook).
design_bytes=$(wc -c < docs/DESIGN.md)
[ "$design_bytes" -le 40000 ] || { echo "test.sh: docs/DESIGN.md is $design_bytes bytes, over 40,000" >&2; exit 1; }

# Every test, the documentation's examples included (`cargo test` runs
# the library's doc tests: src/lib.rs's front door and the modules').
cargo test --release

# The library's public API (issue 56): its documentation builds without a
# warning (a link to a private item; a public item without documentation:
# `missing_docs` warns without the `internals` feature), and at most 150
# items are public, counted from that documentation (scripts/api_count.py
# says what counts). In the release profile, as the builds above: in the
# dev profile cargo first checks every dependency again (55 s against 35 s
# here).
echo "== cargo doc: the public API"
rm -rf target/doc/splatray
RUSTDOCFLAGS="-D warnings" cargo doc --release --no-deps -q -p splatray
python3 scripts/api_count.py --max 150 target/doc/splatray

# Every benchmark compiles (`cargo test` never builds benches/).
echo "== cargo bench --no-run"
cargo bench --no-run -q

# The command line `cargo test` built (with the tests' features), run
# below where `cargo run` would compile the library once more without
# them (about 100 s on 2 cores).
bin=$(cargo test --release --no-run --message-format=json 2>/dev/null | python3 -c '
import json, sys
for line in sys.stdin:
    m = json.loads(line)
    t = m.get("target", {})
    if m.get("reason") == "compiler-artifact" and t.get("kind") == ["bin"] and not m["profile"]["test"]:
        print(m["executable"])' | grep '/splatray$' | head -n 1)
[ -x "$bin" ] || { echo "test.sh: cargo test built no splatray binary ('$bin')" >&2; exit 1; }

# What this CPU runs, from `splatray info`'s machine-readable lines: a line
# missing, empty or naming something unknown stops the run here (no pass
# silently runs zero times).
info=$("$bin" info)
info_line() {
    local v
    v=$(printf '%s\n' "$info" | sed -n "s/^$1: //p")
    if [ -z "$v" ]; then
        echo "test.sh: 'splatray info' printed no '$1:' line (or an empty one):" >&2
        printf '%s\n' "$info" >&2
        exit 1
    fi
    printf '%s' "$v"
}
isas=$(info_line embree-isas)
paths=$(info_line simd-paths)
for isa in $isas; do
    case "$isa" in sse4.2 | avx2 | avx512) ;; *) echo "test.sh: unknown Embree ISA '$isa' in info" >&2; exit 1 ;; esac
done
for path in $paths; do
    case "$path" in portable | avx2 | avx512) ;; *) echo "test.sh: unknown SIMD path '$path' in info" >&2; exit 1 ;; esac
done

# The library's examples of use (examples/, the front door only), their
# output checked: a cloud to an image, byte for byte the image `render`
# makes of the cloud given alone (the scene it used saved and handed to
# the example); rays cast on both backends, identical bit for bit (the
# example exits 1 otherwise); a small sweep of speed against error (exits 1
# when the backends' images differ or the error does not fall).
echo "== examples"
ex=$(mktemp -d)
trap 'rm -rf "$ex"' EXIT
"$bin" render scenes/data/milk.pcd --width 160 --height 120 \
    -o "$ex/cli.png" --save-scene "$ex/milk.toml"
cargo run --release -q --example cloud_to_image -- "$ex/milk.toml" "$ex/example.png"
cmp "$ex/cli.png" "$ex/example.png" || { echo "test.sh: cloud_to_image's image differs from render's" >&2; exit 1; }
cargo run --release -q --example cast_both -- scenes/data/milk.pcd
cargo run --release -q --example speed_error

# The targets that never build Embree (generation, tiles, reading, the
# command line without `compare`, `sweep` or `--backend`) are left out of
# the forced-ISA passes, where they would run the same code again. A target
# named here whose files come to name Embree, the registry's backends or a
# command that renders with every backend stops the run: take it off the
# list. Every other target (a new one too) runs under each ISA.
no_embree=" cli_input cli_splat far io_readers scans splatgen thin tiled tiled_disk "
targets=()
for f in tests/*.rs tests/*/main.rs; do
    name=$(basename "$f" .rs)
    src=$f
    [ "$name" = main ] && { src=$(dirname "$f"); name=$(basename "$src"); }
    [ "$name" = fuzz ] && continue
    case "$no_embree" in
        *" $name "*)
            if grep -rqiE 'embree|other_renderer|renderers\(|backends\(|registry|--backend|"compare"|"sweep"' "$src"; then
                echo "test.sh: $src names Embree or every backend: take '$name' off no_embree" >&2
                exit 1
            fi
            continue ;;
    esac
    targets+=(--test "$name")
done
[ "${#targets[@]}" -gt 10 ] || { echo "test.sh: found only ${#targets[@]} test targets" >&2; exit 1; }
# The library's generation tests (`splat::`, 80 of its 184 unit tests:
# 18.1 of the 18.9 s they take on 2 cores) are left out too: src/splat
# names neither Embree nor the backends (checked here).
if grep -rqiE 'embree|registry|accel::' src/splat; then
    echo "test.sh: src/splat names Embree or the backends: run its tests under each ISA" >&2
    exit 1
fi
for isa in $isas; do
    echo "== tests again with Embree forced to isa=$isa"
    SPLATRAY_EMBREE_CONFIG="isa=$isa" cargo test --release -q --lib "${targets[@]}" -- --skip splat::
done

# The octree's leaf filter on each SIMD path this CPU runs (SPLATRAY_SIMD):
# the suites whose renders use the default octree (the conformance suite
# builds every path at once through the registry).
for path in $paths; do
    echo "== octree suites again with SPLATRAY_SIMD=$path"
    SPLATRAY_SIMD="$path" cargo test --release -q --test far --test window --test hard_scenes --test contact --test render
done

# The randomised suites again with a fresh seed (the first pass ran their
# default seeds): the conformance rays and scenes, and the fuzzer's mutation
# stream. A fresh seed per run, from /dev/urandom, printed with the command
# that replays it; SPLATRAY_SEED set by the caller replays a run. (Seeds that
# failed once are kept as regression cases in the tests themselves.)
if [ -n "${SPLATRAY_SEED:-}" ]; then
    seed=$SPLATRAY_SEED
else
    seed=0x$(od -An -N8 -tx8 /dev/urandom | tr -d ' \n')
    [[ "$seed" =~ ^0x[0-9a-f]{16}$ ]] || { echo "test.sh: no fresh seed from /dev/urandom ('$seed')" >&2; exit 1; }
fi
echo "== conformance and fuzz again with SPLATRAY_SEED=$seed"
echo "   (replay: SPLATRAY_SEED=$seed cargo test --release --test conformance --test fuzz)"
SPLATRAY_SEED="$seed" cargo test --release -q --test conformance --test fuzz

# What this run covered (a path or ISA this CPU lacks is named, not skipped
# in silence).
untested() {
    local want=$1 have=$2 w missing=""
    for w in $want; do
        case " $have " in *" $w "*) ;; *) missing="$missing $w" ;; esac
    done
    printf '%s' "${missing:- none}"
}
echo "== covered: Embree ISAs (default, then forced): $isas; not tested on this CPU:$(untested "sse4.2 avx2 avx512" "$isas")"
echo "== covered: octree SIMD paths: $paths; not tested on this CPU:$(untested "portable avx2 avx512" "$paths")"
echo "== covered: seeds: the suites' defaults, then SPLATRAY_SEED=$seed"

# The Python package and the Dask driver (python/): the wheel built from
# this clone into python/.venv (scripts/python-package.sh; setup made the
# environment), then their tests against the package and the release
# binary built above, from python/ (which holds no package source, so the
# installed package is the one tested).
scripts/python-package.sh
echo "== the Python package's and the Dask driver's tests"
(cd python && .venv/bin/python -m pytest -q -p no:cacheprovider tests)
