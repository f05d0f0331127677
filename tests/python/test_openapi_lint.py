"""The served OpenAPI document (/v1/openapi.json) passes Redocly's linter (@redocly/cli of
tests/tools/package.json, its built-in recommended rules) without errors, and every operation
documents its 4XX answers, with no warning either; its license is the repository's (LICENSE, the
GNU AGPL v3 or later, DECISIONS 40)."""
import json
import os
import subprocess

import pytest
import requests

from conftest import REPO
from daemon import Daemon

REDOCLY = REPO / "tests" / "tools" / "node_modules" / ".bin" / "redocly"
ALLOWED_WARNINGS = set()
METHODS = ("get", "put", "post", "patch", "delete")


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    d = Daemon()
    try:
        r = requests.get(d.url + "/v1/openapi.json", timeout=10)
        assert r.status_code == 200
    finally:
        d.stop()
    path = tmp_path_factory.mktemp("openapi") / "openapi.json"
    path.write_bytes(r.content)
    return path


def test_every_operation_has_4xx_answers(served):
    doc = json.loads(served.read_text(encoding="utf-8"))
    ids = []
    for p, item in doc["paths"].items():
        for m in METHODS:
            if m in item:
                op = item[m]
                ids.append(op["operationId"])
                codes = set(op["responses"])
                assert any(c.startswith("4") for c in codes), f"{m.upper()} {p}: no 4XX answer"
                assert "400" in codes, f"{m.upper()} {p}: every route refuses unknown parameters"
    assert len(ids) == len(set(ids)), "operationIds are unique"


def test_redocly_lint(served):
    if not REDOCLY.exists():
        pytest.skip(f"{REDOCLY} is not installed: (cd tests/tools && npm install), or make deps")
    env = dict(os.environ, REDOCLY_TELEMETRY="off", REDOCLY_SUPPRESS_UPDATE_NOTICE="true",
               NO_COLOR="1")
    r = subprocess.run([str(REDOCLY), "lint", "--format=json", str(served)], capture_output=True,
                       encoding="utf-8", env=env, cwd=served.parent, timeout=120)
    out = r.stdout[r.stdout.index("{"):] if "{" in r.stdout else r.stdout
    report = json.loads(out)
    problems = [(p["severity"], p["ruleId"], p["message"], p["location"][0].get("pointer"))
                for p in report["problems"]]
    errors = [p for p in problems if p[0] == "error"]
    assert not errors and r.returncode == 0, errors or r.stderr
    warnings = [p for p in problems if p[0] == "warn" and p[1] not in ALLOWED_WARNINGS]
    assert not warnings, warnings
