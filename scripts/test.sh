#!/usr/bin/env bash
# The test suite, as CI runs it: every test once with Embree's default
# kernels (the widest ISA this CPU has), then every test but the fuzzer
# again with Embree forced to each of its ISAs this CPU runs (sse4.2, avx2,
# avx512), through SPLATRAY_EMBREE_CONFIG, then the octree's render suites
# on each of its SIMD paths (SPLATRAY_SIMD). Floats that Embree computes are
# compared with a tolerance; candidate hits must stay identical.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

cargo test --release

targets=()
for f in tests/*.rs tests/*/main.rs; do
    name=$(basename "$f" .rs)
    [ "$name" = main ] && name=$(basename "$(dirname "$f")")
    [ "$name" = fuzz ] && continue
    targets+=(--test "$name")
done
isas=$(cargo run --release -q -- info | sed -n 's/^cpu isas //p')
for isa in $isas; do
    case "$isa" in sse4.2 | avx2 | avx512) ;; *) continue ;; esac
    echo "== tests again with Embree forced to isa=$isa"
    SPLATRAY_EMBREE_CONFIG="isa=$isa" cargo test --release -q --lib "${targets[@]}"
done

# The octree's leaf filter on each SIMD path this CPU runs (SPLATRAY_SIMD):
# the suites whose renders use the default octree (the conformance suite
# builds every path at once through the registry).
paths=$(cargo run --release -q -- info | sed -n 's/^simd .*this CPU runs: \([a-z0-9 ]*\);.*/\1/p')
for path in $paths; do
    echo "== octree suites again with SPLATRAY_SIMD=$path"
    SPLATRAY_SIMD="$path" cargo test --release -q --test far --test window --test hard_scenes --test contact --test render
done

# The Python package and the Dask driver (python/): the wheel built from
# this clone into python/.venv (scripts/python-package.sh; setup made the
# environment), then their tests against the package and the release
# binary built above, from python/ (which holds no package source, so the
# installed package is the one tested).
scripts/python-package.sh
echo "== the Python package's and the Dask driver's tests"
(cd python && .venv/bin/python -m pytest -q -p no:cacheprovider tests)
