#!/usr/bin/env bash
# System libraries graphnav's wheels need on Debian/Ubuntu: open3d loads libusb-1.0.so.0.
# Installs them when running as root and they are missing; otherwise prints the exact command.
set -euo pipefail
missing=()
if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then missing+=(libusb-1.0-0); fi
[ ${#missing[@]} -eq 0 ] && exit 0
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  echo "installing system packages: ${missing[*]}" >&2
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq >&2
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >&2
else
  echo "error: missing system packages: ${missing[*]}" >&2
  echo "run:   sudo apt-get update && sudo apt-get install -y ${missing[*]}" >&2
  exit 1
fi
