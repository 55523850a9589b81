#!/usr/bin/env bash
# Installs what vmap needs on Debian 12 (idempotent: skips what is there), then fetches the
# model data (scripts/fetch-models.sh) and the viewer's three.js and its browser test's
# puppeteer-core (scripts/fetch-web.sh) into git-ignored folders; --no-models skips both.
# Usage: scripts/setup.sh [--no-models]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"

pkgs=(build-essential cmake ninja-build pkg-config
      libtbb-dev libembree-dev libcli11-dev libfmt-dev nlohmann-json3-dev libnanoflann-dev
      libstb-dev libgtest-dev libgmock-dev libbenchmark-dev zlib1g-dev ca-certificates
      libstreamvbyte-dev  # the .vmap file's link lists (delta StreamVByte)
      libcpp-httplib-dev chromium  # `vmap view` serves with cpp-httplib; its test drives chromium
      python3-dev python3-pybind11 pybind11-dev python3-numpy python3-pytest  # the Python module
      clang-14 libclang-rt-14-dev  # clang's libFuzzer and sanitizer runtimes (scripts/fuzz.sh)
      libopenmpi-dev openmpi-bin)  # mpirun -np N vmap build (src/mpi/; optional at build time)
# npm fetches the dragon; the Debian package conflicts with a NodeSource nodejs, so only when absent.
command -v npm >/dev/null || pkgs+=(npm)

missing=()
for p in "${pkgs[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
    echo "setup: installing ${missing[*]}" >&2
    sudo_cmd=()
    [[ $(id -u) -ne 0 ]] && sudo_cmd=(sudo)
    "${sudo_cmd[@]}" apt-get update -qq
    DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
    echo "setup: Debian packages present" >&2
fi

if [[ "${1:-}" != "--no-models" ]]; then
    "$here/fetch-models.sh"
    "$here/fetch-web.sh"
fi
