#!/usr/bin/env bash
# What make test and make bench need beyond scripts/bootstrap.sh (make demo does not: it stays within about
# 20 minutes on a bare machine): the real-model catalogues of data=completion_installed and the Anny
# body-model cache. Run after scripts/bootstrap.sh (it uses $VENV). Each part is skipped when already there.
set -euo pipefail
VENV=${VENV:-.venv}

# Real models of the unseen categories (planes, cars, firearms, faucets, monitors) and more furniture for the
# completion data (data=completion_installed; datamodules/completion/catalogues.py): Debian packages downloaded
# with 'apt-get download' and unpacked with 'dpkg-deb -x' (never installed: some pull in a JRE or a game) into
#   LIT3D_CATALOGUES       (default ~/.cache/lit3d/catalogues), one folder per package;
#   LIT3D_CATALOGUE_PKGS   which ones (default below; torcs-data, 333 MB, adds nothing yet: its cars have no wheels).
# Only the files the readers use are unpacked. A package already there is skipped; one that cannot be had is
# reported and skipped, never failing the bootstrap. Measured here: download + unpack about 20 s for the
# three small ones (24 MB), about 50 s for ufoai-data (312 MB) and 2 min for flightgear-data-ai (287 MB).
CAT_DIR=${LIT3D_CATALOGUES:-$HOME/.cache/lit3d/catalogues}
CAT_PKGS=${LIT3D_CATALOGUE_PKGS:-crrcsim-data sweethome3d minetest-mod-homedecor ufoai-data flightgear-data-ai}
cat_members() {  # the tar members of a package that the readers need (empty: all)
  case "$1" in
    flightgear-data-ai) echo "--wildcards ./usr/share/games/flightgear/AI/Aircraft/*.ac ./usr/share/games/flightgear/AI/Aircraft/*.xml ./usr/share/doc/*" ;;
    ufoai-data) echo "./usr/share/games/ufoai/base/0models.pk3 --wildcards ./usr/share/doc/*" ;;
    torcs-data) echo "--wildcards ./usr/share/games/torcs/cars/* ./usr/share/doc/*" ;;
    *) echo "" ;;
  esac
}
cat_download() {  # apt-get download into folder $2; on a fresh machine (no package lists yet) update them once
  (cd "$2" && apt-get download -qq "$1" >/dev/null 2>&1) && return 0
  if [ -z "${CAT_UPDATED:-}" ] && [ "$(id -u)" = "0" ]; then
    CAT_UPDATED=1
    apt-get update -qq >/dev/null 2>&1 || true
    (cd "$2" && apt-get download -qq "$1" >/dev/null 2>&1) && return 0
  fi
  return 1
}
if command -v apt-get >/dev/null && command -v dpkg-deb >/dev/null; then
  for pkg in $CAT_PKGS; do
    [ -f "$CAT_DIR/$pkg/.unpacked" ] && continue
    tmp=$(mktemp -d)
    start=$(date +%s)
    if cat_download "$pkg" "$tmp" && deb=$(ls "$tmp"/*.deb 2>/dev/null | head -1) && [ -n "$deb" ]; then
      rm -rf "$CAT_DIR/$pkg" && mkdir -p "$CAT_DIR/$pkg"
      # shellcheck disable=SC2046
      if dpkg-deb --fsys-tarfile "$deb" | tar -x -C "$CAT_DIR/$pkg" $(cat_members "$pkg") 2>/dev/null; then
        touch "$CAT_DIR/$pkg/.unpacked"
        echo "bootstrap: catalogue $pkg: $(( $(stat -c %s "$deb") / 1000000 )) MB unpacked into $CAT_DIR/$pkg in $(( $(date +%s) - start )) s"
      else
        echo "bootstrap: catalogue $pkg: could not unpack; skipped (data=completion_installed goes without it)"
      fi
    else
      echo "bootstrap: catalogue $pkg: not available from apt here; skipped (data=completion_installed goes without it)"
    fi
    rm -rf "$tmp"
  done
else
  echo "bootstrap: no apt-get/dpkg-deb: real-model catalogues skipped (data=completion_installed needs them)"
fi

# The Anny body model builds its cache (about 790 MB, about 2.5 min on 2 cores) on its first start:
# once here, not inside a test or a training run. ANNY_CACHE_DIR moves it (default ~/.cache/anny).
echo "bootstrap: warming the Anny body-model cache (first time: about 2.5 min)"
"$VENV/bin/python" -c "import anny; anny.Anny()" >/dev/null 2>&1 \
  || { echo "bootstrap: the Anny body model failed to start; run: $VENV/bin/python -c 'import anny; anny.Anny()'" >&2; exit 1; }
touch "$VENV/.extras"
