#!/usr/bin/python3
"""Run the golden scenarios (scenarios.py) against a daemon and print or write their digests.

    capture.py [--write] [--subdivd PATH] [--dump DIR]

Without --write it prints the digests as JSON; with it, it (re)writes manifest.json. A level-stats
answer is recorded without its timings; every other answer byte for byte (status, content type
and the sha256 of the body)."""
import hashlib
import json
import os
import pathlib
import subprocess
import sys
import tempfile

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "python"))

import scenarios  # noqa: E402


def strip_times(x):
    if isinstance(x, dict):
        return {k: strip_times(v) for k, v in x.items() if "second" not in k}
    if isinstance(x, list):
        return [strip_times(v) for v in x]
    return x


DUMP = None  # a directory: every body is also written there (--dump DIR), to diff two builds


def digest(status, ctype, body):
    if DUMP:
        import re as _re
        name = _re.sub(r"[^A-Za-z0-9_.-]+", "_", hashlib.sha256(body).hexdigest()[:16])
        (pathlib.Path(DUMP) / name).write_bytes(body)
    return {"status": status, "type": ctype, "bytes": len(body),
            "sha256": hashlib.sha256(body).hexdigest()}


def run_scenario(daemon_mod, d, sc):
    s = daemon_mod.Session(d)
    out = {}
    r = s.put_complex(sc["complex"])
    out["PUT /complex"] = digest(r.status_code, r.headers.get("Content-Type"),
                                 json.dumps(strip_times(r.json()), sort_keys=True).encode())
    if "rules" in sc:
        r = s.req("PUT", "/rules", json=sc["rules"])
        assert r.status_code == 200, r.text
    if "tags" in sc:
        r = s.req("PUT", "/tags", json=sc["tags"])
        assert r.status_code == 200, r.text
    for i, (method, path, params) in enumerate(sc["requests"]):
        key = f"{i:02d} {method} {path} {json.dumps(params, sort_keys=True)}"
        if method == "GET":
            r = s.req("GET", path, params=params)
            body = r.content
        elif method == "STATS":
            r = s.req("GET", path, params=params)
            body = json.dumps(strip_times(r.json()), sort_keys=True).encode()
        elif method == "PATCH":
            v = s.req("GET", "").json()["version"]
            r = s.req("PATCH", path, json=params, headers={"If-Match": f'"{v}"'})
            body = r.content
        elif method == "REFINE":
            r = s.req("POST", path, json=params)
            body = json.dumps(strip_times(r.json()), sort_keys=True).encode()
        else:
            raise ValueError(method)
        out[key] = digest(r.status_code, r.headers.get("Content-Type"), body)
    s.delete()
    return out


def run_offline(subdivd):
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, inp, args, ext in scenarios.OFFLINE:
            dst = pathlib.Path(tmp) / f"{name}.{ext}"
            r = subprocess.run([str(subdivd), "refine", str(scenarios.REPO / inp), *args, "-o", str(dst)],
                               capture_output=True)
            body = dst.read_bytes() if dst.exists() else b""
            out[f"offline {name}"] = digest(r.returncode, ext, body)
    sdlevel = os.environ.get("SDLEVEL", str(scenarios.REPO / "build" / "sdlevel"))
    for name, inp, args in scenarios.SDLEVEL:
        r = subprocess.run([sdlevel, *args, str(scenarios.REPO / inp)], capture_output=True)
        out[f"sdlevel {name}"] = digest(r.returncode, "text", r.stdout)
    return out


def capture(subdivd=None):
    if subdivd:
        os.environ["SUBDIVD"] = str(subdivd)
    import daemon as daemon_mod
    d = daemon_mod.Daemon("--max-sessions", "100")
    try:
        result = {sc["name"]: run_scenario(daemon_mod, d, sc) for sc in scenarios.scenarios()}
    finally:
        d.stop()
    result["offline"] = run_offline(daemon_mod.SUBDIVD)
    return result


if __name__ == "__main__":
    args = sys.argv[1:]
    sub = None
    if "--dump" in args:
        DUMP = args[args.index("--dump") + 1]
        pathlib.Path(DUMP).mkdir(parents=True, exist_ok=True)
    if "--subdivd" in args:
        sub = args[args.index("--subdivd") + 1]
    res = capture(sub)
    text = json.dumps(res, indent=1, sort_keys=True) + "\n"
    if "--write" in args:
        (HERE / "manifest.json").write_text(text)
        print(f"wrote {HERE / 'manifest.json'}: {sum(len(v) for v in res.values())} answers")
    else:
        sys.stdout.write(text)
