"""Commands the docs name exist as written: every `subdiv WORD` in the docs, the READMEs and the
web front end's messages is a subcommand of `subdiv --help`, and the sdlevel synopsis of
docs/TEXT_FORMAT.md lists every option of sdlevel's own usage line."""
import re
import subprocess
import sys

from conftest import REPO, SDLEVEL

CLIENT = REPO / "clients" / "python"


def texts():
    files = [REPO / "README.md", REPO / "clients" / "README.md", *sorted((REPO / "docs").glob("*.md")),
             *sorted((REPO / "web" / "src").glob("*.js"))]
    return {f.relative_to(REPO): f.read_text(encoding="utf-8") for f in files}


def test_subdiv_subcommands_exist():
    r = subprocess.run([sys.executable, "-m", "subdiv", "--help"], cwd=CLIENT, capture_output=True,
                       encoding="utf-8")
    assert r.returncode == 0, r.stderr
    subs = set(re.search(r"\{([a-z,]+)\}", r.stdout).group(1).split(","))
    assert {"refine", "batch", "convert", "deform"} <= subs
    bad = []
    for name, t in texts().items():
        # `subdiv WORD` in code spans: the command, not the package (`subdiv.client`) or a path
        for span in re.findall(r"`([^`\n]+)`", t):
            for m in re.finditer(r"(?:^|[\s/])subdiv ([a-z][a-z-]*)\b", span):
                if m.group(1) not in subs:
                    bad.append(f"{name}: `{span}`")
    assert not bad, "subcommands that subdiv does not have:\n" + "\n".join(bad)


def test_sdlevel_synopsis_lists_its_options():
    r = subprocess.run([str(SDLEVEL)], capture_output=True, encoding="utf-8")
    usage = r.stderr
    assert usage.startswith("usage: sdlevel"), usage
    own = set(re.findall(r"\[(-[-a-z]+)", usage))
    doc = (REPO / "docs" / "TEXT_FORMAT.md").read_text(encoding="utf-8")
    synopsis = re.search(r"```\n(sdlevel .*?)```", doc, flags=re.S).group(1)
    listed = set(re.findall(r"\[(-[-a-z]+)", synopsis))
    assert own == listed, f"usage {sorted(own)} vs docs/TEXT_FORMAT.md {sorted(listed)}"
    for opt in own - {"-l", "-w", "-s"}:
        assert re.search(rf"^- .*`{re.escape(opt)}`", doc, flags=re.M), f"{opt} is not described"
