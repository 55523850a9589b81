#!/usr/bin/env bash
# `vmap view` as a process: exit codes (1 input, 2 usage) with one-line messages, the loopback
# bind, a request over TCP, clean stops on SIGTERM and SIGINT (exit 0), a port in use, and an
# interrupt while building (exit 130). Needs no browser: the page is a stand-in folder.
# Usage: view_cli_test.sh <path-to-vmap-binary> <source-dir>
set -u
VMAP=$(realpath "$1")
SRC=$(realpath "$2")
WORK=$(mktemp -d "${TMPDIR:-/tmp}/vmap_view_cli.XXXXXX")
pids=()
cleanup() {
    for p in "${pids[@]}"; do kill -KILL "$p" 2>/dev/null; done
    rm -rf "$WORK"
}
trap cleanup EXIT
cd "$WORK" || exit 1
failures=0
fail() { echo "FAIL: $*"; failures=$((failures + 1)); }
ok() { echo "ok:   $*"; }
expect() {  # expect RC WORDS ARGS...: exit status RC and WORDS on stderr
    local want=$1 words=$2
    shift 2
    "$VMAP" "$@" >out.txt 2>err.txt
    local rc=$?
    if [ "$rc" -eq "$want" ] && grep -qF -- "$words" err.txt && [ "$(wc -l <err.txt)" -le 2 ]; then
        ok "vmap $* -> $rc, '$words'"
    else
        fail "vmap $* -> $rc (want $want, '$words'): $(head -3 err.txt)"
    fi
}

mkdir -p web/vendor empty
echo '<!doctype html><p>stand-in</p>' >web/index.html
echo '// stand-in' >web/vendor/three.module.js
"$VMAP" build "$SRC/scenes/cornell-bunny.json" --points 1000 --max-height 5 -o small.vmap \
    >/dev/null || { echo "FAIL: building small.vmap"; exit 1; }

expect 1 "missing.vmap" view missing.vmap --web web
expect 1 "three.module.js: missing" view small.vmap --web empty
expect 1 "apply when building" view small.vmap --web web --points 10
expect 2 "--port" view small.vmap --web web --port 70000
expect 2 "--backend" view small.vmap --web web --backend gpu

# start_view LOG ARGS...: starts the server in the background; sets $pid and $port.
start_view() {
    local log=$1
    shift
    "$VMAP" view small.vmap --web web "$@" >"$log" 2>&1 &
    pid=$!
    pids+=("$pid")
    port=""
    for _ in $(seq 100); do
        port=$(sed -n 's|^url: *http://127\.0\.0\.1:\([0-9]*\)/.*|\1|p' "$log")
        [ -n "$port" ] && return 0
        sleep 0.1
    done
    return 1
}
# http_get PORT PATH [HOST]: the status line of a GET over bash's /dev/tcp (Host: HOST, by default
# 127.0.0.1:PORT).
http_get() {
    exec 3<>"/dev/tcp/127.0.0.1/$1" || return 1
    printf 'GET %s HTTP/1.1\r\nHost: %s\r\nConnection: close\r\n\r\n' "$2" "${3:-127.0.0.1:$1}" >&3
    head -1 <&3 | tr -d '\r'
    exec 3<&-
}
# stops SIGNAL WORD: the server stops on SIGNAL with exit 0 and says so.
stops() {
    kill "-$1" "$pid"
    wait "$pid"
    local rc=$?
    if [ "$rc" -eq 0 ] && grep -q "stopped\." "$log"; then ok "$1 stops it, exit 0"; else
        fail "$1: exit $rc: $(tail -2 "$log")"
    fi
}

log=view1.txt
if start_view "$log"; then
    ok "serves on 127.0.0.1:$port"
    # The listening socket's local address in /proc/net/tcp is 127.0.0.1 (0100007F).
    hexport=$(printf '%04X' "$port")
    if grep -qE "^ *[0-9]+: 0100007F:$hexport 00000000:0000 0A" /proc/net/tcp; then
        ok "bound to the loopback address only"
    else
        fail "no listening socket 127.0.0.1:$port in /proc/net/tcp"
    fi
    status=$(http_get "$port" /api/info)
    [[ "$status" == *" 200 "* ]] && ok "GET /api/info: $status" || fail "GET /api/info: $status"
    status=$(http_get "$port" /../../etc/passwd)
    [[ "$status" == *" 404 "* || "$status" == *" 400 "* ]] && ok "GET /../../etc/passwd: $status" ||
        fail "GET /../../etc/passwd: $status"
    status=$(http_get "$port" /api/info "rebound.example:$port")
    [[ "$status" == *" 403 "* ]] && ok "Host rebound.example: $status" ||
        fail "Host rebound.example: $status"
    expect 1 "cannot listen" view small.vmap --web web --port "$port"
    stops TERM
else
    fail "vmap view did not print its URL: $(cat "$log")"
fi

log=view2.txt
if start_view "$log"; then stops INT; else fail "second start: $(cat "$log")"; fi

# An interrupt while the V-map is still being built ends at once with 130.
"$VMAP" view "$SRC/scenes/cornell-bunny.json" --web web --points 40000 >build.txt 2>&1 &
pid=$!
pids+=("$pid")
sleep 1
kill -INT "$pid"
wait "$pid"
rc=$?
if [ "$rc" -eq 130 ] && grep -q "interrupted" build.txt; then ok "SIGINT while building: 130"; else
    fail "SIGINT while building: exit $rc: $(tail -2 build.txt)"
fi

[ "$failures" -eq 0 ] && echo "all view CLI checks passed" || echo "$failures view CLI checks failed"
exit $((failures > 0))
