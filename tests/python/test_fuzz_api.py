"""Run the api/ mutation fuzzer (tests/fuzz/fuzz_api.c): thousands of mutated request bodies
through parsing, the change handlers and every writer. Under make sanitize it is the ASan build."""
import os
import subprocess

from conftest import REPO

FUZZ = os.environ.get("FUZZ_API", str(REPO / "build" / "fuzz_api"))


def test_fuzz_api_bodies():
    r = subprocess.run([FUZZ, "3000", "12345"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "no memory errors" in r.stdout
    accepted = int(r.stdout.split(",")[1].split()[0])
    assert accepted > 50, "the mutations should leave a fair share of valid requests"
