#!/usr/bin/env bash
# Builds the book (docs/, mdBook) into target/book/ and checks the links of
# the book, README.md and ARCHITECTURE.md (scripts/check_links.py: files,
# images, #anchors, includes, in the sources and in the built HTML; external
# links are not fetched).
#
# mdBook comes from crates.io, pinned, without its default features (serve,
# watch, search: the build needs none of them), installed into
# target/tools/ the first time (a few minutes on two cores); an mdbook of the
# pinned version on PATH is used instead.
#
#   scripts/docs.sh                 install if needed, build, check
#   scripts/docs.sh --install-only  only make sure mdbook is there
#
# Needs the Rust toolchain and python3. Run from anywhere.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

MDBOOK_VERSION=0.5.4
TARGET=${CARGO_TARGET_DIR:-$PWD/target}
case $TARGET in /*) ;; *) TARGET=$PWD/$TARGET ;; esac
TOOLS=$TARGET/tools

has_version() { [[ -x "$1" ]] && [[ "$("$1" --version 2>/dev/null)" == "mdbook v$MDBOOK_VERSION" ]]; }

if MDBOOK=$(command -v mdbook) && has_version "$MDBOOK"; then
    :
elif MDBOOK=$TOOLS/bin/mdbook && has_version "$MDBOOK"; then
    :
else
    echo "docs: installing mdbook $MDBOOK_VERSION into $TOOLS (cargo install)" >&2
    # Built in a directory of its own that goes away after (~300 MB), not
    # in the workspace's target directory.
    BUILD=$(mktemp -d)
    trap 'rm -rf "$BUILD"' EXIT
    cargo install mdbook --locked --version "$MDBOOK_VERSION" --no-default-features \
        --root "$TOOLS" --target-dir "$BUILD" --force --quiet
    MDBOOK=$TOOLS/bin/mdbook
    if ! has_version "$MDBOOK"; then
        echo "docs: $MDBOOK is not mdbook v$MDBOOK_VERSION after the install" >&2
        exit 1
    fi
fi

if [[ ${1:-} == --install-only ]]; then
    exit 0
fi

# A clean build: a page removed from the book leaves no stale HTML behind.
rm -rf "$TARGET/book"
"$MDBOOK" build docs --dest-dir "$TARGET/book"
# The sources (files, images, anchors, includes) and the HTML mdBook made
# from them (every href and src, every anchor against the ids it generated).
python3 scripts/check_links.py --html "$TARGET/book"
echo "docs: built $TARGET/book/index.html, links checked" >&2
