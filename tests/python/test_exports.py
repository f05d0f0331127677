"""The core library exports its public API only (STYLE.md: jansson checks its exports).

Every global symbol defined in libsubdiv.a is either a function declared in core/sd.h or an
internal one with the internal prefix (sdi_ / SDI_: shared between the core's files, declared in
core/internal.h); file-local helpers are static. And every function sd.h declares is defined."""
import re
import subprocess

from conftest import REPO, SDLEVEL

LIB = SDLEVEL.parent / "libsubdiv.a"   # the build under test (make sanitize: build-asan)


def public_functions():
    text = (REPO / "core" / "sd.h").read_text()
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    return set(re.findall(r"\b(sd_\w+)\s*\(", text))


def defined_globals():
    out = subprocess.run(["nm", "-g", "--defined-only", str(LIB)], check=True,
                         capture_output=True, text=True).stdout
    names = set()
    for line in out.splitlines():
        f = line.split()
        if len(f) == 3:
            names.add(f[2])
    return names


def test_only_the_public_api_and_internal_names_are_global():
    public = public_functions()
    stray = sorted(n for n in defined_globals()
                   if n not in public and not n.startswith(("sdi_", "SDI_", "__")))
    assert not stray, "global symbols neither in sd.h nor with the sdi_ prefix: " + ", ".join(stray)


def test_every_public_function_is_defined():
    missing = sorted(public_functions() - defined_globals())
    assert not missing, "declared in sd.h but not defined: " + ", ".join(missing)
