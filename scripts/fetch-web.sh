#!/usr/bin/env bash
# Fetches what `vmap view` and its browser test need from the npm registry, into git-ignored
# folders, caching the downloads in ${VMAP_CACHE:-$HOME/.cache/vmap}. Idempotent. Needs npm.
#   three.js (the page's WebGL): `npm pack three@0.170.0`, the two files the page loads copied
#     into web/vendor/ (never `npm install`: nothing of it runs here).
#   puppeteer-core (drives Debian's chromium in tests/browser): `npm install --ignore-scripts`
#     into tests/browser/node_modules/ (puppeteer-core downloads no browser).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cache="${VMAP_CACHE:-$HOME/.cache/vmap}"
three_version=0.170.0
puppeteer_version=24.43.1
mkdir -p "$cache"

vendor="$root/web/vendor"
if [[ ! -s "$vendor/three.module.js" || ! -s "$vendor/OrbitControls.js" ||
      "$(cat "$vendor/VERSION" 2>/dev/null)" != "three@$three_version" ]]; then
    tgz="$cache/three-$three_version.tgz"
    if [[ ! -s "$tgz" ]]; then
        echo "fetch-web: npm pack three@$three_version" >&2
        (cd "$cache" && npm pack --silent "three@$three_version" >/dev/null)
    fi
    tmp=$(mktemp -d)
    tar xzf "$tgz" -C "$tmp" package/build/three.module.js \
        package/examples/jsm/controls/OrbitControls.js package/LICENSE
    mkdir -p "$vendor"
    cp "$tmp/package/build/three.module.js" "$tmp/package/examples/jsm/controls/OrbitControls.js" \
        "$vendor/"
    cp "$tmp/package/LICENSE" "$vendor/LICENSE-three"
    echo "three@$three_version" > "$vendor/VERSION"
    rm -rf "$tmp"
fi

nm="$root/tests/browser/node_modules"
if [[ "$(cat "$nm/puppeteer-core/package.json" 2>/dev/null | grep -o "\"version\": *\"[^\"]*\"" \
        | head -1)" != *"\"$puppeteer_version\"" ]]; then
    echo "fetch-web: npm install puppeteer-core@$puppeteer_version" >&2
    npm install --silent --prefix "$root/tests/browser" --no-save --no-package-lock \
        --ignore-scripts --no-audit --no-fund "puppeteer-core@$puppeteer_version" >/dev/null
fi
echo "fetch-web: three.js in $vendor, puppeteer-core in $nm" >&2
