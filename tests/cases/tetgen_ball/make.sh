#!/bin/sh
# Regenerate mesh.txt from ball.smesh (a unit-radius icosphere, 42 vertices, 80 triangles):
#   tetgen -pq1.4a0.025 ball.smesh   (TetGen 1.5 is deterministic: the result is mesh.txt)
exec sh "$(dirname "$0")/../tetgen_case.sh" "$(dirname "$0")" ball -pq1.4a0.025
