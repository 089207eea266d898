#!/usr/bin/env bash
# The Python package into the project's virtual environment: python/.venv
# made (again) when python/requirements.txt changed, then the package
# (python/splatray-py: the native module, the pure-Python part and the Dask
# driver) built from this clone by maturin as an abi3 wheel into
# target/wheels/ and installed into python/.venv. scripts/setup.sh and
# scripts/test.sh run it; cargo shares target/ with the root package, so
# the library is compiled once for both.
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
say "building the splatray wheel (maturin) and installing it into $venv"
rm -f target/wheels/splatray-*.whl
"$venv/bin/maturin" build --release --quiet -m python/splatray-py/Cargo.toml \
    -i "$venv/bin/python" --out target/wheels >&2
"$venv/bin/pip" install -q --disable-pip-version-check --force-reinstall --no-deps target/wheels/splatray-*.whl
