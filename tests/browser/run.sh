#!/usr/bin/env bash
# CTest entry for the browser test: skipped (exit 77, reported SKIPPED, never passed) when node
# is missing; view_browser_test.mjs skips itself when chromium, puppeteer-core or three.js are.
# Usage: tests/browser/run.sh VMAP_BINARY SOURCE_DIR
set -euo pipefail
if ! command -v node >/dev/null; then
    echo "SKIPPED: node not found (scripts/setup.sh installs npm and node)"
    exit 77
fi
exec node "$(dirname "${BASH_SOURCE[0]}")/view_browser_test.mjs" "$@"
