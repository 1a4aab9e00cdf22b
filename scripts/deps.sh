#!/usr/bin/env bash
# Installs what voyage needs from Debian beyond Rust itself:
#   cmake, g++  — build the CharLS (JPEG-LS) decoder.
#   mesa-vulkan-drivers, libvulkan1 — Mesa's CPU Vulkan driver (lavapipe), so the wgpu
#     renderer runs (and is tested) where there is no GPU.
#   libxkbcommon-x11-0, libx11-xcb1 — what the window (winit on X11) loads at run time.
#   xvfb, xdotool — a virtual display and mouse/keyboard driver for the window's tests.
#   chromium — headless, renders report.html in its test.
# Idempotent; skips apt when everything is already there. Needs root (or sudo) for apt.
set -euo pipefail
need=()
command -v cmake >/dev/null 2>&1 || need+=(cmake)
command -v g++ >/dev/null 2>&1 || need+=(g++)
command -v pkg-config >/dev/null 2>&1 || need+=(pkg-config)
ls /usr/lib/*/libvulkan.so.1 >/dev/null 2>&1 || need+=(libvulkan1)
ls /usr/share/vulkan/icd.d/lvp_icd.*.json >/dev/null 2>&1 || need+=(mesa-vulkan-drivers)
ls /usr/lib/*/libxkbcommon-x11.so.0 >/dev/null 2>&1 || need+=(libxkbcommon-x11-0)
ls /usr/lib/*/libX11-xcb.so.1 >/dev/null 2>&1 || need+=(libx11-xcb1)
command -v Xvfb >/dev/null 2>&1 || need+=(xvfb)
command -v xvfb-run >/dev/null 2>&1 || need+=(xvfb)
command -v xdotool >/dev/null 2>&1 || need+=(xdotool)
command -v xauth >/dev/null 2>&1 || need+=(xauth)
command -v chromium >/dev/null 2>&1 || need+=(chromium)
if [ ${#need[@]} -eq 0 ]; then
  exit 0
fi
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
echo "installed: ${need[*]}"
