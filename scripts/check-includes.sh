#!/usr/bin/env bash
# apps/ (the CLI) and bench/ (the benchmark programs) use vmap through its public headers only,
# as any program outside the library would. Every project include in their C++ files must be
#   "vmap/X.h"   with include/vmap/X.h present (the public API), or
#   "bench/X.h"  a benchmark's options and run function (in bench/, and in apps/, which
#                registers the benchmarks' subcommands), or
#   "apps/X.h"   in apps/ only (the CLI's own registration, apps/commands.h), or
#   "view/view_server.h" in apps/view_cmd.cpp only (the viewer's HTTP server: library vmap_view,
#                not part of the installed API);
# and none may name a header under src/ in any other way (<...> or a relative path). The one
# exception is bench/internal/: benchmarks of library parts without a public entry (the per-node
# link arrays), which time detail:: code and so include src/. Prints
# each include that breaks the rule, FILE:LINE: include, and exits 1 if there is one.
# Usage: scripts/check-includes.sh [ROOT]   (ctest: Layout.PublicHeadersOnly)
set -euo pipefail
root="${1:-$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)}"
cd "$root"
bad=0
while IFS=: read -r file line text; do
    target=$(sed -E 's/^[[:space:]]*#[[:space:]]*include[[:space:]]*[<"]([^>"]*)[>"].*/\1/' <<< "$text")
    dir=${file%%/*}
    ok=0
    if [[ "$text" =~ \#[[:space:]]*include[[:space:]]*\" ]]; then
        case "$target" in
            vmap/*.h) [[ -f "include/$target" ]] && ok=1 ;;
            bench/*.h) [[ -f "$target" ]] && ok=1 ;;
            apps/*.h) [[ $dir == apps && -f "$target" ]] && ok=1 ;;
            view/view_server.h) [[ $file == apps/view_cmd.cpp ]] && ok=1 ;;
        esac
    else
        # A system or library header: fine unless it is one of src/'s.
        [[ -e "src/$target" || "$target" == */src/* || "$target" == src/* ]] || ok=1
    fi
    if [[ $ok == 0 ]]; then
        echo "$file:$line: $target: apps/ and bench/ include only the public headers (include/vmap)"
        bad=1
    fi
done < <(grep -nE '^[[:space:]]*#[[:space:]]*include' \
    $(find apps bench -path bench/internal -prune -o -type f \( -name '*.cpp' -o -name '*.h' -o -name '*.hpp' -o -name '*.cu' \) -print | sort))
if [[ $bad == 0 ]]; then
    echo "apps/ and bench/: public headers only ($(find apps bench -type f \( -name '*.cpp' -o -name '*.h' \) | wc -l) files)"
fi
exit $bad
