#!/usr/bin/env bash
# The daemon's web dashboard in a real browser: tests/browser/dashboard.test.js starts
# `tactile daemon --sim`, drives headless Chromium through playwright-core (pinned by
# tests/browser/package-lock.json) and checks login, the live curve and E2, the field
# errors, the stop button, a foreign page and the reconnect after a restart. Needs
# Chromium at /usr/bin/chromium (Debian's `chromium` package), Node.js >= 20 and
# `npm ci` in tests/browser (.ci/run does all three). Prints "N passed, M failed" last;
# exits non-zero if any check failed.
#
#   scripts/dashboard-browser-test.sh
#   DASHBOARD_SCREENSHOT=docs/dashboard.png scripts/dashboard-browser-test.sh   # also the picture
set -uo pipefail
cd "$(dirname "$0")/.."

fail() {
    echo "$1" >&2
    echo "0 passed, 1 failed"
    exit 1
}
[ -x /usr/bin/chromium ] || fail "/usr/bin/chromium not found (apt-get install chromium)"
command -v node >/dev/null || fail "node not found (Node.js >= 20 drives the browser)"
[ -f tests/browser/node_modules/playwright-core/package.json ] \
    || fail "browser test packages missing: (cd tests/browser && npm ci)"

cargo build -p tactile --quiet || fail "cargo build -p tactile failed"
tactile="$(pwd)/target/debug/tactile"

shot=()
if [ -n "${DASHBOARD_SCREENSHOT:-}" ]; then
    shot=(--screenshot "$(pwd)/$DASHBOARD_SCREENSHOT")
fi
# The whole tier normally takes about a minute; the timeout bounds a wedged browser or
# daemon (the test's own waits are shorter and report what they waited for).
timeout 300 node tests/browser/dashboard.test.js --tactile "$tactile" "${shot[@]}"
status=$?
if [ "$status" -eq 124 ]; then
    echo "the browser test did not finish in 300 s" >&2
    echo "0 passed, 1 failed"
fi
exit "$status"
