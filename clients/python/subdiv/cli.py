"""subdiv — batch refinement through a subdivd daemon.

    subdiv refine INPUT --level L -o OUT [-o OUT2 ...] [--tags T.json] [--rules R.json]
                  [--fill [--max-volume V] [--min-ratio R]] [--singular-groups A,B]
                  [--parts P] [--slice nx,ny,nz,d] [--attributes A] [--colormap NAME:min:max]
                  [--octahedra tets|polyhedra] [--names true|false] [--compress none|zlib]
                  [--limit true|false] [--pvd DIR] [--save-complex C.json]
    subdiv refine INPUT --level L -o OUT.pvtu|OUT.vtu --mpi N [--tags T.json] [--rules R.json]
    subdiv batch JOBS.json [--fail-fast]
    subdiv convert INPUT -o BODY.json [--tags-out T.json] [--fill ...] [--singular-groups A,B]

Every command takes --url URL (default $SUBDIV_URL, else http://127.0.0.1:8080) or --spawn (start
a private daemon on a free loopback port for the run: --subdivd PATH, default $SUBDIVD, else the
subdivd beside this program, else on PATH), and --progress auto|bar|lines|none.

INPUT: OBJ, OFF, STL, Gmsh .msh, VTK .vtk/.vtu, TetGen .node/.ele or a PUT /complex body
(.json). OUT: .glb, .gltf, .vtu, .vtk or .json (the level's format); each output gets the level
options that apply to its format (--octahedra and --names VTU and VTK, --compress VTU,
--colormap GLB and glTF). --pvd DIR writes the levels
0..L as DIR/level_K.vtu and the ParaView time series DIR/levels.pvd (timestep K = level K). The job file format and the
exit codes are in clients/README.md; exit codes: 0 done, 1 the daemon refused the input (4xx),
2 usage, file or mesh error, 3 the daemon failed or could not be reached, 4 the daemon does not
implement an option that was asked for (501), 130 interrupted. `batch` exits with the code of its
first failed job.
"""
import argparse
import json
import math
import os
import pathlib
import shutil
import subprocess
import sys
import threading
import time

from . import __version__, meshes
from .client import FORMATS, Client
from .errors import ProblemError, SubdivError, TransportError

EXIT_OK, EXIT_REFUSED, EXIT_USAGE, EXIT_DAEMON, EXIT_NOT_IMPLEMENTED, EXIT_INTERRUPTED = 0, 1, 2, 3, 4, 130
LEVEL_OPTS = ("parts", "slice", "attributes", "colormap", "octahedra", "names", "compress",
              "limit")
# Level options that apply to some formats only (docs/OUTPUTS.md; the daemon refuses them with
# any other format): each output is sent the options that apply to its format.
FORMAT_OPTS = {"octahedra": ("vtu", "vtk"), "names": ("vtu", "vtk"), "compress": ("vtu",),
               "colormap": ("glb", "gltf")}
JOB_KEYS = {"input", "output", "outputs", "level", "tags", "rules", "fill", "singular_groups", "options",
            "name", "save_complex", "pvd", "repair", "crease_angle"}


class UsageError(Exception):
    """A bad command line or job file (exit 2)."""


# ---- progress ---------------------------------------------------------------------------------

def level_number(text):
    """A level as --level takes it: a whole number from 0 (argparse says which option, exit 2)."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a level: {text!r}") from None
    if n < 0:
        raise argparse.ArgumentTypeError(f"a level is 0 or more, not {n}")
    return n


def _size(n):
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000


def _server(done, total):
    """The daemon's progress: a fraction of the levels' work (total 1.0), or seconds."""
    return f"{100 * done:3.0f}%" if total else f"{done:.1f} s"


class Progress:
    """Renders client progress events on stderr: one updating line on a terminal ("bar"),
    milestone lines otherwise ("lines"), or nothing."""

    def __init__(self, mode="auto", stream=None, quiet=False):
        self.out = stream or sys.stderr
        self.quiet = quiet
        if mode == "auto" and quiet:   # -q: errors alone (as --mpi's -q), unless --progress says
            mode = "none"
        if mode == "auto":
            mode = "bar" if self.out.isatty() else "lines"
        self.mode = mode
        self.label = ""
        self.last = 0.0
        self.state = {}
        self.lock = threading.Lock()

    def begin(self, label):
        self.finish()
        self.label = label
        self.state = {}

    def note(self, text):
        """A result line (printed whatever the progress mode, unless --quiet)."""
        self.finish()
        if not self.quiet:
            print(text, file=self.out, flush=True)

    def __call__(self, kind, done, total):
        if self.mode == "none":
            return
        with self.lock:
            prev = self.state.get(kind)
            self.state[kind] = (done, total)
            now = time.time()
            if self.mode == "bar":
                final = total is not None and kind != "server" and done >= total
                if final or now - self.last > 0.1:
                    self.last = now
                    self.out.write("\r\033[K" + self._line())
                    self.out.flush()
            elif self.mode == "lines":
                if kind == "server":
                    if prev is None or now - self.last >= 2:
                        self.last = now
                        print(f"  {self.label}: daemon computing, {_server(done, total)}",
                              file=self.out, flush=True)
                elif total is not None and done >= total and (prev is None or prev[0] < total):
                    verb = "sent" if kind == "upload" else "received"
                    print(f"  {self.label}: {verb} {_size(done)}", file=self.out, flush=True)

    def _line(self):
        parts = [self.label]
        for kind in ("upload", "server", "download"):
            if kind not in self.state:
                continue
            done, total = self.state[kind]
            if kind == "server":
                parts.append(f"computing {_server(done, total)}")
            elif total:
                parts.append(f"{kind} {100 * done // max(total, 1):3d}% {_size(done)}/{_size(total)}")
            else:
                parts.append(f"{kind} {_size(done)}")
        return " | ".join(parts)

    def finish(self):
        if self.mode == "bar" and self.state:
            self.out.write("\r\033[K" + self._line() + "\n")
            self.out.flush()
        self.state = {}

    def done(self, kind, total):
        """A download without Content-Length has ended (lines mode reports it here)."""
        if self.mode == "lines" and kind in self.state and self.state[kind][1] is None:
            print(f"  {self.label}: received {_size(total)}", file=self.out, flush=True)


# ---- the daemon ------------------------------------------------------------------------------

def find_subdivd(explicit=None):
    """The daemon for --spawn: --subdivd PATH, else $SUBDIVD, else the subdivd beside the launcher,
    else on PATH. A binary the user named (--subdivd or $SUBDIVD) is used or refused, never
    replaced by another one found further down the list."""
    def runnable(cand):
        return os.access(cand, os.X_OK) and not os.path.isdir(cand)
    for what, cand in (("--subdivd", explicit), ("SUBDIVD", os.environ.get("SUBDIVD"))):
        if cand:
            if not runnable(cand):
                raise UsageError(f"--spawn: {what} {cand} is not an executable file")
            return cand
    launcher = os.environ.get("SUBDIV_LAUNCHER") or sys.argv[0]
    for cand in (str(pathlib.Path(launcher).resolve().parent / "subdivd"), shutil.which("subdivd")):
        if cand and runnable(cand):
            return cand
    raise UsageError("--spawn: cannot find subdivd; give --subdivd PATH or set SUBDIVD")


class SpawnedDaemon:
    """A private subdivd on a free loopback port, stopped when the block ends."""

    def __init__(self, path, flags=()):
        self.proc = subprocess.Popen([path, "--port", "0", "--log-level", "warn", *flags],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        if "http://" not in line:
            # stdout closed: the daemon is exiting (a bad --daemon-flag, a busy port...); its
            # stderr says why once it has
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                pass
            err = self.proc.stderr.read() if self.proc.poll() is not None else ""
            self.stop()
            lines = []
            for x in err.strip().splitlines()[:3]:
                if x.startswith("usage:"):   # after a bad flag: the message is enough
                    break
                lines.append(x.strip())
            why = "; ".join(x for x in (line.strip(), *lines) if x)
            code = self.proc.returncode
            raise TransportError(f"subdivd did not start (exit {code}): {why}" if why else
                                 f"subdivd did not start (exit {code})")
        self.url = line.split("http://", 1)[1].split("/", 1)[0]
        self.url = "http://" + self.url
        self.log = []
        threading.Thread(target=self._drain, daemon=True).start()

    def _drain(self):
        for line in self.proc.stderr:
            self.log = (self.log + [line.rstrip()])[-50:]

    def stop(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


class Connection:
    """The client for the command: --url, or --spawn's private daemon."""

    def __init__(self, args):
        self.daemon = None
        if args.spawn:
            self.daemon = SpawnedDaemon(find_subdivd(args.subdivd), args.daemon_flag or ())
            url = self.daemon.url
        else:
            url = args.url or os.environ.get("SUBDIV_URL") or "http://127.0.0.1:8080"
        self.client = Client(url, timeout=args.timeout, retries=args.retries)

    def __enter__(self):
        try:
            self.client.wait_ready(10 if self.daemon else 2)
        except SubdivError:
            self.__exit__()
            raise
        return self.client

    def __exit__(self, *exc):
        self.client.close()
        if self.daemon:
            self.daemon.stop()


# ---- jobs ------------------------------------------------------------------------------------

def _load_json(value, what, base):
    """A JSON value given inline or as a path (relative to `base`)."""
    if isinstance(value, (dict, list)):
        return value
    if not isinstance(value, str):
        raise UsageError(f"{what} must be a file name or a JSON value")
    p = pathlib.Path(value)
    if not p.is_absolute():
        p = base / p
    try:
        return json.loads(p.read_text())
    except OSError as e:
        raise UsageError(f"{what}: cannot read {p}: {e.strerror}") from e
    except ValueError as e:
        raise UsageError(f"{what}: {p} is not JSON: {e}") from e


def _output_format(path):
    ext = pathlib.Path(path).suffix.lower().lstrip(".")
    if ext not in FORMATS:
        raise UsageError(f"cannot tell the format of {path}: use .glb, .gltf, .vtu, .vtk or .json")
    return ext


def options_for(options, fmt):
    """The level options that apply to format `fmt` (FORMAT_OPTS)."""
    return {k: v for k, v in options.items() if fmt in FORMAT_OPTS.get(k, (fmt,))}


def check_options(options, formats):
    """A format-specific level option that applies to none of the outputs' formats is a usage
    error (it would be dropped from every request)."""
    for k in options:
        if k in FORMAT_OPTS and not set(FORMAT_OPTS[k]) & set(formats):
            raise UsageError(f"{k} applies to {' and '.join(FORMAT_OPTS[k])} outputs only "
                             f"(docs/OUTPUTS.md); none of the outputs is one")


PVD_NAME = "levels.pvd"


def pvd_text(files):
    """A ParaView collection (.pvd) of the VTU files `files` (names relative to it), the K-th at
    timestep K: VTK's Collection layout, as ParaView writes it."""
    rows = "".join(f'    <DataSet timestep="{k}" group="" part="0" file="{f}"/>\n'
                   for k, f in enumerate(files))
    return ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" '
            'byte_order="LittleEndian">\n  <Collection>\n' + rows + "  </Collection>\n</VTKFile>\n")


def write_pvd(s, level, directory, options, progress, name):
    """Levels 0..level of session s as DIR/level_K.vtu, then DIR/levels.pvd (written last, as
    .part renamed: it exists only once every level is there). Returns [(path, bytes, what)],
    `what` the level of the file ("level K", "levels 0..L" for the .pvd)."""
    d = pathlib.Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    results, files = [], []
    for k in range(level + 1):
        out = d / f"level_{k}.vtu"
        progress.begin(f"{name} -> {out.name}")
        n = s.level(k, format="vtu", out=str(out), progress=progress, **options_for(options, "vtu"))
        progress.done("download", n)
        results.append((str(out), n, f"level {k}"))
        files.append(out.name)
    text = pvd_text(files).encode()
    part = d / (PVD_NAME + ".part")
    part.write_bytes(text)
    os.replace(part, d / PVD_NAME)
    results.append((str(d / PVD_NAME), len(text), f"levels 0..{level}"))
    return results


def run_job(client, job, progress, base=pathlib.Path(".")):
    """One input through one session: rules, complex, tags, then every output (and with "pvd"
    the time series of levels 0..L), each sent the level options that apply to its format.
    Returns a list of (output path, bytes)."""
    inp = str(base / job["input"]) if not os.path.isabs(job["input"]) else job["input"]
    level = job["level"]
    outputs = [o if os.path.isabs(o) else str(base / o) for o in job.get("outputs") or []]
    pvd = job.get("pvd")
    if pvd is not None:
        pvd = pvd if os.path.isabs(pvd) else str(base / pvd)
    if not outputs and pvd is None:
        raise UsageError("give an output (-o) or --pvd DIR")
    formats = [_output_format(o) for o in outputs] + (["vtu"] if pvd is not None else [])
    options = job.get("options", {})
    check_options(options, formats)
    fill = job.get("fill")
    if fill is True:
        fill = {}
    if fill is not None and not isinstance(fill, dict):
        raise UsageError("fill is true or {\"max_volume\": v, \"min_ratio\": r}")
    body, group_tags = meshes.read(inp, fill=fill, singular_groups=job.get("singular_groups"))
    rules = _load_json(job["rules"], "rules", base) if job.get("rules") is not None else None
    tags = _load_json(job["tags"], "tags", base) if job.get("tags") is not None else None
    if isinstance(tags, list):
        tags = {"singular": tags}
    if tags is None and group_tags:
        tags = {"singular": group_tags}
    if job.get("repair") not in (None, False, True):
        raise UsageError("repair is true or false")
    if job.get("repair"):  # dropped simplices are reported (docs/API.md, "repair")
        body["repair"] = True
    crease = job.get("crease_angle")
    if crease is not None:
        if (isinstance(crease, bool) or not isinstance(crease, (int, float))
                or not math.isfinite(crease)):
            raise UsageError("crease_angle is a finite number of degrees")
        tags = dict(tags or {})
        tags["crease_angle"] = crease
    name = job.get("name") or pathlib.Path(inp).name
    progress.begin(name)
    results = []
    with client.create_session() as s:
        if rules is not None:
            s.put_rules(rules)
        answer = s.put_complex(body, progress=progress)
        fills = answer.get("summary", {}).get("fill")
        repaired = answer.get("summary", {}).get("repaired_count")
        if tags is not None:
            creased = s.put_tags(body=tags).get("crease_angle")
            if creased is not None:
                progress.note(f"{name}: crease angle {creased['degrees']:g}: "
                              f"{creased['tagged']} edges tagged")
        if repaired is not None:
            progress.note(f"{name}: repaired: {repaired} simplices dropped")
        if job.get("save_complex"):
            sc = job["save_complex"]
            sc = pathlib.Path(sc if os.path.isabs(sc) else base / sc)
            sc.parent.mkdir(parents=True, exist_ok=True)
            with open(sc, "w") as f:
                json.dump(s.get_complex(), f)
        for out in outputs:
            pathlib.Path(out).parent.mkdir(parents=True, exist_ok=True)
            progress.begin(f"{name} -> {pathlib.Path(out).name}")
            fmt = _output_format(out)
            n = s.level(level, format=fmt, out=out, progress=progress, **options_for(options, fmt))
            progress.done("download", n)
            results.append((out, n, f"level {level}"))
        if pvd is not None:
            results += write_pvd(s, level, pvd, options, progress, name)
    progress.finish()
    extra = ""
    if fills:
        extra = ", filled: " + ", ".join(f"{f['tets']} tets" for f in fills)
    for out, n, what in results:
        progress.note(f"{name}: {what} -> {out} ({_size(n)}{extra})")
    for f in fills or []:   # e.g. max_volume not met on a coarse surface (docs/SERVICE.md, fill)
        if f.get("warning"):
            print(f"subdiv: {name}: fill: {f['warning']}", file=sys.stderr)
    return [(out, n) for out, n, _ in results]


def _exit_code(e):
    if isinstance(e, (UsageError, meshes.MeshError, OSError)):
        return EXIT_USAGE
    if isinstance(e, SubdivError):
        return e.exit_code
    return EXIT_DAEMON


def _report(e, what):
    if isinstance(e, ProblemError):
        kind = {1: "refused", 4: "not implemented by the daemon"}.get(e.exit_code, "failed")
        msg = f"subdiv: {what}: {kind} ({e.status} {e.slug}): {e.detail}"
        for err in e.errors:
            where = err.get("pointer") or "(the request)"
            msg += f"\n  at {where}" + ("" if err.get("message") == e.detail else f": {err.get('message')}")
        if e.limit_name:
            msg += f"\n  limit {e.limit_name} = {e.limit}, requested {e.requested}"
    elif isinstance(e, OSError) and not isinstance(e, TransportError):
        msg = f"subdiv: {what}: {e.strerror or e}" + (f": {e.filename}" if e.filename else "")
    else:
        msg = f"subdiv: {what}: {e}"
    print(msg, file=sys.stderr, flush=True)


def _job_from_args(args):
    job = {"input": args.input, "level": args.level, "outputs": args.output or [], "pvd": args.pvd,
           "tags": args.tags, "rules": args.rules,
           "options": {k: getattr(args, k) for k in LEVEL_OPTS if getattr(args, k) is not None}}
    if args.fill or args.max_volume is not None or args.min_ratio is not None:
        job["fill"] = {k: v for k, v in (("max_volume", args.max_volume), ("min_ratio", args.min_ratio))
                       if v is not None}
    if args.singular_groups is not None:
        job["singular_groups"] = [g for g in args.singular_groups.split(",") if g]
    if args.save_complex:
        job["save_complex"] = args.save_complex
    if args.repair:
        job["repair"] = True
    if args.crease_angle is not None:
        job["crease_angle"] = args.crease_angle
    return job


def find_subdivd_mpi():
    launcher = os.environ.get("SUBDIV_LAUNCHER") or sys.argv[0]
    for cand in (os.environ.get("SUBDIVD_MPI"),
                 str(pathlib.Path(launcher).resolve().parent / "subdivd-mpi"),
                 shutil.which("subdivd-mpi")):
        if cand and os.access(cand, os.X_OK) and not os.path.isdir(cand):
            return cand
    raise UsageError("--mpi: cannot find subdivd-mpi; set SUBDIVD_MPI or build it (make build/subdivd-mpi)")


def cmd_refine_mpi(args):
    """`refine --mpi N`: the mesh converted here (as `convert` does), then `mpirun -n N
    subdivd-mpi refine` on it (docs/BATCH.md, section 7): no daemon; one .pvtu (a VTU piece per rank)
    or one merged .vtu. mpirun's stderr (each rank's progress) passes through."""
    job = _job_from_args(args)
    outs = job["outputs"]
    if args.mpi < 1:
        raise UsageError("--mpi takes a number of processes (1 or more)")
    if len(outs) != 1 or not outs[0].endswith((".pvtu", ".vtu")) or job.get("pvd"):
        raise UsageError("--mpi writes one output: OUT.pvtu (a piece per process) or OUT.vtu (merged)")
    if job["options"] or job.get("save_complex") or job.get("repair") or job.get("crease_angle") is not None:
        raise UsageError("--mpi takes the mesh, --level, --tags, --rules and one -o; no level options, "
                         "--save-complex, --repair or --crease-angle")
    mpirun = shutil.which("mpirun")
    if not mpirun:
        raise UsageError("--mpi: mpirun is not on PATH (Debian: openmpi-bin)")
    exe = find_subdivd_mpi()
    import tempfile
    with tempfile.TemporaryDirectory(prefix="subdiv-mpi-") as tmp:
        try:
            body, group_tags = meshes.read(args.input, fill=job.get("fill"),
                                           singular_groups=job.get("singular_groups"))
        except (meshes.MeshError, OSError) as e:
            _report(e, args.input)
            return EXIT_USAGE
        mesh = pathlib.Path(tmp) / "mesh.json"
        mesh.write_text(json.dumps(body))
        cmd = [mpirun, "-n", str(args.mpi)]
        if args.mpi > (os.cpu_count() or 1):
            cmd.append("--oversubscribe")
        cmd += [exe, "refine", str(mesh), "--level", str(args.level), "-o", outs[0]]
        if job.get("tags"):
            cmd += ["--tags", job["tags"]]
        elif group_tags:
            t = pathlib.Path(tmp) / "tags.json"
            t.write_text(json.dumps({"singular": group_tags}))
            cmd += ["--tags", str(t)]
        if job.get("rules"):
            cmd += ["--rules", job["rules"]]
        if args.quiet:  # no result lines: not even rank 0's summary
            cmd.append("-qq")
        elif args.progress == "none":
            cmd.append("-q")
        try:
            rc = subprocess.run(cmd).returncode
        except KeyboardInterrupt:
            return EXIT_INTERRUPTED
    return rc if rc in (EXIT_OK, EXIT_REFUSED, EXIT_USAGE) else EXIT_DAEMON


def cmd_refine(args):
    if args.mpi is not None:
        try:
            return cmd_refine_mpi(args)
        except UsageError as e:
            _report(e, args.input)
            return EXIT_USAGE
    job = _job_from_args(args)
    progress = Progress(args.progress, quiet=args.quiet)
    try:
        with Connection(args) as client:
            run_job(client, job, progress, pathlib.Path("."))
        return EXIT_OK
    except (SubdivError, meshes.MeshError, UsageError, OSError) as e:
        progress.finish()
        _report(e, args.input)
        return _exit_code(e)


def parse_jobs(path):
    """The job file: {"defaults": {...}, "jobs": [{...}, ...]} (clients/README.md)."""
    base = pathlib.Path(path).resolve().parent
    try:
        doc = json.loads(pathlib.Path(path).read_text())
    except OSError as e:
        raise UsageError(f"cannot read the job file {path}: {e.strerror}") from e
    except ValueError as e:
        raise UsageError(f"the job file {path} is not JSON: {e}") from e
    if not isinstance(doc, dict) or not isinstance(doc.get("jobs"), list) or not doc["jobs"]:
        raise UsageError(f"{path}: a job file is {{\"jobs\": [{{\"input\", \"outputs\", \"level\"}}...]}}")
    unknown = set(doc) - {"defaults", "jobs"}
    if unknown:
        raise UsageError(f"{path}: unknown member {sorted(unknown)[0]!r} (defaults, jobs)")
    defaults = doc.get("defaults", {})
    if not isinstance(defaults, dict) or set(defaults) - (JOB_KEYS - {"input", "name"}):
        bad = sorted(set(defaults) - (JOB_KEYS - {"input", "name"})) if isinstance(defaults, dict) else ["?"]
        raise UsageError(f"{path}: /defaults: unknown member {bad[0]!r}")
    jobs = []
    for i, j in enumerate(doc["jobs"]):
        if not isinstance(j, dict):
            raise UsageError(f"{path}: /jobs/{i} must be an object")
        if set(j) - JOB_KEYS:
            raise UsageError(f"{path}: /jobs/{i}: unknown member {sorted(set(j) - JOB_KEYS)[0]!r}; "
                             f"allowed: {', '.join(sorted(JOB_KEYS))}")
        # "output" is "outputs" spelled for one file: the job's own (either spelling) replaces
        # the defaults' (either spelling), as every other key does
        job = {}
        for layer in (defaults, j):
            layer = dict(layer)
            if "output" in layer:
                o = layer.pop("output")
                layer.setdefault("outputs", o if isinstance(o, list) else [o])
            job.update(layer)
        opts = dict(defaults.get("options", {}))
        opts.update(j.get("options", {}))
        job["options"] = opts
        if "pvd" in job:
            job.setdefault("outputs", [])
        for k in ("input", "outputs", "level"):
            if k not in job:
                raise UsageError(f"{path}: /jobs/{i}: \"{k}\" is required")
        if not isinstance(job["level"], int) or isinstance(job["level"], bool):
            raise UsageError(f"{path}: /jobs/{i}/level must be a whole number")
        if set(job["options"]) - set(LEVEL_OPTS):
            raise UsageError(f"{path}: /jobs/{i}/options: unknown option "
                             f"{sorted(set(job['options']) - set(LEVEL_OPTS))[0]!r}")
        stem = pathlib.Path(job["input"]).stem
        job["outputs"] = [str(o).format(name=stem, level=job["level"]) for o in job["outputs"]]
        for k in ("pvd", "save_complex"):
            if job.get(k) is not None:
                job[k] = str(job[k]).format(name=stem, level=job["level"])
        jobs.append(job)
    return base, jobs


def cmd_batch(args):
    progress = Progress(args.progress, quiet=args.quiet)
    try:
        base, jobs = parse_jobs(args.jobfile)
    except UsageError as e:
        _report(e, args.jobfile)
        return EXIT_USAGE
    first, failed, done = EXIT_OK, 0, 0
    try:
        with Connection(args) as client:
            for i, job in enumerate(jobs):
                try:
                    run_job(client, job, progress, base)
                    done += 1
                except (SubdivError, meshes.MeshError, UsageError, OSError) as e:
                    progress.finish()
                    failed += 1
                    _report(e, f"job {i + 1} ({job['input']})")
                    first = first or _exit_code(e)
                    if args.fail_fast or isinstance(e, TransportError):
                        break
    except (SubdivError, UsageError) as e:
        _report(e, args.jobfile)
        return _exit_code(e)
    skipped = len(jobs) - done - failed
    progress.note(f"subdiv: {len(jobs)} job(s): {done} done, {failed} failed"
                  + (f", {skipped} not run" if skipped else ""))
    return first


def cmd_convert(args):
    fill = None
    if args.fill or args.max_volume is not None or args.min_ratio is not None:
        fill = {k: v for k, v in (("max_volume", args.max_volume), ("min_ratio", args.min_ratio)) if v is not None}
    groups = None if args.singular_groups is None else [g for g in args.singular_groups.split(",") if g]
    try:
        body, tags = meshes.read(args.input, fill=fill, singular_groups=groups)
        pathlib.Path(args.output).write_text(json.dumps(body))
        if args.tags_out:
            pathlib.Path(args.tags_out).write_text(json.dumps({"singular": tags or []}))
    except (meshes.MeshError, OSError) as e:
        _report(e, args.input)
        return EXIT_USAGE
    return EXIT_OK


def cmd_deform(args):
    """A mesh as the solid, a model embedded in it, moves, the deformed model written out."""
    progress = Progress(args.progress, quiet=args.quiet)
    ext = pathlib.Path(args.output).suffix.lower()
    fmt = {".obj": "obj", ".json": "json", ".glb": "glb"}.get(ext)
    if not fmt:
        raise UsageError(f"cannot tell the format from {args.output!r}: use .obj, .json or .glb")
    try:
        body, tags = meshes.read(args.input)
        model, _ = meshes.read(args.embed)
        tris = [t for t in model["simplices"] if len(t) == 3]
        moves = _load_json(args.moves, "--moves", pathlib.Path(".")) if args.moves else []
        moves = moves if isinstance(moves, list) else [moves]
        if not all(isinstance(m, dict) for m in moves):
            raise UsageError(f"--moves: {args.moves} holds a PATCH /control-points body "
                             "({\"moves\": [...]}) or a list of them")
        with Connection(args) as client, client.create_session() as s:
            progress.begin(f"{args.input} + {args.embed}")
            s.put_complex(body, progress=progress)
            if tags:
                s.put_tags(tags)
            j = s.put_embedded("model", model["vertices"], tris or None, level=args.level,
                               outside=args.outside)
            for m in moves:   # sent as it is: the daemon names a wrong member (exit 1)
                s._change("PATCH", "/control-points", m, True, None)
            out = s.get_embedded("model", fmt)
            data = out if isinstance(out, bytes) else (json.dumps(out) if fmt == "json" else out).encode()
            part = pathlib.Path(args.output + ".part")
            part.write_bytes(data)
            part.replace(args.output)
            progress.note(f"{args.embed}: {j['embedded']['vertices']} vertices at level {args.level} "
                          f"({j['embedded']['outside_vertices']} outside), {len(moves)} edit(s) "
                          f"-> {args.output} ({len(data)} bytes)")
        return EXIT_OK
    except (SubdivError, meshes.MeshError, UsageError, OSError, ValueError, KeyError) as e:
        progress.finish()
        _report(e, args.input)
        return _exit_code(e) if isinstance(e, (SubdivError, meshes.MeshError, UsageError, OSError)) else EXIT_USAGE


def build_parser():
    common = argparse.ArgumentParser(add_help=False)
    g = common.add_argument_group("daemon")
    g.add_argument("--url", help="the daemon (default $SUBDIV_URL, else http://127.0.0.1:8080)")
    g.add_argument("--spawn", action="store_true", help="start a private daemon for this run")
    g.add_argument("--subdivd", help="the subdivd binary for --spawn")
    g.add_argument("--daemon-flag", action="append", help="a flag for the spawned daemon (repeatable)")
    g.add_argument("--timeout", type=float, default=600, help="seconds per request (default 600)")
    g.add_argument("--retries", type=int, default=3, help="retries of a 429/503 answer (default 3)")
    g.add_argument("--progress", choices=("auto", "bar", "lines", "none"), default="auto",
                   help="progress on stderr: an updating line (bar, the default on a terminal), "
                   "milestone lines (lines, the default otherwise) or none")
    g.add_argument("-q", "--quiet", action="store_true", help="errors alone: no result lines, "
                   "and no progress unless --progress names a mode")
    mesh = argparse.ArgumentParser(add_help=False)
    m = mesh.add_argument_group("mesh")
    m.add_argument("--fill", action="store_true", help="post the 2-D cells (triangles, split quads and polygons) as a TetGen fill surface")
    m.add_argument("--max-volume", type=float, help="fill: TetGen's largest tetrahedron volume")
    m.add_argument("--min-ratio", type=float, help="fill: TetGen's radius-edge ratio bound (quality)")
    m.add_argument("--singular-groups", help="Gmsh physical groups that are singular tags, "
                   "comma-separated (default: names starting with singular, crease, corner)")
    p = argparse.ArgumentParser(prog="subdiv", description="Batch refinement through subdivd.",
                                epilog="exit codes: 0 done, 1 the daemon refused the input, 2 usage, "
                                "file or mesh error, 3 the daemon failed or is unreachable, 4 not "
                                "implemented by the daemon (501), 130 interrupted")
    p.add_argument("--version", action="version", version=f"subdiv {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("refine", parents=[common, mesh], help="one mesh to one or more outputs")
    r.add_argument("input")
    r.add_argument("--level", "-l", type=level_number, required=True)
    r.add_argument("-o", "--output", action="append",
                   help="an output file: .glb .gltf .vtu .vtk .json (repeatable; or --pvd)")
    r.add_argument("--pvd", metavar="DIR", help="levels 0..L as DIR/level_K.vtu and the time "
                   "series DIR/levels.pvd (ParaView opens it; timestep K = level K)")
    r.add_argument("--tags", help="a PUT /tags body (JSON file)")
    r.add_argument("--rules", help="a PUT /rules body (JSON file)")
    for k in LEVEL_OPTS:
        r.add_argument("--" + k, help=f"level option {k} (docs/OUTPUTS.md)")
    r.add_argument("--save-complex", help="write GET /complex (after tags) to this file")
    r.add_argument("--repair", action="store_true", help="drop degenerate, repeated-vertex and "
                   "duplicate simplices instead of refusing the mesh (reported)")
    r.add_argument("--crease-angle", type=float, metavar="DEG", help="tag as creases the surface "
                   "edges whose dihedral angle exceeds DEG degrees (0..180)")
    r.add_argument("--mpi", type=int, metavar="N", help="refine with N MPI processes (mpirun -n N "
                   "subdivd-mpi; no daemon): -o OUT.pvtu (a piece per process) or OUT.vtu (merged)")
    r.set_defaults(fn=cmd_refine)
    b = sub.add_parser("batch", parents=[common], help="run a job file")
    b.add_argument("jobfile")
    b.add_argument("--fail-fast", action="store_true", help="stop at the first failed job")
    b.set_defaults(fn=cmd_batch)
    d = sub.add_parser("deform", parents=[common], help="a model embedded in a mesh's solid, "
                       "deformed by moves (free-form deformation)")
    d.add_argument("input", help="the solid: any mesh file of refine")
    d.add_argument("--embed", required=True, help="the model: OBJ, OFF, STL (its triangles) or JSON")
    d.add_argument("--level", "-l", type=level_number, default=2, help="the level it is bound to (default 2)")
    d.add_argument("--outside", choices=("refuse", "fixed", "nearest"), default="refuse")
    d.add_argument("--moves", help="a PATCH /control-points body, or a list of them (JSON file)")
    d.add_argument("-o", "--output", required=True, help="the deformed model: .obj .json .glb")
    d.set_defaults(fn=cmd_deform)
    c = sub.add_parser("convert", parents=[mesh], help="a mesh file to a PUT /complex body (no daemon)")
    c.add_argument("input")
    c.add_argument("-o", "--output", required=True)
    c.add_argument("--tags-out", help="also write the PUT /tags body of the physical groups")
    c.set_defaults(fn=cmd_convert)
    return p


def main(argv=None):
    p = build_parser()
    try:
        args = p.parse_args(argv)
    except SystemExit as e:
        return EXIT_USAGE if e.code else EXIT_OK
    try:
        return args.fn(args)
    except UsageError as e:
        _report(e, args.command)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("subdiv: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
