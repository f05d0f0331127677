"""The plain builds of the libFuzzer targets (tests/fuzz/): fuzz_packed (api/packed.c against
jansson, differentially) and fuzz_http (the request parsers of server/parse.c against their
promises), each over its seeds and deterministic mutations. Under make sanitize they are the
ASan builds; make fuzz runs the same sources under libFuzzer."""
import os
import subprocess
import tempfile

import pytest

from conftest import REPO

TARGETS = {
    "fuzz_packed": (os.environ.get("FUZZ_PACKED", str(REPO / "build" / "fuzz_packed")), "agree with jansson"),
    "fuzz_http": (os.environ.get("FUZZ_HTTP", str(REPO / "build" / "fuzz_http")), "every promise"),
}


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_mutations(name):
    exe, ok = TARGETS[name]
    r = subprocess.run([exe, "20000", "4242"], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert ok in r.stdout, r.stdout


@pytest.mark.parametrize("name", sorted(TARGETS) + ["fuzz_api"])
def test_seeds_are_written_for_make_fuzz(name):
    exe = TARGETS[name][0] if name in TARGETS else os.environ.get("FUZZ_API", str(REPO / "build" / "fuzz_api"))
    with tempfile.TemporaryDirectory() as d:
        r = subprocess.run([exe, "--write-seeds", d], capture_output=True, text=True, timeout=60)
        assert r.returncode == 0, r.stderr
        assert len(os.listdir(d)) >= 5
