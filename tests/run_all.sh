#!/bin/sh
# Runs every test suite of the project and ends with one line: "N passed, N failed".
# Binaries can be overridden (make sanitize points them at the ASan/UBSan build).
set -u
cd "$(dirname "$0")/.."
TEST_CORE=${TEST_CORE:-build/test_core}
SDLEVEL=${SDLEVEL:-build/sdlevel}
PYTHON=${PYTHON:-/usr/bin/python3}
export SDLEVEL
# big core blocks kept between builds are handed out filled with 0xff bytes, so a reader of
# memory the core did not write shows in the results (api/mem.c)
SUBDIVD_KEEP_POISON=${SUBDIVD_KEEP_POISON:-1}
export SUBDIVD_KEEP_POISON
passed=0
failed=0

# 1. C unit tests of the core
out=$("$TEST_CORE" 2>&1)
rc=$?
printf '%s\n' "$out"
line=$(printf '%s\n' "$out" | grep -E '^core: [0-9]+ passed, [0-9]+ failed$' | tail -n 1)
if [ -n "$line" ]; then
    p=$(echo "$line" | sed -E 's/^core: ([0-9]+) passed, ([0-9]+) failed$/\1/')
    f=$(echo "$line" | sed -E 's/^core: ([0-9]+) passed, ([0-9]+) failed$/\2/')
    passed=$((passed + p))
    failed=$((failed + f))
    [ "$rc" -ne 0 ] && [ "$f" -eq 0 ] && failed=$((failed + 1))
else
    echo "test_core did not finish (exit $rc)"
    failed=$((failed + 1))
fi

# 2. Python suites (oracles, peers, tools)
mkdir -p build
"$PYTHON" -m pytest -q -p no:cacheprovider --junitxml=build/pytest.xml tests/python
rc=$?
if [ "$rc" -eq 5 ]; then
    echo "pytest collected no tests"
    failed=$((failed + 1))
elif [ -f build/pytest.xml ]; then
    counts=$("$PYTHON" - <<'PY'
import xml.etree.ElementTree as ET
r = ET.parse("build/pytest.xml").getroot()
s = r if r.tag == "testsuite" else r.find("testsuite")
t, f, e, k = (int(s.get(a, 0)) for a in ("tests", "failures", "errors", "skipped"))
print(t - f - e - k, f + e)
PY
)
    passed=$((passed + ${counts% *}))
    failed=$((failed + ${counts#* }))
    [ "$rc" -ne 0 ] && [ "${counts#* }" -eq 0 ] && failed=$((failed + 1))
else
    echo "pytest did not run (exit $rc)"
    failed=$((failed + 1))
fi

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
