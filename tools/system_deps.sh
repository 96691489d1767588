#!/usr/bin/env bash
# Install the system packages rce_gtsam needs beyond Python, or say in one line how to.
#   libusb-1.0-0                : pyrealsense2 (reading RealSense .bag/.db3 recordings) loads libusb-1.0.so.0
#   chromium, chromium-driver   : the browser test of `rce annotate` (Selenium drives Debian's chromium)
#   python3-venv                : `python3 -m venv` (only where the interpreter lacks ensurepip)
# As root with apt-get: installs what is missing. Otherwise: prints the command and exits 0, so `make test`
# still runs (the tests that need a missing package skip and say why).
set -euo pipefail
missing=()
have_lib() { ldconfig -p 2>/dev/null | grep -q "$1" || [ -e "/usr/lib/x86_64-linux-gnu/$1" ] || [ -e "/usr/lib/$1" ]; }
have_lib libusb-1.0.so.0 || missing+=(libusb-1.0-0)
command -v chromium >/dev/null 2>&1 || missing+=(chromium)
# `python3 -m venv` needs ensurepip, which Debian ships separately in python3-venv
"${PYTHON:-python3}" -c "import ensurepip" >/dev/null 2>&1 || missing+=(python3-venv)
command -v chromedriver >/dev/null 2>&1 || missing+=(chromium-driver)
[ ${#missing[@]} -eq 0 ] && exit 0
if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "installing system packages: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
elif command -v apt-get >/dev/null 2>&1; then
  echo "rce_gtsam: missing system packages; install them with: sudo apt-get install -y ${missing[*]}" >&2
else
  echo "rce_gtsam: missing system packages (Debian names): ${missing[*]}; install them with your package manager" >&2
fi
