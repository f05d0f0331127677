#!/bin/sh
# Prints the Debian packages of tools/packages.txt for one apt-get install line (.ci/run and the
# Dockerfile both use it). nodejs and npm are left out when a working npm is already on PATH: a
# Node.js from another distribution (nodesource's bundles npm) conflicts with Debian's npm
# package, and apt-get would refuse the whole line.
set -eu
list="$(dirname "$0")/packages.txt"
for p in $(grep -v '^#' "$list"); do
    case $p in nodejs|npm) command -v npm >/dev/null 2>&1 && command -v node >/dev/null 2>&1 && continue ;; esac
    printf '%s\n' "$p"
done
