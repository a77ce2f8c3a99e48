#!/usr/bin/env bash
# Install what the emulated firmware build needs (Debian packages): the Arm bare-metal
# cross compiler, newlib with its semihosting library rdimon, and QEMU's Arm system
# emulator with its TCG plugins (instruction counting). Installs only when run as root and
# something is missing; otherwise it reports what is missing and exits 1.
# Idempotent: a second run only checks.
set -euo pipefail

need_apt=()
command -v arm-none-eabi-gcc >/dev/null 2>&1 || need_apt+=(gcc-arm-none-eabi)
# newlib: the C library and the semihosting spec file of arm-none-eabi-gcc
if ! command -v arm-none-eabi-gcc >/dev/null 2>&1 \
   || [ ! -f "$(arm-none-eabi-gcc -print-file-name=rdimon.specs)" ]; then
    need_apt+=(libnewlib-arm-none-eabi)
fi
command -v qemu-system-arm >/dev/null 2>&1 || need_apt+=(qemu-system-arm)

if [ ${#need_apt[@]} -gt 0 ]; then
    if [ "$(id -u)" = 0 ]; then
        echo "setup_firmware: installing Debian packages: ${need_apt[*]}"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${need_apt[@]}"
    else
        echo "setup_firmware: missing ${need_apt[*]}; install them (as root: apt-get install ${need_apt[*]})" >&2
        exit 1
    fi
fi
