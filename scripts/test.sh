#!/usr/bin/env bash
# Installs what the tests need (Debian packages when run as root, a venv with the package) and
# runs the whole test suite. Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."

# user-mode-linux gives a real vcan0 on kernels without SocketCAN; can-utils is the outside peer;
# systemd provides systemd-analyze for the unit-file checks; tmux drives the monitor in a real terminal;
# gcc and the Python headers build the compiled fit (frictiond/_fitcore.c).
DEB_PACKAGES=(python3-venv gcc libc6-dev python3-dev user-mode-linux can-utils kmod iproute2 systemd tmux)
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    missing=()
    for pkg in "${DEB_PACKAGES[@]}"; do
        dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
    done
    if [ ${#missing[@]} -gt 0 ]; then
        echo "installing Debian packages: ${missing[*]}"
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
    fi
else
    echo "not root: assuming ${DEB_PACKAGES[*]} are installed (vcan tests need them)"
fi

python3 -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip >/dev/null
.venv/bin/python -m pip install -q -e '.[test,plot]'
exec .venv/bin/python -m pytest "$@"
