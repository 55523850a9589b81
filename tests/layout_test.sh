#!/usr/bin/env bash
# scripts/check-includes.sh: the tree passes (apps/ and bench/ on the public headers only), and
# a copy with one include of each forbidden kind planted fails, naming every one of them.
# Usage: tests/layout_test.sh SOURCE_DIR
set -euo pipefail
src="${1:?usage: layout_test.sh SOURCE_DIR}"
"$src/scripts/check-includes.sh" "$src"
t=$(mktemp -d)
trap 'rm -rf "$t"' EXIT
cp -r "$src/apps" "$src/bench" "$src/include" "$t/"
mkdir -p "$t/src/visibility" && touch "$t/src/visibility/backend.h"
printf '#include "visibility/backend.h"\n#include "apps/commands.h"\n#include <visibility/backend.h>\n' \
    >> "$t/bench/bench.cpp"
printf '#include "vmap/no_such_header.h"\n#include "view/view_server.h"\n' >> "$t/apps/info_cmd.cpp"
if "$src/scripts/check-includes.sh" "$t" > "$t/out"; then
    echo "FAIL: planted includes passed"; exit 1
fi
cat "$t/out"
for want in "bench/bench.cpp:.*: visibility/backend.h" "bench/bench.cpp:.*: apps/commands.h" \
            "apps/info_cmd.cpp:.*: vmap/no_such_header.h" "apps/info_cmd.cpp:.*: view/view_server.h"; do
    grep -q "$want" "$t/out" || { echo "FAIL: not reported: $want"; exit 1; }
done
[[ $(wc -l < "$t/out") == 5 ]] || { echo "FAIL: expected 5 reports"; exit 1; }
echo "PASS"
