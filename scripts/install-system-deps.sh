#!/usr/bin/env bash
# Debian libraries that the binary wheels need at import time:
# open3d -> libusb-1.0-0, libGL/libEGL, libgomp; pymeshlab -> libGL, libgomp, glib.
# Installs only what is missing; needs root (or sudo) and apt-get.
# --browser (used by `make test` only): also chromium, for the test that loads a run page with its
# interactive 3D view in headless Chromium; if it cannot be installed, that test is skipped, so
# this part only warns.
set -euo pipefail
pkgs=(libusb-1.0-0 libgomp1 libgl1 libegl1 libglib2.0-0 libx11-6)
if [ "${1:-}" = "--browser" ]; then
  command -v chromium >/dev/null && exit 0
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  if command -v apt-get >/dev/null; then
    echo "installing Debian package chromium (for the run-page browser test)" >&2
    { $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends chromium >/dev/null; } \
      || echo "topomatch: warning: could not install chromium; the run-page browser test will be skipped" >&2
  else
    echo "topomatch: warning: no apt-get; the run-page browser test will be skipped (install chromium)" >&2
  fi
  exit 0
fi
missing=()
for p in "${pkgs[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
[ ${#missing[@]} -eq 0 ] && exit 0
if ! command -v apt-get >/dev/null; then
  echo "topomatch: please install the system libraries: ${missing[*]}" >&2
  exit 1
fi
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
echo "installing Debian packages: ${missing[*]}" >&2
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
