"""The Dockerfile, checked without a Docker engine: the build stage installs exactly what .ci/run
installs (tools/packages.txt), the runtime stage is Debian 12, non-root, exposes the port, has a
HEALTHCHECK on /healthz that works (the daemon is its own probe), ships the TetGen helper, and
every shared library the shipped binaries load comes from a package the runtime stage installs
(or from libc6, which every Debian image has)."""
import os
import re
import shutil
import subprocess


from conftest import REPO
from daemon import SUBDIVD, Daemon

DOCKERFILE = (REPO / "Dockerfile").read_text()


def instructions():
    """[(stage index, INSTRUCTION, arguments)] with continuation lines joined."""
    text = re.sub(r"\\\n", " ", DOCKERFILE)
    out, stage = [], -1
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        word, _, rest = line.partition(" ")
        word = word.upper()
        if word == "FROM":
            stage += 1
        out.append((stage, word, " ".join(rest.split())))
    return out


def install_args(cmd):
    """What follows `apt-get install` in a shell command (up to &&), its options dropped."""
    m = re.search(r"apt-get install((?:\s+-\S+)*)\s+(.*?)\s*(?:&&|$)", cmd)
    assert m, cmd
    return " ".join(m.group(2).split())


def test_build_stage_installs_what_ci_installs(tmp_path):
    ins = instructions()
    froms = [a for s, w, a in ins if w == "FROM"]
    assert len(froms) >= 2, "multi-stage: build, then runtime"
    assert froms[0].split()[0] == "debian:12" and froms[-1].split()[0].startswith("debian:12")
    build_runs = [a for s, w, a in ins if s == 0 and w == "RUN" and "apt-get install" in a]
    assert len(build_runs) == 1
    ci_lines = re.sub(r"\\\n", " ", (REPO / ".ci" / "run").read_text()).splitlines()
    (ci_install,) = [" ".join(l.split()) for l in ci_lines if "apt-get install" in l]
    ci_args = install_args(ci_install)
    assert install_args(build_runs[0]) == ci_args
    assert ci_args.startswith("make ") and "tools/apt-packages.sh" in ci_args
    # ... and the expression really reads the list (both run it the same way)
    copies = [a for s, w, a in ins if s == 0 and w == "COPY"]
    assert any("tools/packages.txt" in a and "tools/apt-packages.sh" in a for a in copies)
    listed = [l.strip() for l in (REPO / "tools" / "packages.txt").read_text().splitlines()
              if l.strip() and not l.startswith("#")]

    def expand(path):
        out = subprocess.run(["sh", "-c", f"echo {ci_args}"], cwd=REPO, capture_output=True,
                             text=True, check=True, env={"PATH": path}).stdout.split()
        assert out[0] == "make"
        return out[1:]
    assert "libtet1.5-dev" in listed and "nodejs" in listed and "npm" in listed
    # a machine without Node.js (debian:12) gets every listed package ...
    bare = tmp_path / "bin"
    bare.mkdir()
    for tool in ("sh", "grep", "tr", "dirname", "printf"):
        found = shutil.which(tool)
        if found:
            (bare / tool).symlink_to(found)
    assert expand(str(bare)) == listed
    # ... one whose Node.js brings its own npm (nodesource) gets all but nodejs and npm, which
    # would conflict with it
    for tool in ("node", "npm"):
        (bare / tool).symlink_to("/bin/true")
    assert expand(str(bare)) == [p for p in listed if p not in ("nodejs", "npm")]


def test_runtime_stage():
    ins = instructions()
    last = max(s for s, _, _ in ins)
    rt = [(w, a) for s, w, a in ins if s == last]
    users = [a for w, a in rt if w == "USER"]
    assert users and users[-1] not in ("root", "0")
    assert ("EXPOSE", "8080") in rt
    hc = [a for w, a in rt if w == "HEALTHCHECK"]
    assert len(hc) == 1 and "/healthz" in hc[0] and "--healthcheck" in hc[0]
    copies = " ".join(a for w, a in rt if w == "COPY")
    for binary in ("subdivd", "subdivd-tetgen", "sdlevel", "subdivd-mpi"):
        assert f"/build/{binary} " in copies + " "
    cmd = [a for w, a in rt if w == "CMD"][-1]
    assert "0.0.0.0" in cmd and "8080" in cmd


def _deps(pkgs):
    """The installed packages `pkgs` pull in (Depends and Pre-Depends, recursively; for an
    alternative, the installed ones)."""
    seen, todo = set(), list(pkgs)
    while todo:
        p = todo.pop()
        if p in seen:
            continue
        r = subprocess.run(["dpkg-query", "-W", "-f=${Depends}, ${Pre-Depends}", p],
                           capture_output=True, text=True)
        if r.returncode:
            continue    # a virtual package (e.g. libgcc1): its provider is listed elsewhere
        seen.add(p)
        for dep in r.stdout.split(","):
            for alt in dep.split("|"):
                name = alt.strip().split(" ")[0].split(":")[0]
                if name:
                    todo.append(name)
    return seen


def _owner(path):
    for cand in (path, os.path.realpath(path), path.replace("/usr/lib/", "/lib/"),
                 os.path.realpath(path).replace("/usr/lib/", "/lib/")):
        r = subprocess.run(["dpkg", "-S", cand], capture_output=True, text=True)
        if r.returncode == 0:
            return r.stdout.split(":")[0]
    return None


def test_runtime_libraries_are_installed():
    """ldd of the shipped binaries, mapped to Debian packages, all within the runtime install."""
    ins = instructions()
    last = max(s for s, _, _ in ins)
    runs = [a for s, w, a in ins if s == last and w == "RUN" and "apt-get install" in a]
    assert len(runs) == 1
    runtime = install_args(runs[0]).split()
    assert "libtet1.5" in runtime
    have = _deps(runtime + ["libc6"])
    missing = {}
    assert "openmpi-bin" in runtime   # mpirun, for subdivd-mpi
    for binary in (SUBDIVD, SUBDIVD.parent / "subdivd-tetgen", SUBDIVD.parent / "sdlevel",
                   SUBDIVD.parent / "subdivd-mpi"):
        out = subprocess.run(["ldd", str(binary)], capture_output=True, text=True, check=True).stdout
        for lib, path in re.findall(r"(\S+) => (/\S+)", out):
            if "asan" in lib or "ubsan" in lib:
                continue   # make sanitize's builds
            pkg = _owner(path)
            assert pkg, f"no package owns {path}"
            if pkg not in have:
                missing[lib] = pkg
    assert not missing, f"libraries from packages the runtime stage does not install: {missing}"


def test_healthcheck_probe():
    d = Daemon()
    try:
        ok = subprocess.run([str(SUBDIVD), "--healthcheck", d.url + "/healthz"], capture_output=True,
                            text=True, timeout=10)
        assert ok.returncode == 0 and ok.stdout.startswith("ok"), ok.stderr
        miss = subprocess.run([str(SUBDIVD), "--healthcheck", d.url + "/nothing"], capture_output=True,
                              text=True, timeout=10)
        assert miss.returncode == 1 and "404" in miss.stderr
    finally:
        d.stop()
    dead = subprocess.run([str(SUBDIVD), "--healthcheck", d.url + "/healthz"], capture_output=True,
                          text=True, timeout=10)
    assert dead.returncode == 1 and "cannot connect" in dead.stderr
    bad = subprocess.run([str(SUBDIVD), "--healthcheck", "ftp://x/"], capture_output=True, text=True)
    assert bad.returncode == 2


def test_dockerignore_keeps_host_builds_out():
    ignored = (REPO / ".dockerignore").read_text().split()
    assert "build/" in ignored and "build-asan/" in ignored
