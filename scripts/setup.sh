#!/usr/bin/env bash
# Idempotent set-up on a fresh Debian/Ubuntu machine: system libraries, a .venv in the repository,
# PyTorch (the build that fits this machine), and this package with its test extras.
#
#   ORCA_TORCH   pip requirement(s) for PyTorch, installed before anything else so no dependency pulls
#                another build. Default "torch==2.13.0": on the project's CPU machines this resolves to a
#                local CPU wheel; on a Linux machine with an NVIDIA GPU, PyPI's torch==2.13.0 is a CUDA
#                build. For a specific CUDA version use PyTorch's index, e.g.
#                ORCA_TORCH="torch==2.13.0 --index-url https://download.pytorch.org/whl/cu128"
#   ORCA_VENV    where the virtual environment lives (default: .venv in the repository)
#   ORCA_CONSTRAINTS  pip constraints file (default: constraints.txt, the known-good versions of every package but
#                torch); ORCA_CONSTRAINTS="" installs the newest versions pyproject.toml allows
#   PYTHON       interpreter to create it with (default: python3; 3.10 or newer)
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${ORCA_VENV:-$ROOT/.venv}"
TORCH_SPEC="${ORCA_TORCH:-torch==2.13.0}"
PYTHON="${PYTHON:-python3}"
CONSTRAINTS="${ORCA_CONSTRAINTS-$ROOT/constraints.txt}"
CONSTRAINT_ARGS=()
[ -z "$CONSTRAINTS" ] || CONSTRAINT_ARGS=(-c "$CONSTRAINTS")
say() { printf '\033[1m[setup]\033[0m %s\n' "$*" >&2; }

# open3d loads libusb-1.0 at import time; Debian's minimal images lack it.
if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
    say "installing Debian package libusb-1.0-0 (needed by open3d)"
    SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    export DEBIAN_FRONTEND=noninteractive
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq libusb-1.0-0 >/dev/null
fi

if [ ! -x "$VENV/bin/python" ]; then
    say "creating virtual environment $VENV"
    "$PYTHON" -m venv "$VENV"
fi
# venv installs pip last: a creation stopped half way (Ctrl-C, a killed CI job) leaves an environment without it
if ! "$VENV/bin/python" -m pip --version >/dev/null 2>&1; then
    say "$VENV has no pip (its creation was interrupted): installing it"
    "$VENV/bin/python" -m ensurepip --upgrade --default-pip >/dev/null
fi

# Re-install only when what defines the environment changed.
STAMP="$VENV/.orca-setup-stamp"
DEFINITION=("$ROOT/pyproject.toml" "${BASH_SOURCE[0]}" ${CONSTRAINTS:+"$CONSTRAINTS"})
WANT="$(cat "${DEFINITION[@]}" | sha256sum | cut -c1-16) $TORCH_SPEC"
if [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$WANT" ]; then
    say "environment up to date ($VENV)"
    exit 0
fi

PIP=("$VENV/bin/python" -m pip --disable-pip-version-check --quiet)
say "installing PyTorch: $TORCH_SPEC"
# shellcheck disable=SC2086  # the spec may carry pip options such as --index-url
"${PIP[@]}" install "${CONSTRAINT_ARGS[@]}" $TORCH_SPEC
say "installing orca-capture, its test tools and mitsuba (first run: a few minutes)"
[ -z "$CONSTRAINTS" ] || say "versions from $CONSTRAINTS"
"${PIP[@]}" install "${CONSTRAINT_ARGS[@]}" -e "$ROOT[test,synth]"
"$VENV/bin/python" - <<'PY'
import torch, open3d, mitsuba, rawpy, pycolmap, cv2  # noqa: F401  fail here, not in the middle of a run
# opencv-python-headless installed after opencv-contrib-python-headless replaces its cv2 with one without contrib
assert hasattr(getattr(cv2, "ximgproc", None), "guidedFilter"), \
    "cv2 lacks ximgproc: pip install --force-reinstall --no-deps opencv-contrib-python-headless==<cv2's version>"
print(f"[setup] torch {torch.__version__} (CUDA available: {torch.cuda.is_available()})")
PY
echo "$WANT" > "$STAMP"
say "done"
