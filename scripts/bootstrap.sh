#!/usr/bin/env bash
# Create .venv and install lit3d with every extra and the test tools (lit3d[all,dev]: the body model, SLURM,
# W&B, TensorBoard, Optuna); make sure the EGL libraries are there. This is all
# that make demo needs; make test and make bench also run scripts/bootstrap_extras.sh (the real-model
# catalogues and the Anny body-model cache, about 5 min on a bare machine).
#   TORCH_SPEC   torch requirement (default torch==2.13.0, the CPU wheel). GPU users:
#                TORCH_SPEC="torch" (or a CUDA build index via PIP_INDEX_URL) make demo
#   VENV         virtual environment folder (default .venv)
#   PYTHON       interpreter used to create it (default python3)
set -euo pipefail
VENV=${VENV:-.venv}
TORCH_SPEC=${TORCH_SPEC:-torch==2.13.0}
PYTHON=${PYTHON:-python3}
EGL_PKGS="libegl1 libgl1 libgl1-mesa-dri libegl-mesa0"

have_egl() {
  ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' && ldconfig -p 2>/dev/null | grep -q 'libEGL_mesa.so.0\|libEGL_nvidia.so.0' \
    && { [ -d /usr/lib/x86_64-linux-gnu/dri ] || [ -d /usr/lib/dri ] || ldconfig -p | grep -q 'libEGL_nvidia'; }
}

if ! have_egl; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null; then
    echo "bootstrap: installing EGL libraries ($EGL_PKGS)"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $EGL_PKGS) >/dev/null
  else
    echo "bootstrap: EGL libraries missing: run 'sudo apt-get install $EGL_PKGS' and retry" >&2
    exit 1
  fi
fi

# Real CAD furniture for the completion data (data.source=sweethome3d, used by make demo): CC0 / CC-BY
# models, about 120 MB. Optional: without it the demo falls back to procedural shapes and says so.
SH3D_PKG=sweethome3d-furniture
if ! compgen -G "/usr/share/sweethome3d/furniture/*.sh3f" >/dev/null; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null; then
    echo "bootstrap: installing real furniture models ($SH3D_PKG)"
    (DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $SH3D_PKG >/dev/null 2>&1 \
      || { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $SH3D_PKG; } >/dev/null 2>&1) \
      || echo "bootstrap: could not install $SH3D_PKG; the completion demo will use procedural shapes"
  else
    echo "bootstrap: optional: 'sudo apt-get install $SH3D_PKG' gives the completion demo real furniture"
  fi
fi

if [ ! -x "$VENV/bin/python" ]; then
  echo "bootstrap: creating $VENV"
  "$PYTHON" -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --upgrade pip >/dev/null 2>&1 || true
echo "bootstrap: installing $TORCH_SPEC and lit3d[all,dev]"
"$VENV/bin/pip" install -q "$TORCH_SPEC"
"$VENV/bin/pip" install -q -e ".[all,dev]"  # all: make demo and make test use every extra
# piq: the colour image measures of the quality features (FSIMc, VIF, GMSD, HaarPSI, MDSI, VSI of coloured point
# clouds, lit3d.metrics.image.colour_measures) and the reference of tests/metrics/test_fsim_piq.py. --no-deps: piq requires
# torchvision, whose PyPI wheels are CUDA builds that replace the CPU torch (or fail to load beside it); the six
# measures need only torch. Not a package dependency for that reason.
"$VENV/bin/pip" install -q --no-deps "piq==0.8.0" || echo "bootstrap: piq not installed: coloured point-cloud pairs need it"
touch "$VENV/.installed"
