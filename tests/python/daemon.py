"""Start the real subdivd on a free loopback port and talk to it (the HTTP suites' harness).

SUBDIVD may point at another build of the daemon (make sanitize uses the ASan one).

The suites create many sessions quickly, all from 127.0.0.1, so a Daemon passes
`--session-rate 1000000` unless its flags set --session-rate themselves (the hardening tests of
the per-client rate do), and lifts the per-client caps of the table and the store likewise."""
import http.client
import json
import os
import pathlib
import re
import subprocess
import threading
import time

import requests

from conftest import REPO

SUBDIVD = pathlib.Path(os.environ.get("SUBDIVD", str(REPO / "build" / "subdivd"))).resolve()
# make sanitize runs the suites on its ASan/UBSan build: that allocator keeps freed blocks in
# quarantine and pads every block (resident size does not follow what the daemon holds), and the
# daemon runs a few times slower. Tests of resident size skip there; time bounds scale by SLOW.
SANITIZED = os.environ.get("SD_SANITIZE") == "1"
SLOW = 4.0 if SANITIZED else 1.0


class Daemon:
    """One daemon process; `url` is its base URL. Logs are kept in `log_lines`."""

    def __init__(self, *flags, env=None, wait_ready=True):
        self.log_lines = []
        e = dict(os.environ)
        e.update(env or {})
        if not any(str(f).startswith("--session-rate") for f in flags):
            flags = ("--session-rate", "1000000", *flags)
        if not any(str(f).startswith("--max-sessions-per-client") for f in flags):
            flags = ("--max-sessions-per-client", "0", *flags)
        if not any(str(f).startswith("--max-stored-sessions-per-client") for f in flags):
            flags = ("--max-stored-sessions-per-client", "0", *flags)
        self.proc = subprocess.Popen([str(SUBDIVD), "--port", "0", "--log-level", "info", *flags],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     env=e)
        line = self.proc.stdout.readline()
        m = re.search(r"http://([\d.]+):(\d+)/", line)
        if not m:
            self.proc.kill()
            raise RuntimeError(f"subdivd did not start: {line!r} {self.proc.stderr.read()}")
        self.url = f"http://{m.group(1)}:{m.group(2)}"
        self._t = threading.Thread(target=self._drain, daemon=True)
        self._t.start()
        deadline = time.time() + (10 if wait_ready else 0)
        while time.time() < deadline:
            try:
                if requests.get(self.url + "/readyz", timeout=1).status_code == 200:
                    break
            except requests.ConnectionError:
                time.sleep(0.05)

    def _drain(self):
        for line in self.proc.stderr:
            self.log_lines.append(line.rstrip("\n"))

    def alive(self):
        return self.proc.poll() is None

    def stop(self, sig_term=True):
        if self.proc.poll() is None:
            self.proc.terminate() if sig_term else self.proc.kill()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._t.join(2)
        return self.proc.returncode

    def rss_bytes(self):
        for line in open(f"/proc/{self.proc.pid}/status"):
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
        return 0


class Session:
    """A session on a daemon: request helpers that add the bearer token."""

    def __init__(self, daemon, http=None, ttl_s=None):
        self.d = daemon
        self.http = http or requests.Session()
        r = self.http.post(daemon.url + "/v1/sessions", json={} if ttl_s is None else {"ttl_s": ttl_s})
        assert r.status_code == 201, r.text
        j = r.json()
        self.id, self.token = j["id"], j["token"]
        self.base = f"{daemon.url}/v1/sessions/{self.id}"
        self.auth = {"Authorization": f"Bearer {self.token}"}

    def req(self, method, path="", **kw):
        headers = dict(self.auth)
        headers.update(kw.pop("headers", {}))
        return self.http.request(method, self.base + path, headers=headers, timeout=120, **kw)

    def put_complex(self, body, **kw):
        return self.req("PUT", "/complex", json=body, **kw)

    def level(self, level, **params):
        return self.req("GET", f"/levels/{level}", params=params)

    def delete(self):
        return self.req("DELETE")


def create_from(d, src, ttl_s=600):
    """POST /v1/sessions from the loopback address src: (status, Retry-After, body)."""
    host, port = d.url.split("//")[1].split(":")
    c = http.client.HTTPConnection(host, int(port), timeout=10, source_address=(src, 0))
    c.request("POST", "/v1/sessions", json.dumps({"ttl_s": ttl_s}),
              {"Content-Type": "application/json"})
    r = c.getresponse()
    out = (r.status, r.getheader("Retry-After"), json.loads(r.read() or b"null"))
    c.close()
    return out


def complex_from_text(path):
    """The PUT /complex body of a mesh in the text format of docs/TEXT_FORMAT.md."""
    verts, simp, attrs = [], [], {}
    for line in pathlib.Path(path).read_text().splitlines():
        t = line.split("#", 1)[0].split()
        if not t:
            continue
        if t[0] == "v":
            verts.append([float(x) for x in t[1:4]])
        elif t[0] == "s":
            simp.append([int(x) for x in t[1:]])
    return {"vertices": verts, "simplices": simp}
