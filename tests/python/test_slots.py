"""The compute slots (server/slots.c, tests/api/slots.c): a free slot goes to the waiter whose
session holds the fewest, then to the earliest; a waiter is refused at its deadline."""
import os
import subprocess

from conftest import REPO

SLOTS = os.environ.get("SLOTS_TEST", str(REPO / "build" / "slots_test"))


def test_slots_are_handed_over_fairly():
    r = subprocess.run([SLOTS], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "ok" in r.stdout
