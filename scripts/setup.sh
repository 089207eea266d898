#!/usr/bin/env bash
# Set-up for splatray on a fresh Debian/Ubuntu machine. Idempotent, and fast
# when everything is already present. It installs what is missing:
#   1. libclang, which bindgen (inside embree4-sys) needs at build time, and
#      prlimit and unshare (util-linux), which tests/limits.rs and
#      tests/tiled_disk.rs run the binary under, and strip (binutils), which
#      strips the libraries the wheel carries;
#   2. Embree 4: nothing to do when EMBREE_DIR or `pkg-config embree4` already
#      provides it; otherwise the system's package when the distribution has
#      one; otherwise the libraries of the PyPI wheel embreex==4.4.0.post1,
#      downloaded with pip (nothing is installed into Python) and extracted into
#      the project's git-ignored .embree/lib;
#   3. python/.venv (python3-venv from apt when Python lacks it) with
#      python/requirements.txt (auditwheel and lief among them), and
#      the Python package: a self-contained manylinux wheel in
#      target/wheels/ (Embree and TBB inside), installed into python/.venv;
#   4. Debian's chromium, the headless browser tests/viewer.rs drives
#      `splatray view` with.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
say() { printf 'setup: %s\n' "$*" >&2; }

as_root() {
  if [ "$(id -u)" -eq 0 ]; then "$@"; elif command -v sudo >/dev/null 2>&1; then sudo "$@"; else
    say "need root to run: $*"; exit 1; fi
}

apt_updated=0
apt_install() {
  if ! command -v apt-get >/dev/null 2>&1; then
    say "apt-get not found: install $* with your package manager"; exit 1
  fi
  if [ "$apt_updated" -eq 0 ]; then
    as_root env DEBIAN_FRONTEND=noninteractive apt-get update -qq >/dev/null
    apt_updated=1
  fi
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@" >/dev/null
}

# --- 1. libclang -------------------------------------------------------------
have_libclang() {
  [ -n "${LIBCLANG_PATH:-}" ] && return 0
  local g
  for g in '/usr/lib/llvm-*/lib/libclang.so' '/usr/lib/llvm-*/lib/libclang-[0-9]*.so*' '/usr/lib/*/libclang-[0-9]*.so*'; do
    compgen -G "$g" >/dev/null && return 0
  done
  return 1
}
if have_libclang; then
  say "libclang: present"
else
  say "libclang: installing libclang-dev"
  apt_install libclang-dev
fi

# --- 1b. prlimit, unshare (util-linux): tests/limits.rs, tests/tiled_disk.rs -
if command -v prlimit >/dev/null 2>&1 && command -v unshare >/dev/null 2>&1; then
  say "prlimit, unshare: present"
else
  say "prlimit, unshare: installing util-linux"
  apt_install util-linux
fi

# --- 1c. strip (binutils): auditwheel repair --strip, the wheel's libraries -
if command -v strip >/dev/null 2>&1; then
  say "strip: present"
else
  say "strip: installing binutils"
  apt_install binutils
fi

# --- 4. chromium (tests/viewer.rs) ------------------------------------------
if [ -x /usr/bin/chromium ]; then
  say "chromium: present"
else
  say "chromium: installing Debian's chromium (the viewer's browser test)"
  apt_install chromium
fi

# --- 2. Embree 4 -------------------------------------------------------------
embree() {
  local_dir="$root/.embree/lib"
  if [ -n "${EMBREE_DIR:-}" ]; then
    say "embree4: using EMBREE_DIR=$EMBREE_DIR"
    return 0
  fi
  if command -v pkg-config >/dev/null 2>&1 && pkg-config --exists embree4 2>/dev/null; then
    say "embree4: system $(pkg-config --modversion embree4) (pkg-config)"
    return 0
  fi
  if [ -e "$local_dir/libembree4.so" ]; then
    say "embree4: present in .embree/lib"
    return 0
  fi
  # A distribution that packages Embree 4 (Debian 13 and later) gets it from apt.
  if command -v apt-cache >/dev/null 2>&1; then
    cand=$(apt-cache policy libembree-dev 2>/dev/null | awk '/Candidate:/ {print $2}')
    case "$cand" in
      4.*) say "embree4: installing the system's libembree-dev $cand"
           apt_install libembree-dev pkg-config
           return 0 ;;
    esac
  fi

  say "embree4: fetching the libraries of the PyPI wheel embreex==4.4.0.post1"
  py=$(command -v python3 || true)
  [ -n "$py" ] || { say "python3 with pip is needed to fetch Embree 4"; exit 1; }
  tmp=$(mktemp -d)
  trap 'rm -rf "$tmp"' EXIT
  "$py" -m pip download --quiet --no-deps --only-binary=:all: \
    --python-version 3.11 --implementation cp --abi cp311 \
    --platform manylinux_2_28_x86_64 \
    embreex==4.4.0.post1 -d "$tmp" >&2
  whl=$(ls "$tmp"/embreex-*.whl)
  "$py" - "$whl" "$tmp/x" <<'PY'
import sys, zipfile
with zipfile.ZipFile(sys.argv[1]) as z:
    for n in z.namelist():
        if n.startswith("embreex.libs/"):
            z.extract(n, sys.argv[2])
PY
  mkdir -p "$local_dir.partial"
  cp "$tmp"/x/embreex.libs/* "$local_dir.partial/"
  lib=$(cd "$local_dir.partial" && ls libembree4-*.so.4 | head -n1)
  ln -sf "$lib" "$local_dir.partial/libembree4.so"
  rm -rf "$local_dir"
  mkdir -p "$(dirname "$local_dir")"
  mv "$local_dir.partial" "$local_dir"
  say "embree4: installed $lib into .embree/lib"
}
embree

# --- 3. The Python package -----------------------------------------------------
# python/.venv with python/requirements.txt (maturin, auditwheel, lief,
# numpy, pytest, Dask), then the package (python/splatray-py) built from the
# clone by maturin, repaired by auditwheel into a manylinux wheel that
# carries Embree and TBB (target/wheels/) and installed into it:
# scripts/python-package.sh. `pip install target/wheels/*manylinux*.whl`
# elsewhere gives the package and the `splatray` command.
"$root/scripts/python-package.sh"
