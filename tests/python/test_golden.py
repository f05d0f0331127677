"""Outputs byte for byte against tests/golden/manifest.json, made by the build before the layout
refactor (issue 13): every level format and option, the complex with its classes, stats without
timings, matrices, analysis, an edit, a local refinement, the offline mode and sdlevel on the
scenarios of tests/golden/scenarios.py. A change that alters output bytes on purpose regenerates
the manifest (`/usr/bin/python3 tests/golden/capture.py --write`) and says why."""
import json
import pathlib
import sys

GOLDEN = pathlib.Path(__file__).resolve().parents[1] / "golden"
sys.path.insert(0, str(GOLDEN))

import capture  # noqa: E402


def test_outputs_match_the_golden_manifest():
    want = json.loads((GOLDEN / "manifest.json").read_text())
    got = capture.capture()
    assert sorted(got) == sorted(want)
    diff = [f"{sc} / {key}: {got[sc].get(key)} != {d}"
            for sc in want for key, d in want[sc].items() if got[sc].get(key) != d]
    assert not diff, f"{len(diff)} answers differ:\n" + "\n".join(diff[:20])
    assert all(set(got[sc]) == set(want[sc]) for sc in want)
