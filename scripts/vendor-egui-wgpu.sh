#!/usr/bin/env bash
# The vendored egui-wgpu (vendor/egui-wgpu, used through [patch.crates-io]): the published
# crate plus vendor/egui-wgpu.patch (what and why: vendor/egui-wgpu/VOYAGE.md).
#
#   bash scripts/vendor-egui-wgpu.sh check     the version eframe uses is the vendored one and
#                                              the patch is in use (offline; CI runs it)
#   bash scripts/vendor-egui-wgpu.sh verify    also: vendor/egui-wgpu is exactly the published
#                                              crate with the patch applied (downloads the crate)
#   bash scripts/vendor-egui-wgpu.sh apply [VERSION]
#                                              rebuild vendor/egui-wgpu from the published crate
#                                              (default: the vendored version) and the patch; on
#                                              an upgrade, a hunk that no longer applies is named
set -euo pipefail
cd "$(dirname "$0")/.."
VENDOR=vendor/egui-wgpu
PATCH=vendor/egui-wgpu.patch

vendored_version() { sed -n 's/^version = "\(.*\)"$/\1/p' "$VENDOR/Cargo.toml" | head -n1; }

# The version of a package in Cargo.lock, and whether it comes from a registry.
lock_entry() {
    awk -v name="$1" '
        /^\[\[package\]\]/ { if (found) exit; p = 0 }
        $0 == "name = \"" name "\"" { p = 1; found = 1 }
        p && /^version = / { gsub(/"/, "", $3); printf "%s", $3 }
        p && /^source = / { printf " registry" }
    ' Cargo.lock
}

check() {
    local vendored eframe wgpu_entry
    vendored=$(vendored_version)
    eframe=$(lock_entry eframe)
    wgpu_entry=$(lock_entry egui-wgpu)
    [[ -n "$vendored" && -n "$eframe" ]] || { echo "error: cannot read the versions (Cargo.lock, $VENDOR/Cargo.toml)" >&2; exit 1; }
    if [[ "${eframe%% *}" != "$vendored" ]]; then
        echo "error: eframe is ${eframe%% *} but $VENDOR is $vendored: run 'bash scripts/vendor-egui-wgpu.sh apply ${eframe%% *}' (or drop the patch)" >&2
        exit 1
    fi
    if [[ "$wgpu_entry" != "$vendored" ]]; then
        echo "error: Cargo.lock's egui-wgpu is '$wgpu_entry', not the vendored $vendored: the [patch.crates-io] entry is not in use" >&2
        exit 1
    fi
    grep -q "^egui-wgpu = { path = \"$VENDOR\" }" Cargo.toml || { echo "error: Cargo.toml has no [patch.crates-io] entry for $VENDOR" >&2; exit 1; }
    echo "egui-wgpu $vendored: vendored, patched, in use"
}

# Unpacks the published crate VERSION into the folder $2.
fetch() {
    local version=$1 out=$2 crate
    crate=$(ls ~/.cargo/registry/cache/*/"egui-wgpu-$version.crate" 2>/dev/null | head -n1 || true)
    mkdir -p "$out"
    if [[ -n "$crate" ]]; then
        tar xzf "$crate" -C "$out"
    else
        curl -fsSL "https://static.crates.io/crates/egui-wgpu/egui-wgpu-$version.crate" | tar xz -C "$out"
    fi
    rm -f "$out/egui-wgpu-$version/.cargo_vcs_info.json" "$out/egui-wgpu-$version/Cargo.toml.orig" \
        "$out/egui-wgpu-$version/Cargo.lock"
}

verify() {
    check
    local tmp version
    tmp=$(mktemp -d); trap 'rm -rf "$tmp"' RETURN
    version=$(vendored_version)
    fetch "$version" "$tmp"
    (cd "$tmp/egui-wgpu-$version" && patch -s -p1 < "$OLDPWD/$PATCH")
    if diff -r --exclude=VOYAGE.md "$tmp/egui-wgpu-$version" "$VENDOR" > "$tmp/diff"; then
        echo "$VENDOR is egui-wgpu $version with $PATCH, nothing else"
    else
        cat "$tmp/diff" >&2
        echo "error: $VENDOR differs from egui-wgpu $version + $PATCH (above)" >&2
        exit 1
    fi
}

apply() {
    local version=${1:-$(vendored_version)} tmp
    tmp=$(mktemp -d); trap 'rm -rf "$tmp"' RETURN
    fetch "$version" "$tmp"
    (cd "$tmp/egui-wgpu-$version" && patch -p1 --no-backup-if-mismatch < "$OLDPWD/$PATCH") || {
        echo "error: $PATCH does not apply to egui-wgpu $version (hunks above); $VENDOR left as it was" >&2
        exit 1
    }
    cp "$VENDOR/VOYAGE.md" "$tmp/egui-wgpu-$version/"
    rm -rf "$VENDOR"
    mv "$tmp/egui-wgpu-$version" "$VENDOR"
    echo "$VENDOR is now egui-wgpu $version with $PATCH; update VOYAGE.md and the eframe/egui versions in Cargo.toml"
}

case "${1:-}" in
    check) check ;;
    verify) verify ;;
    apply) apply "${2:-}" ;;
    *) sed -n '2,12p' "$0" >&2; exit 2 ;;
esac
