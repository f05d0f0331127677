"""Every allocation of the api/ request path failed in turn (tests/api/faults.c, api/mem.h): each
entry point refuses with a 5xx problem or succeeds, and gives back every byte it took. Under make
sanitize it is the ASan build, which also checks the C-library blocks."""
import os
import subprocess

from conftest import REPO

FAULTS = os.environ.get("API_FAULTS", str(REPO / "build" / "api_faults"))


def test_every_allocation_failure_is_a_clean_refusal():
    r = subprocess.run([FAULTS], capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout + r.stderr[-4000:]
    assert "no leaks" in r.stdout
    runs = int(r.stdout.split()[1])
    assert runs > 500, "the scenario should make hundreds of allocations"
