#!/bin/sh
# Regenerate mesh.txt from cube.smesh (the unit cube, 8 corners, 6 square facets):
#   tetgen -pq1.5a0.01 cube.smesh   (TetGen 1.5 is deterministic: the result is mesh.txt)
exec sh "$(dirname "$0")/../tetgen_case.sh" "$(dirname "$0")" cube -pq1.5a0.01
