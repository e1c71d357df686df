#!/usr/bin/env bash
# Install what baselines.py needs; idempotent, non-interactive.
#
#   OpenVDB 10.0.1 Python binding: Debian's python3-openvdb (module `pyopenvdb`, for
#     /usr/bin/python3 only), with python3-numpy.
#   Open3D: from PyPI (open3d-cpu, else open3d) into a virtual environment made from
#     /usr/bin/python3 with --system-site-packages, so one interpreter sees both libraries.
#     Default place: benches/compare/.venv (git-ignored); override with IMPRINT_BASELINES_VENV.
#     baselines.py re-executes itself under that venv when it exists.
#   Taichi (cloth section's baseline, cloth_taichi.py): from PyPI (taichi) into the same venv;
#     cloth_taichi.py re-executes itself under it the same way.
#
# Always exits 0: a baseline that cannot be installed is reported here and by baselines.py
# as unavailable, and the benchmarks run without it.
set -u
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
VENV="${IMPRINT_BASELINES_VENV:-$HERE/.venv}"
SYS_PY=/usr/bin/python3
log() { echo "[compare/install] $*"; }
export DEBIAN_FRONTEND=noninteractive

# ---- Debian packages
APT_PKGS=(python3-openvdb python3-numpy python3-venv libusb-1.0-0 libgomp1 libgl1)
missing=()
for p in "${APT_PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  log "apt: all present (${APT_PKGS[*]})"
elif ! command -v apt-get >/dev/null 2>&1; then
  log "apt: apt-get not found; cannot install ${missing[*]}"
elif [ "$(id -u)" -ne 0 ]; then
  log "apt: not root; cannot install ${missing[*]} (run as root)"
else
  log "apt: installing ${missing[*]}"
  apt-get update -q >/dev/null 2>&1 || log "apt: 'apt-get update' failed (continuing)"
  if ! apt-get install -y -q --no-install-recommends "${missing[@]}" >/tmp/imprint-compare-apt.log 2>&1; then
    log "apt: installing all at once failed (see /tmp/imprint-compare-apt.log); trying one by one"
    for p in "${missing[@]}"; do
      apt-get install -y -q --no-install-recommends "$p" >>/tmp/imprint-compare-apt.log 2>&1 \
        && log "apt: installed $p" \
        || log "apt: FAILED $p: $(tail -n 1 /tmp/imprint-compare-apt.log)"
    done
  else
    log "apt: installed ${missing[*]}"
  fi
fi

# ---- virtual environment with Open3D
if [ ! -x "$SYS_PY" ]; then
  log "venv: $SYS_PY not found; OpenVDB (Debian) and the venv both need it; Open3D not installed"
else
  if [ ! -x "$VENV/bin/python" ]; then
    if "$SYS_PY" -m venv --system-site-packages "$VENV" >/tmp/imprint-compare-venv.log 2>&1; then
      log "venv: created $VENV (from $SYS_PY, --system-site-packages)"
    else
      log "venv: FAILED to create $VENV: $(tail -n 1 /tmp/imprint-compare-venv.log)"
    fi
  else
    log "venv: present at $VENV"
  fi
  if [ -x "$VENV/bin/python" ]; then
    if "$VENV/bin/python" -c "import open3d" >/dev/null 2>&1; then
      log "pip: open3d already importable"
    else
      ok=0
      for pkg in open3d-cpu open3d; do
        log "pip: installing $pkg into $VENV"
        if "$VENV/bin/python" -m pip install -q --disable-pip-version-check "$pkg" \
             >/tmp/imprint-compare-pip.log 2>&1 \
           && "$VENV/bin/python" -c "import open3d" >>/tmp/imprint-compare-pip.log 2>&1; then
          log "pip: installed $pkg"; ok=1; break
        fi
        log "pip: $pkg FAILED: $(grep -E 'ERROR|Error' /tmp/imprint-compare-pip.log | tail -n 2 | tr '\n' ' ')"
      done
      [ $ok -eq 1 ] || log "pip: Open3D unavailable; baselines.py will report it as such"
    fi
    if "$VENV/bin/python" -c "import taichi" >/dev/null 2>&1; then
      log "pip: taichi already importable"
    else
      log "pip: installing taichi into $VENV"
      if "$VENV/bin/python" -m pip install -q --disable-pip-version-check taichi \
           >/tmp/imprint-compare-pip-taichi.log 2>&1 \
         && "$VENV/bin/python" -c "import taichi" >>/tmp/imprint-compare-pip-taichi.log 2>&1; then
        log "pip: installed taichi"
      else
        log "pip: taichi FAILED: $(grep -E 'ERROR|Error' /tmp/imprint-compare-pip-taichi.log | tail -n 2 | tr '\n' ' '); the cloth section will report Taichi as not run"
      fi
    fi
  fi
fi

# ---- what baselines.py will see
PY="$SYS_PY"; [ -x "$VENV/bin/python" ] && PY="$VENV/bin/python"
if [ -x "$PY" ]; then
  IMPRINT_BASELINES_NO_REEXEC=1 "$PY" "$HERE/baselines.py" --versions 2>&1 | sed 's/^/[compare\/install] /' || true
  TI_VER="$("$PY" -c "import taichi; print('.'.join(map(str, taichi.__version__)))" 2>/dev/null | grep -v '^\[Taichi\]')"
  if [ -n "$TI_VER" ]; then log "taichi $TI_VER (cloth_taichi.py)"; else log "taichi: not importable by $PY"; fi
fi
exit 0
