"""A bounded random mutation run over HTTP against the newest request paths: POST /refine,
PUT /complex with details, diagonals and reoriented, PATCH /control-points with level moves and
?delta=, GET /levels/L/delta and /embedded/{name}/delta, GET /events (Last-Event-ID headers,
access_token), /analysis, PUT/GET/DELETE /embedded/{name}, and POST /v1/sessions {"import"} with
a mutated export document (docs/API.md, docs/SERVICE.md "Errors").

Valid requests are mutated at random (a node replaced by a hostile value — huge, negative,
fractional, of another type —, removed, repeated, wrapped, an array grown up to 1000 times, an
unknown member added; query values changed, repeated, dropped or added; bytes of the JSON text
damaged). Every answer must be a success or a problem+json whose `status` is the HTTP status,
never a 5xx (but 503 memory-budget); a refused change must leave the victim session's version
as it was; an accepted import must export again and import again; the daemon must stay up, with
no sanitizer report in its log (make sanitize runs it on the ASan/UBSan build, where a report
stops the daemon). Each request has a deadline: one that hangs is a finding.

The run is bounded by count and time, on loopback only: SD_FUZZ_ROUTES_COUNT (default 200),
SD_FUZZ_ROUTES_SECONDS (default 25, times 4 under the sanitizers: make test stays short; set
both higher for a longer run), SD_FUZZ_ROUTES_SEED (default 1). A finding is reported with the request that made it (method, path, body)."""
import copy
import json
import os
import random
import socket
import time

import requests

from conftest import REPO
from daemon import SLOW, Daemon

MIXED = json.loads((REPO / "examples" / "mixed.json").read_text())
MODEL = {"vertices": [[0.2, 0.2, 0.2], [0.3, 0.2, 0.2], [0.2, 0.3, 0.2]], "triangles": [[0, 1, 2]],
         "level": 1, "outside": "nearest"}
HOSTILE = [0, -1, 1, 2, 3, 4, 5, 7, 8, 12, 13, 17, 18, 255, 256, 65535, 2**31 - 1, 2**31,
           2**32 - 1, 2**32, 2**32 + 1, 2**52, 2**53, 2**53 + 1, 2**63 - 1, -2**63, -2**31, 0.5,
           -0.0, 1e-320, 1e15, 1.0000001e15, -1e15, 1e300, -1e300, 1.0, 4.0, "", "0", "1", "NaN",
           "a" * 300, "\u00e9", None, True, False, [], {}, [0], [[0]], [0, 0, 0], [1e300] * 3,
           {"a": 1}, [[0, 1, 2, 3]] * 3, list(range(50))]
QVALS = ["0", "-1", "1", "2", "12", "13", "4294967296", "9007199254740992", "18446744073709551616",
         "abc", "", "1.0", "%20", "%2B1", "02", "1e3", "%C3%A9", "height", "height,height", ",",
         "height,", ",".join("n%d" % i for i in range(300)), "t2", "json", "bin", "x",
         "points,points", "embedded", "solids", "0,1", "1,0", "3,5", "0,0"]
SEEDS_REFINE = [
    {"select": {"simplices": [[0, 1, 2, 3]]}, "depth": 1, "positions": "subdivision"},
    {"select": {"simplices": [[1, 2, 4], [3, 5]]}, "depth": 2},
    {"select": {"box": {"min": [0, 0, 0], "max": [1, 1, 1]}}, "depth": 1, "positions": "midpoint"},
    {"select": {"sphere": {"center": [0.2, 0.2, 0.2], "radius": 0.5}}, "depth": 1}]
SEEDS_PATCH = [
    {"moves": [{"index": 0, "position": [0, 0, 0.01]}]},
    {"moves": [{"index": 3, "level": 1, "position": [0, 0, 1.1]},
               {"index": 5, "level": 2, "position": [0.1, 0, 0]}]},
    {"moves": [{"index": 1, "level": 0, "position": [1, 0, 0.1]}],
     "attributes": {"height": [{"index": 1, "value": 3}], "t2": [{"index": 0, "value": [1, 1]}]}}]
Q_DELTA = ["", "?delta=2", "?delta=2&format=json", "?delta=1&format=bin&attributes=height",
           "?delta=2&format=json&attributes=height,t2&parts=solids,surfaces"]


class Fuzz:
    def __init__(self, url, seed):
        assert url.startswith("http://127.0.0.1:")
        self.url, self.rng, self.http = url, random.Random(seed), requests.Session()
        self.findings = []

    # ---- mutations ----
    def hostile(self):
        return copy.deepcopy(self.rng.choice(HOSTILE))

    @staticmethod
    def paths(x, p=()):
        yield p
        if isinstance(x, dict):
            for k, v in x.items():
                yield from Fuzz.paths(v, p + (k,))
        elif isinstance(x, list):
            for i, v in enumerate(x):
                yield from Fuzz.paths(v, p + (i,))

    def mutate(self, doc, n=None):
        rng = self.rng
        doc = copy.deepcopy(doc)
        for _ in range(n or rng.choice([1, 1, 1, 2, 3])):
            p = rng.choice(list(self.paths(doc)))
            if not p:
                if rng.random() < 0.1:
                    return self.hostile()
                continue
            parent = doc
            for k in p[:-1]:
                parent = parent[k]
            k, v, op = p[-1], parent[p[-1]], rng.random()
            if op < 0.45:
                parent[k] = self.hostile()
            elif op < 0.55:
                del parent[k]
            elif op < 0.65:
                if isinstance(parent, list):
                    parent.insert(rng.randrange(len(parent) + 1), copy.deepcopy(v))
                else:
                    parent[rng.choice(["x", k + "_", "import", "level", "since", ""])] = self.hostile()
            elif op < 0.72:
                parent[k] = [v]
            elif op < 0.78:
                parent[k] = v * rng.choice([2, 10, 100, 1000]) if isinstance(v, list) and v else self.hostile()
            elif op < 0.85 and isinstance(v, (int, float)) and not isinstance(v, bool):
                parent[k] = rng.choice([v + 1, v - 1, -v, v * 2**32, v + 0.5])
            elif op < 0.92 and isinstance(parent, list) and len(parent) > 1:
                i, j = rng.randrange(len(parent)), rng.randrange(len(parent))
                parent[i], parent[j] = parent[j], parent[i]
            else:
                parent[k] = rng.choice([None, "x", 3.5, -1, [], {}])
        return doc

    def damage(self, text):
        rng, b = self.rng, bytearray(text.encode())
        op = rng.random()
        if op < 0.3 and b:
            i = rng.randrange(len(b))
            b[i:i + 1] = rng.choice([b"NaN", b"Infinity", b"-", b"1e999", b"\xff", b"\"", b"{", b"]",
                                     b"\\u0000", b"99999999999999999999999", b"", b"  "])
        elif op < 0.5:
            b = b[:rng.randrange(len(b) + 1)]
        elif op < 0.6:
            b = b"[" * 40 + b + b"]" * 40
        else:
            b = b.replace(b"]", b"]]", 1)
        return bytes(b)

    def qmut(self, q):
        rng = self.rng
        parts = [x for x in q.lstrip("?").split("&") if x]
        op = rng.random()
        if op < 0.5 and parts:
            i = rng.randrange(len(parts))
            parts[i] = parts[i].split("=")[0] + "=" + rng.choice(QVALS)
        elif op < 0.65 and parts:
            parts.append(rng.choice(parts))
        elif op < 0.8:
            parts.append(rng.choice(["since", "delta", "format", "attributes", "parts", "x", "vertex",
                                     "edge", "level", "outside", "access_token"]) + "=" + rng.choice(QVALS))
        elif parts:
            parts.pop(rng.randrange(len(parts)))
        return "?" + "&".join(parts) if parts else ""

    # ---- the victim session ----
    def reset(self):
        j = self.http.post(self.url + "/v1/sessions", json={}, timeout=30).json()
        self.id, self.tok = j["id"], j["token"]
        self.base = f"{self.url}/v1/sessions/{self.id}"
        self.h = {"Authorization": "Bearer " + self.tok}
        b = copy.deepcopy(MIXED)
        b["attributes"]["t2"] = [[1, 2]] * 8
        assert self.http.put(self.base + "/complex", json=b, headers=self.h, timeout=60).status_code == 200
        self.http.get(self.base + "/levels/2", headers=self.h, timeout=60)
        assert self.http.put(self.base + "/embedded/m", json=MODEL, headers=self.h, timeout=60).status_code == 200
        self.ver = self.version()

    def version(self):
        return self.http.get(self.base, headers=self.h, timeout=30).json()["version"]

    def finding(self, kind, **info):
        self.findings.append(dict(kind=kind, **info))

    def send(self, method, url, **kw):
        try:
            return self.http.request(method, url, timeout=60 * SLOW, **kw)
        except requests.exceptions.RequestException as e:
            self.finding("no-answer", method=method, path=url.replace(self.url, ""),
                         body=str(kw.get("data"))[:2000], error=str(e)[:200])
            return None

    def check(self, r, body, changing):
        info = {"method": r.request.method, "path": r.request.url.replace(self.url, ""),
                "body": body.decode("latin-1")[:2000] if isinstance(body, bytes) else body,
                "status": r.status_code, "answer": r.text[:400]}
        ct = r.headers.get("Content-Type", "")
        if r.status_code >= 500 and not (r.status_code == 503 and "memory-budget" in r.text):
            self.finding("5xx", **info)
        elif r.status_code >= 400 and not ct.startswith("text/html"):   # (MHD's own pages)
            try:
                j = r.json()
                ok = ct == "application/problem+json" and j["status"] == r.status_code and \
                    j["type"].startswith("/errors/")
            except (ValueError, KeyError, TypeError):
                ok = False
            if not ok:
                self.finding("not-a-problem", **info)
        if changing and r.status_code >= 400 and self.version() != self.ver:
            self.finding("changed-on-refusal", before=self.ver, **info)

    # ---- one request of each kind ----
    def events(self):
        rng = self.rng
        lines = [f"GET /v1/sessions/{self.id}/events" + rng.choice(
            ["", "?access_token=" + self.tok, "?access_token=bad",
             f"?access_token={self.tok}&access_token={self.tok}", "?x=1"]) + " HTTP/1.1",
            "Host: 127.0.0.1"]
        for _ in range(rng.randrange(3)):
            lines.append("Last-Event-ID: " + rng.choice(
                ["0", "-1", "1", str(self.ver), str(self.ver + 1), "18446744073709551615",
                 "18446744073709551616", "abc", "", "9" * 400, "1,2", "1 2"]))
        auth = rng.choice(["Authorization: Bearer " + self.tok, "Authorization: Bearer bad", None])
        lines += [auth] if auth else []
        host, port = self.url.split("//")[1].split(":")
        buf = b""
        with socket.create_connection((host, int(port)), timeout=5 * SLOW) as c:
            c.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
            end = time.time() + 0.3
            try:
                while time.time() < end and not (b"\r\n\r\n" in buf and rng.random() < 0.5):
                    d = c.recv(4096)   # (then closed mid-stream)
                    if not d:
                        break
                    buf += d
            except socket.timeout:
                pass
        status = int(buf.split(b" ", 2)[1]) if buf.startswith(b"HTTP/1.1 ") else 0
        if not status or status >= 500:
            self.finding("events", request=lines, answer=buf[:300].decode("latin-1"))

    def one(self):
        rng, hj = self.rng, dict(self.h, **{"Content-Type": "application/json"})
        target = rng.choice(["refine", "complex", "patch", "delta", "events", "analysis",
                             "embedded", "import", "raw"])
        if target == "events":
            return self.events()
        if target == "refine":
            body = self.mutate(rng.choice(SEEDS_REFINE))
            r, ch = self.send("POST", self.base + "/refine", headers=hj, data=json.dumps(body)), True
        elif target == "complex":
            body = self.mutate(self.cx_seed, rng.choice([1, 2]))
            r, ch = self.send("PUT", self.base + "/complex", headers=hj, data=json.dumps(body)), True
        elif target == "patch":
            body = self.mutate(rng.choice(SEEDS_PATCH)) if rng.random() < 0.8 else rng.choice(SEEDS_PATCH)
            q = rng.choice(Q_DELTA)
            q = self.qmut(q) if rng.random() < 0.6 else q
            im = '"%d"' % self.ver if rng.random() < 0.85 else rng.choice(
                ["*", '"0"', 'W/"%d"' % self.ver, '"x"', '"%d", "%d"' % (self.ver, self.ver + 1), ""])
            r = self.send("PATCH", self.base + "/control-points" + q, headers=dict(hj, **{"If-Match": im}),
                          data=json.dumps(body))
            body, ch = {"query": q, "if-match": im, "body": body}, True
        elif target == "delta":
            L = rng.choice(["0", "1", "2", "2", "3", "12", "13", "-1", "x", "02", "99999999999999999999"])
            q = self.qmut("?since=%d&format=json&attributes=height" % max(0, self.ver - rng.randrange(3)))
            if rng.random() < 0.2:   # a change first, so that deltas are not empty
                self.http.patch(self.base + "/control-points", json=rng.choice(SEEDS_PATCH),
                                headers=dict(self.h, **{"If-Match": '"%d"' % self.ver}), timeout=60)
                self.ver = self.version()
            path = f"/levels/{L}/delta{q}" if rng.random() < 0.8 else f"/embedded/m/delta{q}"
            r, body, ch = self.send("GET", self.base + path, headers=self.h), None, True
        elif target == "analysis":
            q = self.qmut(rng.choice(["?vertex=0", "?edge=0,1", "?vertex=7", "?edge=3,5"]))
            r, body, ch = self.send("GET", self.base + "/analysis" + q, headers=self.h), None, False
        elif target == "embedded":
            name = rng.choice(["m", "n", "a" * 48, "a" * 49, "a" * 64, "a" * 65, "%C3%A9", "a.b",
                               "a%2Fb", "%2e%2e", "a%25", "-", "m%20"])
            method = rng.choice(["PUT", "PUT", "PUT", "GET", "DELETE"])
            body = self.mutate(MODEL)
            q = self.qmut(rng.choice(["", "?level=1", "?outside=fixed"])) if rng.random() < 0.3 else ""
            hh = dict(hj, **({"If-Match": rng.choice(['"%d"' % self.ver, '"0"', "*"])}
                             if rng.random() < 0.2 else {}))
            r = self.send(method, self.base + "/embedded/" + name + q, headers=hh,
                          data=json.dumps(body) if method == "PUT" else None)
            body, ch = {"name": name, "query": q, "body": body}, True
        elif target == "import":
            body = {"import": self.mutate(self.export_seed, rng.choice([1, 1, 2, 3]))}
            if rng.random() < 0.1:
                body["ttl_s"] = self.hostile()
            r = self.send("POST", self.url + "/v1/sessions", headers={"Content-Type": "application/json"},
                          data=json.dumps(body))
            ch = False
            if r is not None and r.status_code == 201:
                self.imported(r.json(), body)
        else:   # byte-level damage of a valid body
            which = rng.choice(["refine", "complex", "patch", "import", "embedded"])
            method, url, text = {
                "refine": ("POST", self.base + "/refine", json.dumps(rng.choice(SEEDS_REFINE))),
                "complex": ("PUT", self.base + "/complex", json.dumps(self.cx_seed)),
                "patch": ("PATCH", self.base + "/control-points?delta=2", json.dumps(rng.choice(SEEDS_PATCH))),
                "embedded": ("PUT", self.base + "/embedded/m", json.dumps(MODEL)),
                "import": ("POST", self.url + "/v1/sessions", json.dumps({"import": self.export_seed}))}[which]
            body = self.damage(text)
            r = self.send(method, url, headers=dict(hj, **{"If-Match": '"%d"' % self.ver}), data=body)
            ch = which != "import"
        if r is not None:
            self.check(r, body, ch)

    def imported(self, j, body):
        """An accepted import exports again, imports again, and serves its level 1."""
        h = {"Authorization": "Bearer " + j["token"]}
        base = f"{self.url}/v1/sessions/{j['id']}"
        ex = self.http.get(base + "/export", headers=h, timeout=60 * SLOW)
        if ex.status_code != 200:
            self.finding("import-export", body=body, answer=ex.text[:400])
        else:
            again = self.http.post(self.url + "/v1/sessions", json={"import": ex.json()}, timeout=60 * SLOW)
            if again.status_code != 201:
                self.finding("reimport", body=body, answer=again.text[:400])
            else:
                a = again.json()
                self.http.delete(f"{self.url}/v1/sessions/{a['id']}",
                                 headers={"Authorization": "Bearer " + a["token"]}, timeout=30)
        lv = self.http.get(base + "/levels/1?format=json", headers=h, timeout=60 * SLOW)
        if lv.status_code >= 500:
            self.finding("import-level", body=body, answer=lv.text[:400])
        self.http.delete(base, headers=h, timeout=30)

    def run(self, count, seconds, alive):
        self.reset()
        self.export_seed = self.http.get(self.base + "/export", headers=self.h, timeout=30).json()
        cx = self.export_seed["complex"]
        cx.update(details=[{"level": 1, "index": 3, "offset": [0.1, 0, 0]},
                           {"level": 2, "index": 10, "offset": [0, 0.1, 0]}],
                  diagonals=[[0, 1]], reoriented=[0])
        self.cx_seed = cx
        t0, n = time.time(), 0
        while n < count and time.time() - t0 < seconds and alive() and len(self.findings) < 20:
            n += 1
            if n % 60 == 0 or self.version() > self.ver + 40:
                self.reset()
            self.ver = self.version()
            self.one()
        return n


def test_fuzz_new_routes():
    count = int(os.environ.get("SD_FUZZ_ROUTES_COUNT", "200"))
    seconds = float(os.environ.get("SD_FUZZ_ROUTES_SECONDS", "25")) * SLOW
    seed = int(os.environ.get("SD_FUZZ_ROUTES_SEED", "1"))
    d = Daemon("--max-sessions", "64", "--max-session-bytes", str(256 << 20))
    try:
        f = Fuzz(d.url, seed)
        n = f.run(count, seconds, d.alive)
        reports = [line for line in d.log_lines
                   if "AddressSanitizer" in line or "runtime error" in line or "LeakSanitizer" in line]
        assert d.alive() and not reports, (n, reports[:20], f.findings[:3])
        assert not f.findings, json.dumps(f.findings[:5], indent=1)[:6000]
        assert requests.get(d.url + "/healthz", timeout=10).status_code == 200
        assert n >= min(count, 50), n
    finally:
        d.stop()
