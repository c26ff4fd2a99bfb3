#!/usr/bin/env bash
# Builds oneTBB with ThreadSanitizer into PREFIX, from Debian's source package of the installed
# libtbb-dev (same version, same Debian patches), for scripts/sanitize.sh tsan.
#   scripts/sanitizers/build-tsan-tbb.sh PREFIX
set -euo pipefail
PREFIX=$(realpath -m "${1:?usage: build-tsan-tbb.sh PREFIX}")
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
VERSION=$(dpkg-query -W -f='${Version}' libtbb-dev)
# apt-get source needs a deb-src entry; Debian 12 images ship only binary ones.
if ! grep -rqs '^Types:.*deb-src\|^deb-src' /etc/apt/sources.list /etc/apt/sources.list.d/; then
  echo "build-tsan-tbb: adding a deb-src entry for bookworm (/etc/apt/sources.list.d/scalefuse-deb-src.sources)" >&2
  $SUDO tee /etc/apt/sources.list.d/scalefuse-deb-src.sources >/dev/null <<'SRC'
Types: deb-src
URIs: http://deb.debian.org/debian
Suites: bookworm bookworm-updates
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
SRC
  $SUDO apt-get update -qq
fi
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
(cd "$WORK" && apt-get source -qq "onetbb=$VERSION" >/dev/null)
SRC_DIR=$(find "$WORK" -maxdepth 1 -type d -name 'onetbb-*' | head -1)
cmake -S "$SRC_DIR" -B "$WORK/build" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTBB_SANITIZE=thread -DTBB_TEST=OFF \
  -DTBB_EXAMPLES=OFF -DTBB_STRICT=OFF -DCMAKE_INSTALL_PREFIX="$PREFIX" >/dev/null
cmake --build "$WORK/build" -j"${JOBS:-2}" >/dev/null
cmake --install "$WORK/build" >/dev/null
echo "build-tsan-tbb: oneTBB $VERSION with ThreadSanitizer in $PREFIX" >&2
