#!/usr/bin/env bash
# Debian libraries that the binary wheels need at import time:
# open3d -> libusb-1.0-0, libGL/libEGL, libgomp; pymeshlab -> libGL, libgomp, glib.
# Installs only what is missing; needs root (or sudo) and apt-get.
set -euo pipefail
pkgs=(libusb-1.0-0 libgomp1 libgl1 libegl1 libglib2.0-0 libx11-6)
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
