#!/bin/sh
# Installs the Debian packages of tools/packages.txt that are missing (needs root or sudo), and
# the npm packages of the tests and the web front end. With a list as argument
# (tools/deps.sh tools/packages-fuzz.txt) only that list's Debian packages.
set -eu
cd "$(dirname "$0")/.."
list=${1:-tools/packages.txt}
pkgs=$(grep -v '^#' "$list" | tr '\n' ' ')
missing=""
for p in $pkgs; do
    # node and npm may come from another distribution of Node.js (e.g. nodesource, which bundles
    # npm): a working command counts as installed
    case $p in nodejs|npm) command -v "${p%js}" >/dev/null 2>&1 && continue ;; esac
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "$missing" ]; then
    echo "installing:$missing"
    SUDO=""
    [ "$(id -u)" -ne 0 ] && SUDO=sudo
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing
fi
[ "$list" = tools/packages.txt ] || exit 0
# npm tools of the tests (tests/tools/package.json: the Khronos glTF validator, Redocly's OpenAPI
# linter)
if [ ! -d tests/tools/node_modules/gltf-validator ] || [ ! -d tests/tools/node_modules/@redocly/cli ]; then
    (cd tests/tools && npm install --no-audit --no-fund --loglevel=error)
fi
# npm packages of the web front end (web/package-lock.json: three, esbuild; the Makefile runs the
# same npm ci when the lock file is newer) and of its browser test (tests/web: playwright-core,
# which drives the chromium package and never downloads a browser)
if [ ! -f web/node_modules/.package-lock.json ]; then
    (cd web && npm ci --no-audit --no-fund --loglevel=error)
fi
if [ ! -d tests/web/node_modules/playwright-core ]; then
    (cd tests/web && npm ci --no-audit --no-fund --loglevel=error)
fi
