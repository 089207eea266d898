#!/usr/bin/env bash
# The Python package into the project's virtual environment: python/.venv
# made (again) when python/requirements.txt changed, then the package
# (python/splatray-py: the native module with the `splatray` command line,
# the pure-Python part and the Dask driver) built from this clone by
# maturin as a stripped abi3 wheel, made self-contained by `auditwheel
# repair --strip` (Embree 4 and TBB copied into it, stripped, found
# through $ORIGIN, tagged with the manylinux policy it meets; the ELF
# patching done by scripts/lief-patchelf) into target/wheels/, and
# installed into python/.venv. auditwheel and lief come from
# requirements.txt.
# scripts/setup.sh and scripts/test.sh run it; cargo shares target/ with
# the root package, so the library is compiled once for both.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
say() { printf 'python: %s\n' "$*" >&2; }

venv=python/.venv
if [ ! -x "$venv/bin/python" ] || ! cmp -s python/requirements.txt "$venv/requirements.txt"; then
    # Debian's python3 makes no virtual environment without python3-venv.
    if ! python3 -c 'import ensurepip, venv' >/dev/null 2>&1; then
        say "installing python3-venv"
        if [ "$(id -u)" -eq 0 ]; then sudo=(); else sudo=(sudo); fi
        "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq >/dev/null
        "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3-venv >/dev/null
    fi
    say "making $venv from python/requirements.txt"
    rm -rf "$venv"
    python3 -m venv "$venv"
    "$venv/bin/pip" install -q --disable-pip-version-check -r python/requirements.txt
    cp python/requirements.txt "$venv/requirements.txt"
fi
say "building the splatray wheel (maturin, auditwheel repair) and installing it into $venv"
rm -rf target/wheels/splatray-*.whl target/wheels/linux
"$venv/bin/maturin" build --release --quiet -m python/splatray-py/Cargo.toml \
    -i "$venv/bin/python" --out target/wheels/linux >&2
# The module's rpath (python/splatray-py/build.rs) is where auditwheel
# finds Embree. --strip: binutils' `strip -s` on the copies, before they are
# patched (TBB, as embreex ships it, carries 2.1 MB of debug info and
# symbols). --patcher lief-patchelf: scripts/lief-patchelf renames and sets
# the search path with LIEF, which keeps the libraries' sizes where
# patchelf adds 2 MiB of zeros to each (6.3 MB; docs/notes/python.md).
command -v strip >/dev/null || { say "strip (binutils) is needed: apt-get install binutils"; exit 1; }
PATH="$root/scripts:$root/$venv/bin:$PATH" "$venv/bin/auditwheel" repair --strip \
    --patcher lief-patchelf -w target/wheels \
    target/wheels/linux/splatray-*.whl 2>&1 | grep -E '^(Fixed-up wheel written|WARNING|ERROR)' >&2 || true
rm -rf target/wheels/linux
whl=$(ls target/wheels/splatray-*manylinux*.whl 2>/dev/null || true)
[ -n "$whl" ] || { say "auditwheel repair wrote no manylinux wheel into target/wheels"; exit 1; }
"$venv/bin/pip" install -q --disable-pip-version-check --force-reinstall --no-deps "$whl"
